"""Safety and state logic of one drive axis, independent of ROS and of the bus (pure, testable).

:class:`DriveAxis` turns received frames into joint-side samples and a joint torque command into
the frames to send, with every safety rule of the drive interface in one place:

* command watchdog: no command for ``command_timeout`` -> zero torque (flag, trip counted);
* NaN/inf commands rejected (the command becomes zero torque, counted);
* joint torque limit, motor current limit, joint velocity limit (no torque that accelerates further);
* late telemetry (newest encoder/effort frame older than ``STALE_PERIODS`` telemetry periods) ->
  no joint sample (never repeated or made-up states) and zero torque until fresh frames arrive;
* stale telemetry (no frame within the stale timeout, see below) -> while enabled a latched fault
  that disables the drive;
* drive error (ODrive axis_error, MIT error code) -> latched fault, drive disabled;
* bus fault reported by the adapter -> latched fault.

Stale timeout (:attr:`AxisConfig.stale_after`): ``telemetry_timeout`` when set, else derived from
the telemetry period T (the drive's encoder/effort frame period): ``STALE_PERIODS`` x T plus
``JITTER_MARGIN`` for frames a healthy drive sends late (scheduling jitter of an emulator process or
of the bus). Age = time since the newest encoder/effort frame, or since the axis' first period when
nothing was ever received, so a dead or absent drive is reported at most one control period after
the timeout.

Latched faults clear only with an explicit :meth:`request_enable`: a drive that faulted does not
restart by itself (no automatic restart after a communication loss, as in EN 60204-1 7.5 and the
CiA 402 fault reset), even when its telemetry comes back. Disabling means zero torque and IDLE
(ODrive Set_Axis_State 1) or zero command + exit motor mode (MIT). Every fault is logged once when
it starts and once when it clears (or is reset) through :class:`~friction_ros.core.can.faults.FaultLog`:
:meth:`DriveAxis.cycle` returns the lines as ``events``.
"""

from __future__ import annotations

import dataclasses
import math
import struct
import threading
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any, NamedTuple

from friction_ros.core.can import mit as mitc
from friction_ros.core.can import odrive as od
from friction_ros.core.can.faults import FaultEvent, FaultLog
from friction_ros.core.can.frame import DecodeStats, Frame
from friction_ros.core.can.joint import JointConversion
from friction_ros.core.config import Field, Schema
from friction_ros.core.validation import ParameterError, check_choice, check_int, check_real

PROTOCOLS = ("odrive_cansimple", "mit")
_F2 = struct.Struct("<ff")
EFFORT_SOURCES = ("current", "torque_estimate")

# Same values as friction_msgs/msg/DriveState FAULT_* (checked by a test).
FAULT_NONE = 0
FAULT_TELEMETRY_STALE = 1
FAULT_DRIVE_ERROR = 2
FAULT_COMMAND_WATCHDOG = 4
FAULT_COMMAND_REJECTED = 8
FAULT_LIMIT = 16
FAULT_BUS = 32
LATCHING = FAULT_TELEMETRY_STALE | FAULT_DRIVE_ERROR | FAULT_BUS

FAULT_NAMES = {
    FAULT_TELEMETRY_STALE: "telemetry_stale",
    FAULT_DRIVE_ERROR: "drive_error",
    FAULT_COMMAND_WATCHDOG: "command_watchdog",
    FAULT_COMMAND_REJECTED: "command_rejected",
    FAULT_LIMIT: "limit",
    FAULT_BUS: "bus",
}


# Stale timeout derived from the telemetry period T: STALE_PERIODS * T + JITTER_MARGIN. The margin
# covers frames a healthy drive sends late. Measured on the 2-core development VM with two busy loops
# (and other users) on the cores: the newest telemetry seen by drive_interface from a drive_emulator
# process (normal priority) was up to 260 ms old in 5 minutes (bench/drive_soak.py, three drives in
# one emulator process; 174 ms in 3 minutes with one), and a bare 1 kHz sleep loop paused up to
# 314 ms in a minute (the same loop under SCHED_FIFO: 2.4 ms): the pauses are the scheduler's. Firmware on a real drive with SocketCAN (kernel receive
# stamps) pauses ~never, so a robot may set telemetry_timeout to a few periods for faster detection.
STALE_PERIODS = 3
JITTER_MARGIN = 0.5  # [s]
# Held kinds count as cleared only after being absent this long (one log line per episode).
FAULT_HOLD = {FAULT_LIMIT: 1.0}
DISABLE_ACTION = "drive disabled (zero torque, idle) until ~/enable"


