"""Safety and state logic of one drive axis, independent of ROS and of the bus (pure, testable).

:class:`DriveAxis` turns received frames into joint-side samples and a joint torque command into
the frames to send, with every safety rule of the drive interface in one place; the wire format is
its :class:`~friction_ros.core.can.protocol.DriveProtocol` (``AxisConfig.protocol``):

* command watchdog: no command for ``command_timeout`` -> zero torque (flag, trip counted);
* NaN/inf commands rejected (the command becomes zero torque, counted);
* joint torque limit, motor current limit, joint velocity limit (no torque that accelerates further);
* late telemetry (newest encoder/effort frame older than ``STALE_PERIODS`` telemetry periods) ->
  no joint sample (never repeated or made-up states) and zero torque until fresh frames arrive;
* stale telemetry (no frame within the stale timeout, see below) -> while enabled a latched fault
  that disables the drive;
* drive error (ODrive axis_error, MIT error code) -> latched fault, drive disabled;
* bus fault reported by the adapter -> latched fault;
* encoder/effort reports pass :class:`~friction_ros.core.can.telemetry_gate.TelemetryGate` (a rejected
  one is dropped, counted, logged); ``reject_run`` in a row -> latched fault, drive disabled.

Stale timeout (:attr:`AxisConfig.stale_after`): ``telemetry_timeout`` when set, else derived from
the telemetry period T (the drive's encoder/effort frame period): ``STALE_PERIODS`` x T plus
``JITTER_MARGIN`` for frames a healthy drive sends late (scheduling jitter of an emulator process or
of the bus). Age = time since the newest encoder/effort frame, or since the axis' first period when
nothing was ever received, so a dead or absent drive is reported at most one control period after
the timeout.

Latched faults clear only with an explicit :meth:`request_enable`: a drive that faulted does not
restart by itself (no automatic restart after a communication loss, as in EN 60204-1 7.5 and the
CiA 402 fault reset), even when its telemetry comes back. Disabling means the protocol's
``disable_frames`` (zero torque, then IDLE on ODrive, exit motor mode on MIT). Every fault is logged once when
it starts and once when it clears (or is reset) through :class:`~friction_ros.core.can.faults.FaultLog`:
:meth:`DriveAxis.cycle` returns the lines as ``events``. The receive side (frames -> telemetry, with
the fast paths of the per-period telemetry frames) is :mod:`~friction_ros.core.can.axis_rx`.
"""

from __future__ import annotations

import math
import threading

from friction_ros.core.can.axis_config import AxisConfig
from friction_ros.core.can.axis_records import AxisCounters, CycleResult, JointSample, Telemetry
from friction_ros.core.can.axis_rx import AxisReceiver
from friction_ros.core.can.faults import (
    DISABLE_ACTION,
    FAULT_BUS,
    FAULT_COMMAND_REJECTED,
    FAULT_COMMAND_WATCHDOG,
    FAULT_DRIVE_ERROR,
    FAULT_HOLD,
    FAULT_LIMIT,
    FAULT_NAMES,
    FAULT_TELEMETRY_IMPLAUSIBLE,
    FAULT_TELEMETRY_STALE,
    FaultEvent,
    FaultLog,
)
from friction_ros.core.can.frame import Frame
from friction_ros.core.can.protocol import DriveProtocol, drive_protocol
from friction_ros.core.can.telemetry_gate import TelemetryGate