def fault_text(flags: int) -> str:
    return ",".join(name for bit, name in FAULT_NAMES.items() if flags & bit) or "none"


@dataclass(frozen=True)
class AxisConfig:
    protocol: str = "odrive_cansimple"
    node_id: int = 0  # ODrive node id (0..63) or MIT motor CAN id
    mit_master_id: int = 0
    mit_ranges: mitc.MitRanges = field(default_factory=mitc.MitRanges)
    conversion: JointConversion = field(default_factory=JointConversion)
    torque_limit: float = 1.0  # |joint torque| [N*m]
    current_limit: float = 10.0  # |motor q current| [A]
    velocity_limit: float = 10.0  # |joint velocity| [rad/s]
    command_timeout: float = 0.1  # [s]
    telemetry_period: float = 0.001  # [s] period of the drive's encoder/effort frames
    telemetry_timeout: float = 0.0  # [s] 0 = STALE_PERIODS * telemetry_period + JITTER_MARGIN
    effort_source: str = "current"  # ODrive: Iq_Measured * k_t, or the drive's Torque_Estimate
    request_telemetry: bool = False  # ODrive: send RTR requests for encoder + effort every cycle

    def __post_init__(self):
        check_choice("protocol", self.protocol, PROTOCOLS)
        check_choice("effort_source", self.effort_source, EFFORT_SOURCES)
        if self.protocol == "odrive_cansimple":
            check_int("node_id", self.node_id, 0, od.NODE_ID_MAX)
        else:
            check_int("node_id", self.node_id, 0, 0x7FF)
            check_int("mit_master_id", self.mit_master_id, 0, 0x7FF)
            if self.node_id == self.mit_master_id:
                raise ParameterError(
                    f"node_id = {self.node_id} equals mit_master_id: must differ (replies go to the master id)"
                )
        check_real("torque_limit", self.torque_limit, 0.0, lo_open=True, unit="N*m")
        check_real("current_limit", self.current_limit, 0.0, lo_open=True, unit="A")
        check_real("velocity_limit", self.velocity_limit, 0.0, lo_open=True, unit="rad/s")
        check_real("command_timeout", self.command_timeout, 0.0, lo_open=True, unit="s")
        check_real("telemetry_period", self.telemetry_period, 0.0, lo_open=True, unit="s")
        check_real("telemetry_timeout", self.telemetry_timeout, 0.0, unit="s (0 = automatic)")
        if 0 < self.telemetry_timeout < 2 * self.telemetry_period:
            raise ParameterError(
                f"telemetry_timeout = {self.telemetry_timeout * 1e3:g} ms is shorter than 2 telemetry "
                f"periods ({2e3 * self.telemetry_period:g} ms): a healthy drive would fault; use 0 "
                f"(automatic: {self.auto_timeout * 1e3:g} ms) or at least {2e3 * self.telemetry_period:g} ms"
            )

    @property
    def auto_timeout(self) -> float:
        return STALE_PERIODS * self.telemetry_period + JITTER_MARGIN

    @property
    def late_after(self) -> float:
        """Telemetry older than this gives no joint sample and zero torque [s] (not yet a fault)."""
        return min(STALE_PERIODS * self.telemetry_period, self.stale_after)

    @property
    def stale_after(self) -> float:
        """Effective stale-telemetry timeout [s]."""
        return self.telemetry_timeout if self.telemetry_timeout > 0 else self.auto_timeout

    def stale_rule(self) -> str:
        if self.telemetry_timeout > 0:
            return f"timeout {self.stale_after * 1e3:.4g} ms"
        return (
            f"timeout {self.stale_after * 1e3:.4g} ms = {STALE_PERIODS} telemetry periods of "
            f"{self.telemetry_period * 1e3:.4g} ms + {JITTER_MARGIN * 1e3:g} ms jitter margin"
        )


AXIS_SCHEMA = Schema(
    "axis",
    [
        Field("protocol", "odrive_cansimple", "drive protocol", choices=PROTOCOLS, read_only=True),
        Field("node_id", 0, "ODrive node id (0..63) or MIT motor CAN id", lo=0, hi=0x7FF, read_only=True),
        Schema(
            "mit",
            [
                Field("master_id", 0, "MIT: CAN id the motor replies to", lo=0, hi=0x7FF, read_only=True),
                *[
                    Field(f.name, float(f.default), f"MIT scaling range {f.name}", read_only=True)
                    for f in dataclasses.fields(mitc.MitRanges)
                ],
            ],
            doc="MIT protocol",
        ),
        Field("gear_ratio", 1.0, "motor revolutions per joint revolution", lo=1e-6, read_only=True),
        Field("torque_constant", 0.1, "motor torque constant", lo=1e-9, read_only=True, unit="N*m/A"),
        Field("direction", 1, "sign between motor and joint: 1 or -1", lo=-1, hi=1, read_only=True),
        Field(
            "zero_offset", 0.0, "joint position reported when the motor reads 0", read_only=True, unit="rad"
        ),
        Field(
            "effort_source",
            "current",
            "joint effort from Iq*k_t*gear (current) or the drive's Torque_Estimate",
            choices=("current", "torque_estimate"),
            read_only=True,
        ),
        Field(
            "request_telemetry",
            False,
            "ODrive: also send RTR requests for encoder + effort every period",
            read_only=True,
        ),
        Field(
            "torque_limit",
            1.0,
            "|joint torque command| limit",
            lo=0.0,
            lo_open=True,
            unit="N*m",
        ),
        Field(
            "current_limit",
            10.0,
            "|motor current| limit (also sent to the drive)",
            lo=0.0,
            lo_open=True,
            unit="A",
        ),
        Field(
            "velocity_limit",
            10.0,
            "|joint velocity| above which no accelerating torque is sent",
            lo=0.0,
            lo_open=True,
            unit="rad/s",
        ),
        Field(
            "command_timeout",
            0.1,
            "watchdog: zero torque when no command arrived for this long",
            lo=1e-4,
            hi=10.0,
            unit="s",
        ),
        Field(
            "telemetry_rate_hz",
            0.0,
            "rate of the drive's encoder and effort frames (ODrive cyclic messages); 0 = control_rate_hz "
            "(MIT replies and RTR requests come once per period)",
            lo=0.0,
            hi=10000.0,
            read_only=True,
            unit="Hz",
        ),
        Field(
            "telemetry_timeout",
            0.0,
            f"stale telemetry fault when no encoder/effort frame for this long; 0 = automatic: "
            f"{STALE_PERIODS} telemetry periods + {JITTER_MARGIN * 1e3:g} ms jitter margin",
            lo=0.0,
            hi=10.0,
            unit="s",
        ),
    ],
    doc="one drive on the CAN bus and its joint",
)
"""Parameters of one drive axis (``drive_interface``; per joint ``<joint>.<key>`` for several)."""


def axis_config(v: Mapping[str, Any], control_rate_hz: float) -> AxisConfig:
    """Build the AxisConfig from validated :data:`AXIS_SCHEMA` values (flat dotted names, ``mit.p_min``);
    ParameterError on bad combinations. ``telemetry_rate_hz`` 0 means ``control_rate_hz``."""
    if v["direction"] not in (1, -1):
        raise ParameterError(f"direction = {v['direction']} is not allowed: must be one of 1, -1")
    ranges = mitc.MitRanges(**{f.name: v[f"mit.{f.name}"] for f in dataclasses.fields(mitc.MitRanges)})
    return AxisConfig(
        protocol=v["protocol"],
        node_id=v["node_id"],
        mit_master_id=v["mit.master_id"],
        mit_ranges=ranges,
        conversion=JointConversion(v["gear_ratio"], v["torque_constant"], v["direction"], v["zero_offset"]),
        torque_limit=v["torque_limit"],
        current_limit=v["current_limit"],
        velocity_limit=v["velocity_limit"],
        command_timeout=v["command_timeout"],
        telemetry_period=1.0 / (v["telemetry_rate_hz"] or control_rate_hz),
        telemetry_timeout=v["telemetry_timeout"],
        effort_source=v["effort_source"],
        request_telemetry=v["request_telemetry"],
    )