class DriveAxis(AxisReceiver):
    """One axis: decode telemetry, supervise, produce command frames. Thread-safe."""

    ERROR_GRACE_S = 0.05  # error reports sent before the drive processed Clear_Errors are ignored
    # A protocol that reports the drive state (ODrive heartbeat): a state report this long after the
    # enable sequence must be closed loop (DriveProtocol.closed_loop); if not, the sequence is sent once
    # more, then the axis faults (frames lost, drive refused). Once in closed loop, a report of any
    # other state (the drive dropped out) is a fault too.
    CLOSED_LOOP_GRACE_S = 0.2
    ENABLE_ATTEMPTS = 2

    def __init__(self, config: AxisConfig):
        self.gate = TelemetryGate(config.plausibility(), f"telemetry of drive id {config.node_id}")
        self.cfg = config
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
        self._closed_loop_seen = False  # a state report after enabling said closed loop
        self._start: float | None = None  # first period: the age of "nothing received yet"
        self._bus_reason = ""  # set while the adapter reports the bus dead
        self.age_window_max = 0.0  # largest telemetry age since take_age_max() [s]
        self.faults = FaultLog(
            {b: n for b, n in FAULT_NAMES.items() if b != FAULT_COMMAND_REJECTED}, FAULT_HOLD
        )  # rejected commands are logged one by one (rate-limited) by the adapter
        self._bind_receive()  # receive side (axis_rx): fast paths of the telemetry of every period
        self._torque_frame = self.protocol.torque_frame
        self._poll_frames = self.protocol.poll_frames
        proto_cls = type(self.protocol)
        self._cycle_frames = (
            self.protocol.cycle_frames if proto_cls.cycle_frames is not DriveProtocol.cycle_frames else None
        )

    @property
    def cfg(self) -> AxisConfig:
        return self._cfg

    @cfg.setter
    def cfg(self, config: AxisConfig) -> None:
        """A new configuration (run-time parameter change) also moves the telemetry gate's bounds."""
        if not hasattr(self, "protocol"):
            self.protocol = drive_protocol(config.protocol)(config)
            self.decoder = self.protocol.decoder
        self.protocol.reconfigure(config)
        self._cfg, self.conv = config, config.conversion
        self.gate.limits = config.plausibility()
        self._bind_conversion()

    # ---- inputs ------------------------------------------------------------------------------------
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
            self.gate.reset()  # an operator's enable adopts the next plausible position (re-homing)

    def request_disable(self) -> list[Frame]:
        with self._lock:
            self.enable_requested = False
            self.enabled = False
            return self.disable_frames()

    # ---- frames ------------------------------------------------------------------------------------
    def enable_frames(self) -> list[Frame]:
        return self.protocol.enable_frames()

    def disable_frames(self) -> list[Frame]:
        """Zero torque, then leave torque control (what shutdown and every fault send)."""
        return self.protocol.disable_frames()

    def startup_frames(self) -> list[Frame]:
        """Frames the protocol sends once when the bus opens (often none)."""
        return self.protocol.startup_frames()

    # ---- the control-period step ---------------------------------------------------------------------
    def _latch(self, bit: int, reason: str) -> None:
        if not self.latched & bit:
            self.fault_reason = reason
        self.latched |= bit

    def _age(self, t: float) -> tuple[float, bool]:
        """(age of the newest telemetry [s], anything ever received). Without any telemetry the
        age counts from the axis' first period, so an absent drive is reported after the same timeout."""
        tel = self.telemetry
        eff_t = tel.iq_time if self._effort_current else tel.torque_time
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
                text = self.protocol.error_text(tel.axis_error)
                reasons[FAULT_DRIVE_ERROR] = f"drive reports error 0x{tel.axis_error:X}" + (
                    f" ({text})" if text else ""
                )
                if self.enabled or self.enable_requested:
                    self._latch(FAULT_DRIVE_ERROR, reasons[FAULT_DRIVE_ERROR])
            implausible = self.gate.implausible
            if implausible:
                flags |= FAULT_TELEMETRY_IMPLAUSIBLE
                reasons[FAULT_TELEMETRY_IMPLAUSIBLE] = self.gate.reason()
                if self.enabled or self.enable_requested:
                    self._latch(FAULT_TELEMETRY_IMPLAUSIBLE, reasons[FAULT_TELEMETRY_IMPLAUSIBLE])
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
            elif self.enabled and self._reports_state:
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
                if self._effort_current:
                    eff = conv.joint_torque_from_current(tel.current_measured)
                    stamp = max(tel.encoder_time, tel.iq_time)
                else:
                    eff = conv.joint_torque(tel.torque_estimate)
                    stamp = tel.encoder_time
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
                i_max_joint = cfg.current_limit * conv.torque_constant * conv.ratio
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
                frames.append(self._torque_frame(motor_torque))
            frames += self._poll_frames(self.enabled)
            if self._cycle_frames is not None:
                frames += self._cycle_frames(t)
            self.counters.frames_tx += len(frames)
            self._last_flags = flags
            active = flags & (FAULT_COMMAND_WATCHDOG | FAULT_LIMIT | FAULT_DRIVE_ERROR)
            if implausible:
                active |= FAULT_TELEMETRY_IMPLAUSIBLE
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
            if self.gate.lines:  # rejection lines of the frames since the last period
                kind = "telemetry_rejected"
                events[:0] = [
                    FaultEvent(t, "info" if ok else "warning", kind, x) for ok, x in self.gate.lines
                ]
                self.gate.lines.clear()
            self.counters.stale_faults = self.faults.starts[FAULT_TELEMETRY_STALE]
            return CycleResult(frames, sample, flags, cmd, events)

    def _check_closed_loop(self, t: float) -> list[Frame]:
        """State check of an enabled axis (lock held): see :attr:`CLOSED_LOOP_GRACE_S`."""
        tel = self.telemetry
        hb = tel.heartbeat_time
        if hb is None or hb < self._enable_time + self.CLOSED_LOOP_GRACE_S:
            if hb is not None and hb >= self._enable_time and self.protocol.closed_loop(tel.axis_state):
                self._closed_loop_seen = True
            return []
        if self.protocol.closed_loop(tel.axis_state):
            self._closed_loop_seen = True
            return []
        state = self.protocol.state_name(tel.axis_state)
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