class JointSample(NamedTuple):
    position: float  # rad
    velocity: float  # rad/s
    effort: float  # N*m joint torque
    stamp: float  # time of the newest frame used [s, same clock as the caller]


@dataclass
class Telemetry:
    """Latest motor-side values as reported by the drive (NaN until received)."""

    motor_position: float = math.nan
    motor_velocity: float = math.nan
    encoder_time: float | None = None
    current_setpoint: float = math.nan
    current_measured: float = math.nan
    iq_time: float | None = None
    torque_target: float = math.nan
    torque_estimate: float = math.nan
    torque_time: float | None = None
    bus_voltage: float = math.nan
    axis_state: int = 0
    axis_error: int = 0
    heartbeat_time: float | None = None


@dataclass
class AxisCounters:
    frames_rx: int = 0
    encoder_frames: int = 0
    effort_frames: int = 0
    heartbeat_frames: int = 0
    frames_tx: int = 0
    commands: int = 0
    commands_rejected: int = 0
    watchdog_trips: int = 0
    fault_trips: int = 0
    limit_hits: int = 0
    bus_errors: int = 0
    stale_faults: int = 0  # stale-telemetry episodes (condition starts)
    late_periods: int = 0  # periods with telemetry older than late_after (zero torque, no sample)
    telemetry_age_max: float = 0.0  # [s] largest age of the newest telemetry seen at a period


class CycleResult(NamedTuple):
    frames: list[Frame]
    sample: JointSample | None
    flags: int
    joint_torque_command: float  # what was sent this cycle [N*m joint], 0 when disabled
    events: list[FaultEvent] = []  # fault start / clear lines to log


class DriveAxis:
    """One axis: decode telemetry, supervise, produce command frames. Thread-safe."""

    ERROR_GRACE_S = 0.05  # error reports sent before the drive processed Clear_Errors are ignored
    # ODrive: a heartbeat this long after the enable sequence must report CLOSED_LOOP_CONTROL; if not,
    # the sequence is sent once more, then the axis faults (frames lost, drive refused). Once in
    # closed loop, a heartbeat reporting any other state (the drive dropped out) is a fault too.
    CLOSED_LOOP_GRACE_S = 0.2
    ENABLE_ATTEMPTS = 2

    def __init__(self, config: AxisConfig):
        self.cfg = config
        self.conv = config.conversion
        self._lock = threading.Lock()
        self.telemetry = Telemetry()
        self.counters = AxisCounters()
        self.enabled = False
        self.enable_requested = False
        self.latched = 0
        self.fault_reason = ""
        self._cmd = 0.0
        self._cmd_time: float | None = None
        self._watchdog_tripped = True
        self._rejected_pending = False
        self._last_flags = 0
        self._ignore_errors_until = -math.inf  # drive errors in flight while clearing are ignored
        self._enable_time = -math.inf  # when the enable sequence was last sent
        self._enable_attempts = 0
        self._closed_loop_seen = False  # a heartbeat after enabling reported CLOSED_LOOP_CONTROL
        self._start: float | None = None  # first period: the age of "nothing received yet"
        self._bus_reason = ""  # set while the adapter reports the bus dead
        self.age_window_max = 0.0  # largest telemetry age since take_age_max() [s]
        self.faults = FaultLog(
            {b: n for b, n in FAULT_NAMES.items() if b != FAULT_COMMAND_REJECTED}, FAULT_HOLD
        )  # rejected commands are logged one by one (rate-limited) by the adapter
        # Fast path of the two telemetry frames of every period (ODrive encoder estimates + Iq): one
        # dict lookup by arbitration id and one unpack instead of a message object and an isinstance
        # chain. Same checks and counters as the decoder; anything else takes the general path.
        self._fast: dict[int, int] = {}
        if config.protocol == "odrive_cansimple":
            self.decoder = od.OdriveDecoder([config.node_id], role="host")
            self.mit = None
            self._effort_cmd = od.Cmd.GET_IQ if config.effort_source == "current" else od.Cmd.GET_TORQUES
            self._fast = {
                (config.node_id << 5) | od.Cmd.GET_ENCODER_ESTIMATES: 0,
                (config.node_id << 5) | od.Cmd.GET_IQ: 1,
            }
        else:
            self.mit = mitc.MitCodec(config.node_id, config.mit_ranges, config.mit_master_id)
            self.decoder = mitc.MitDecoder(self.mit, role="host")

    # ---- inputs ------------------------------------------------------------------------------------
    @property
    def decode_stats(self) -> DecodeStats:
        return self.decoder.stats

    def on_frame(
        self, arb_id: int, data: bytes, is_remote: bool, is_extended: bool, is_error: bool, t: float
    ):
        """Feed one received frame (control or reader thread). ``t`` is the receive time."""
        kind = self._fast.get(arb_id)
        if kind is not None and len(data) == 8 and not (is_remote or is_extended or is_error):
            a, b = _F2.unpack_from(data)
            if a - a == 0.0 and b - b == 0.0:  # both finite (inf - inf and NaN - NaN are NaN)
                tel, c = self.telemetry, self.counters
                with self._lock:
                    self.decoder.stats.decoded += 1
                    c.frames_rx += 1
                    if kind == 0:
                        tel.motor_position, tel.motor_velocity = a * od.TWO_PI, b * od.TWO_PI
                        tel.encoder_time = t
                        c.encoder_frames += 1
                    else:
                        tel.current_setpoint, tel.current_measured, tel.iq_time = a, b, t
                        if self.cfg.effort_source == "current":
                            c.effort_frames += 1
                return
        msg = self.decoder.decode(arb_id, data, is_remote, is_extended, is_error)
        if msg is None:
            return
        tel = self.telemetry
        with self._lock:
            self.counters.frames_rx += 1
            if isinstance(msg, od.EncoderEstimates):
                tel.motor_position, tel.motor_velocity, tel.encoder_time = msg.position, msg.velocity, t
                self.counters.encoder_frames += 1
            elif isinstance(msg, od.Iq):
                tel.current_setpoint, tel.current_measured, tel.iq_time = msg.setpoint, msg.measured, t
                if self.cfg.effort_source == "current":
                    self.counters.effort_frames += 1
            elif isinstance(msg, od.Torques):
                tel.torque_target, tel.torque_estimate, tel.torque_time = msg.target, msg.estimate, t
                if self.cfg.effort_source == "torque_estimate":
                    self.counters.effort_frames += 1
            elif isinstance(msg, od.Heartbeat):
                tel.axis_state, tel.heartbeat_time = msg.axis_state, t
                if t >= self._ignore_errors_until:
                    tel.axis_error = msg.axis_error
                self.counters.heartbeat_frames += 1
            elif isinstance(msg, od.BusVoltageCurrent):
                tel.bus_voltage = msg.voltage
            elif isinstance(msg, od.DriveError):
                if t >= self._ignore_errors_until:
                    tel.axis_error = msg.active_errors
            elif isinstance(msg, mitc.MitReply):
                tel.motor_position, tel.motor_velocity, tel.encoder_time = msg.position, msg.velocity, t
                tel.torque_estimate, tel.torque_time = msg.torque, t
                tel.current_measured = msg.torque / self.conv.torque_constant
                if t >= self._ignore_errors_until:
                    tel.axis_error = msg.error
                tel.axis_state = 1 if self.enabled else 0
                self.counters.encoder_frames += 1
                self.counters.effort_frames += 1

    def set_command(self, joint_torque: float, t: float) -> bool:
        """Store a joint torque command [N*m]. NaN/inf -> rejected (zero torque), returns False."""
        with self._lock:
            self.counters.commands += 1
            self._cmd_time = t
            try:
                ok = math.isfinite(joint_torque)
            except TypeError:
                ok = False
            if not ok:
                self.counters.commands_rejected += 1
                self._rejected_pending = True
                self._cmd = 0.0
                return False
            self._cmd = float(joint_torque)
            self._watchdog_tripped = False
            return True

    def report_bus_fault(self, reason: str) -> None:
        """Adapter reports bus-off / repeated send failures: latched fault (drive disabled); the
        condition lasts until :meth:`clear_bus_fault`."""
        with self._lock:
            self.counters.bus_errors += 1
            self._bus_reason = self._bus_reason or reason
            self._latch(FAULT_BUS, reason)

    def clear_bus_fault(self) -> None:
        """Adapter: the bus works again (the latched fault stays until :meth:`request_enable`)."""
        with self._lock:
            self._bus_reason = ""

    def take_age_max(self) -> float:
        """Largest telemetry age seen since the previous call [s] (diagnostics window)."""
        with self._lock:
            m, self.age_window_max = self.age_window_max, 0.0
            return m

    def request_enable(self) -> None:
        """Clear latched faults and enable as soon as telemetry is fresh (see :meth:`cycle`)."""
        with self._lock:
            self.latched = 0
            self.fault_reason = ""
            self.enable_requested = True
            self.telemetry.axis_error = 0  # cleared by the Clear_Errors frame sent on enable
            self._ignore_errors_until = math.inf

    def request_disable(self) -> list[Frame]:
        with self._lock:
            self.enable_requested = False
            self.enabled = False
            return self.disable_frames()

    # ---- frames ------------------------------------------------------------------------------------
    def enable_frames(self) -> list[Frame]:
        n = self.cfg.node_id
        if self.mit is not None:
            return [self.mit.encode_command(), self.mit.encode_enter()]
        motor_vel_limit = abs(self.conv.motor_velocity(self.cfg.velocity_limit))
        return [
            od.encode_clear_errors(n),
            od.encode_set_limits(n, motor_vel_limit, self.cfg.current_limit),
            od.encode_set_controller_mode(n, od.ControlMode.TORQUE_CONTROL, od.InputMode.PASSTHROUGH),
            od.encode_set_input_torque(n, 0.0),
            od.encode_set_axis_state(n, od.AxisState.CLOSED_LOOP_CONTROL),
        ]

    def disable_frames(self) -> list[Frame]:
        """Zero torque, then idle / exit motor mode (what shutdown and every fault send)."""
        if self.mit is not None:
            return [self.mit.encode_command(), self.mit.encode_exit()]
        n = self.cfg.node_id
        return [od.encode_set_input_torque(n, 0.0), od.encode_set_axis_state(n, od.AxisState.IDLE)]

    # ---- the control-period step ---------------------------------------------------------------------
    def _latch(self, bit: int, reason: str) -> None:
        if not self.latched & bit:
            self.fault_reason = reason
        self.latched |= bit

    def _age(self, t: float) -> tuple[float, bool]:
        """(age of the newest telemetry [s], anything ever received). Without any telemetry the
        age counts from the axis' first period, so an absent drive is reported after the same timeout."""
        tel = self.telemetry
        eff_t = (
            tel.encoder_time
            if self.mit is not None
            else (tel.iq_time if self.cfg.effort_source == "current" else tel.torque_time)
        )
        if tel.encoder_time is None or eff_t is None:
            return t - self._start, False
        age = t - min(tel.encoder_time, eff_t)
        c = self.counters
        if age > c.telemetry_age_max:
            c.telemetry_age_max = age
        if age > self.age_window_max:
            self.age_window_max = age
        return age, True

    def cycle(self, t: float) -> CycleResult:
        """One control period at time ``t``: supervise, and return frames to send + the joint sample."""
        cfg, conv, tel = self.cfg, self.conv, self.telemetry
        frames: list[Frame] = []
        flags = 0
        reasons: dict[int, str] = {}
        with self._lock:
            if self._start is None:
                self._start = t
            age, ever = self._age(t)
            stale = age > cfg.stale_after
            late = not ever or age > cfg.late_after  # no sample, zero torque (not yet a fault)
            if late:
                self.counters.late_periods += 1
            if stale:
                flags |= FAULT_TELEMETRY_STALE
                what = (
                    f"newest telemetry is {age * 1e3:.0f} ms old"
                    if ever
                    else f"no telemetry received from drive id {cfg.node_id} in {age * 1e3:.0f} ms"
                )
                reasons[FAULT_TELEMETRY_STALE] = f"{what} ({cfg.stale_rule()})"
                if self.enabled:
                    self._latch(FAULT_TELEMETRY_STALE, f"telemetry stale: {reasons[FAULT_TELEMETRY_STALE]}")
            if tel.axis_error:
                flags |= FAULT_DRIVE_ERROR
                reasons[FAULT_DRIVE_ERROR] = f"drive reports error 0x{tel.axis_error:X}"
                if self.enabled or self.enable_requested:
                    self._latch(FAULT_DRIVE_ERROR, reasons[FAULT_DRIVE_ERROR])
            flags |= self.latched
            if self.latched:
                if self.enabled or self.enable_requested:
                    self.counters.fault_trips += 1
                    frames += self.disable_frames()
                self.enabled = False
                self.enable_requested = False
            elif self.enable_requested and not self.enabled and not late:
                frames += self.enable_frames()
                self.enabled = True
                self._cmd, self._cmd_time, self._watchdog_tripped = 0.0, None, True
                self._ignore_errors_until = t + self.ERROR_GRACE_S
                self._enable_time, self._enable_attempts, self._closed_loop_seen = t, 1, False
            elif self.enabled and self.mit is None:
                frames += self._check_closed_loop(t)
                if self.latched:  # the drive is not in closed loop: disable (zero torque + IDLE)
                    flags |= self.latched
                    self.counters.fault_trips += 1
                    frames += self.disable_frames()
                    self.enabled = False
                    self.enable_requested = False

            sample = None
            if not late:
                pos = conv.joint_position(tel.motor_position)
                vel = conv.joint_velocity(tel.motor_velocity)
                if self.mit is not None or cfg.effort_source == "torque_estimate":
                    eff = conv.joint_torque(tel.torque_estimate)
                    stamp = tel.encoder_time
                else:
                    eff = conv.joint_torque_from_current(tel.current_measured)
                    stamp = max(tel.encoder_time, tel.iq_time)
                sample = JointSample(pos, vel, eff, stamp)

            cmd = 0.0
            if self.enabled:
                if self._cmd_time is None or t - self._cmd_time > cfg.command_timeout:
                    flags |= FAULT_COMMAND_WATCHDOG
                    if not self._watchdog_tripped:
                        self._watchdog_tripped = True
                        self.counters.watchdog_trips += 1
                elif not late:
                    cmd = self._cmd
                if self._rejected_pending:
                    flags |= FAULT_COMMAND_REJECTED
                    self._rejected_pending = False
                limited = False
                if abs(cmd) > cfg.torque_limit:
                    cmd, limited = math.copysign(cfg.torque_limit, cmd), True
                i_max_joint = cfg.current_limit * conv.torque_constant * conv.gear_ratio
                if abs(cmd) > i_max_joint:
                    cmd, limited = math.copysign(i_max_joint, cmd), True
                if (
                    sample is not None
                    and abs(sample.velocity) > cfg.velocity_limit
                    and cmd * sample.velocity > 0
                ):
                    cmd, limited = 0.0, True
                if limited:
                    flags |= FAULT_LIMIT
                    self.counters.limit_hits += 1
                motor_torque = conv.motor_torque(cmd)
                if self.mit is not None:
                    frames.append(self.mit.encode_command(torque=motor_torque))
                else:
                    frames.append(od.encode_set_input_torque(cfg.node_id, motor_torque))
            elif self.mit is not None:
                frames.append(self.mit.encode_command())  # MIT drives only report when polled
            if self.mit is None and cfg.request_telemetry:
                frames.append(od.encode_rtr(cfg.node_id, od.Cmd.GET_ENCODER_ESTIMATES))
                frames.append(od.encode_rtr(cfg.node_id, self._effort_cmd))
            self.counters.frames_tx += len(frames)
            self._last_flags = flags
            active = flags & (FAULT_COMMAND_WATCHDOG | FAULT_LIMIT | FAULT_DRIVE_ERROR)
            if stale:
                active |= FAULT_TELEMETRY_STALE
            if self._bus_reason:
                active |= FAULT_BUS
                reasons[FAULT_BUS] = self._bus_reason
            for bit in (FAULT_DRIVE_ERROR, FAULT_BUS):  # one-off latches (e.g. no closed loop)
                if self.latched & bit and bit not in reasons:
                    reasons[bit] = self.fault_reason
            reasons[FAULT_COMMAND_WATCHDOG] = (
                "no joint_commands received yet: zero torque"
                if self._cmd_time is None
                else f"no joint_commands for {cfg.command_timeout * 1e3:g} ms: zero torque"
            )
            reasons[FAULT_LIMIT] = "torque command limited (torque, current or velocity limit)"
            events = self.faults.update(t, active, self.latched, reasons, DISABLE_ACTION)
            self.counters.stale_faults = self.faults.starts[FAULT_TELEMETRY_STALE]
            return CycleResult(frames, sample, flags, cmd, events)

    def _check_closed_loop(self, t: float) -> list[Frame]:
        """ODrive heartbeat check of an enabled axis (lock held): see :attr:`CLOSED_LOOP_GRACE_S`."""
        tel = self.telemetry
        hb = tel.heartbeat_time
        if hb is None or hb < self._enable_time + self.CLOSED_LOOP_GRACE_S:
            if (
                hb is not None
                and hb >= self._enable_time
                and tel.axis_state == od.AxisState.CLOSED_LOOP_CONTROL
            ):
                self._closed_loop_seen = True
            return []
        if tel.axis_state == od.AxisState.CLOSED_LOOP_CONTROL:
            self._closed_loop_seen = True
            return []
        state = (
            od.AxisState(tel.axis_state).name
            if tel.axis_state in od.AxisState._value2member_map_
            else tel.axis_state
        )
        if self._closed_loop_seen:
            self._latch(FAULT_DRIVE_ERROR, f"drive left closed loop: heartbeat reports axis state {state}")
            return []
        if self._enable_attempts < self.ENABLE_ATTEMPTS:
            self._enable_attempts += 1
            self._enable_time = t
            self._ignore_errors_until = t + self.ERROR_GRACE_S
            return self.enable_frames()
        self._latch(
            FAULT_DRIVE_ERROR,
            f"drive did not enter closed loop: heartbeat reports axis state {state} "
            f"{self.CLOSED_LOOP_GRACE_S:g} s after each of {self._enable_attempts} enable requests",
        )
        return []

    def shutdown_frames(self) -> list[Frame]:
        """Frames that leave the drive safe; marks the axis disabled."""
        with self._lock:
            self.enabled = False
            self.enable_requested = False
            return self.disable_frames()


def frame_router(axes: list[DriveAxis]) -> Callable[[int, bytes], DriveAxis]:
    """Received frame (arbitration id, data) -> the axis it belongs to, for several drives on one bus.

    ODrive CANSimple: node id = arbitration id >> 5. MIT: a reply's first data byte is the motor id.
    With one axis, or for a frame of no configured drive, the first axis: its decoder counts the
    frame as ignored or rejected, as a single-drive node does.
    """
    first = axes[0]
    if len(axes) == 1:
        return lambda arb_id, data: first
    if first.cfg.protocol == "odrive_cansimple":
        by_id = {a.cfg.node_id: a for a in axes}
        return lambda arb_id, data: by_id.get(arb_id >> 5, first)
    by_motor = {a.cfg.node_id & 0xFF: a for a in axes}
    return lambda arb_id, data: by_motor.get(data[0], first) if data else first
