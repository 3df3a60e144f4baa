"""Configuration of one drive axis: :class:`AxisConfig` (what :class:`~friction_ros.core.can.axis.DriveAxis`
runs with) and :data:`AXIS_SCHEMA`, the drive_interface parameters it is built from (:func:`axis_config`).

Units at this boundary: the drive's own (A, motor rad) are converted by
:class:`~friction_ros.core.can.joint.JointConversion`; everything else is SI on the joint side (rad,
N*m; m and N on a ``joint_type: prismatic`` axis, which needs ``lead``, its travel per motor turn).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

from friction_ros.core.can import mit as mitc
from friction_ros.core.can.joint import JointConversion
from friction_ros.core.can.protocol import PROTOCOLS, drive_protocol
from friction_ros.core.can.telemetry_gate import TelemetryLimits
from friction_ros.core.config import Field, Schema
from friction_ros.core.joint_type import JOINT_TYPE_FIELD, units_of
from friction_ros.core.validation import ParameterError, check_choice, check_int, check_real

EFFORT_SOURCES = ("current", "torque_estimate")

# Stale timeout derived from the telemetry period T: STALE_PERIODS * T + JITTER_MARGIN. The margin
# covers frames a healthy drive sends late. Measured on the 2-core development VM with two busy loops
# (and other users) on the cores: the newest telemetry seen by drive_interface from a drive_emulator
# process (normal priority) was up to 260 ms old in 5 minutes (bench/drive_soak.py, three drives in
# one emulator process; 174 ms in 3 minutes with one), and a bare 1 kHz sleep loop paused up to
# 314 ms in a minute (the same loop under SCHED_FIFO: 2.4 ms): the pauses are the scheduler's. Firmware on a real drive with SocketCAN (kernel receive
# stamps) pauses ~never, so a robot may set telemetry_timeout to a few periods for faster detection.
STALE_PERIODS = 3
JITTER_MARGIN = 0.5  # [s]


@dataclass(frozen=True)
class AxisConfig:
    protocol: str = "odrive_cansimple"
    node_id: int = 0  # the drive's id on the bus (ODrive node id 0..63, MIT motor CAN id)
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
    limit_factor: float = 10.0  # telemetry above this many times a configured limit is implausible
    reject_run: int = 5  # consecutive implausible reports that latch a fault
    cia402: tuple[
        tuple[str, Any], ...
    ] = ()  # CiA 402 settings (Cia402Config keyword, value), see cia402.config

    def __post_init__(self):
        check_choice("protocol", self.protocol, PROTOCOLS)
        check_choice("effort_source", self.effort_source, EFFORT_SOURCES)
        drive_protocol(self.protocol).check_config(self)
        check_real("torque_limit", self.torque_limit, 0.0, lo_open=True, unit="N*m")
        check_real("current_limit", self.current_limit, 0.0, lo_open=True, unit="A")
        check_real("velocity_limit", self.velocity_limit, 0.0, lo_open=True, unit="rad/s")
        check_real("command_timeout", self.command_timeout, 0.0, lo_open=True, unit="s")
        check_real("telemetry_period", self.telemetry_period, 0.0, lo_open=True, unit="s")
        check_real("telemetry_timeout", self.telemetry_timeout, 0.0, unit="s (0 = automatic)")
        check_real("telemetry_gate.limit_factor", self.limit_factor, 1.0)
        check_int("telemetry_gate.reject_run", self.reject_run, 1, 1_000_000)
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

    def plausibility(self) -> TelemetryLimits:
        """Joint-side bounds of plausible telemetry (:mod:`~friction_ros.core.can.telemetry_gate`):
        ``limit_factor`` x the velocity limit and x the effort the current limit gives
        (``current_limit * k_t * ratio``); position within the protocol's range
        (:meth:`DriveProtocol.position_range <friction_ros.core.can.protocol.DriveProtocol.position_range>`:
        ODrive 2^24 float32 turns; MIT its p range, whose 16-bit step is the resolution)."""
        conv, f = self.conversion, self.limit_factor
        motor_max, step = drive_protocol(self.protocol).position_range(self)
        return TelemetryLimits(
            max_position=motor_max / conv.ratio + abs(conv.zero_offset),
            max_velocity=f * self.velocity_limit,
            max_effort=f * self.current_limit * conv.torque_constant * conv.ratio,
            period=self.telemetry_period,
            resolution=step / conv.ratio,
            reject_run=self.reject_run,
        )

    def stale_rule(self) -> str:
        if self.telemetry_timeout > 0:
            return f"timeout {self.stale_after * 1e3:.4g} ms"
        return (
            f"timeout {self.stale_after * 1e3:.4g} ms = {STALE_PERIODS} telemetry periods of "
            f"{self.telemetry_period * 1e3:.4g} ms + {JITTER_MARGIN * 1e3:g} ms jitter margin"
        )


CIA402_KEYS = ("eds_path", "counts_per_rev", "rated_torque", "rated_current", "heartbeat_ms")
AXIS_SCHEMA = Schema(
    "axis",
    [
        Field(
            "protocol",
            "odrive_cansimple",
            "drive protocol: odrive_cansimple (ODrive CANSimple), mit (MIT mode), cia402 (CANopen CiA 402) "
            "or a registered plugin's",
            choices=PROTOCOLS,
            read_only=True,
        ),
        Field(
            "node_id",
            0,
            "ODrive node id (0..63), MIT motor CAN id or CANopen node id (1..127)",
            lo=0,
            hi=0x7FF,
            read_only=True,
        ),
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
        Schema(
            "cia402",
            [
                Field(
                    "eds_path",
                    "",
                    "CiA 402: the drive's EDS file; its defaults fill the units left at 0",
                    read_only=True,
                ),
                Field(
                    "counts_per_rev",
                    0,
                    "CiA 402: encoder counts per motor revolution (0: EDS, else the drive's 0x608F)",
                    lo=0,
                    hi=2**31 - 1,
                    read_only=True,
                    unit="counts/rev",
                ),
                Field(
                    "rated_torque",
                    0.0,
                    "CiA 402: motor rated torque, the unit of target torque (0: EDS, else 0x6076)",
                    lo=0.0,
                    read_only=True,
                    unit="N*m",
                ),
                Field(
                    "rated_current",
                    0.0,
                    "CiA 402: motor rated current, the unit of current actual (0: EDS, else 0x6075)",
                    lo=0.0,
                    read_only=True,
                    unit="A",
                ),
                Field(
                    "heartbeat_ms",
                    100,
                    "CiA 402: heartbeat period the drive is told to send [ms]",
                    lo=1,
                    hi=65535,
                    read_only=True,
                ),
            ],
            doc="CiA 402 over CANopen (units left at 0 are read from the EDS or the drive)",
        ),
        JOINT_TYPE_FIELD,
        Field("gear_ratio", 1.0, "motor revolutions per joint revolution", lo=1e-6, read_only=True),
        Field(
            "lead",
            0.0,
            "prismatic joint: travel per motor turn (screw lead / gear ratio; required there, 0 on a "
            "revolute joint)",
            lo=0.0,
            read_only=True,
            unit="m/rev",
        ),
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
            "rate of the drive's encoder and effort frames (ODrive cyclic messages); 0 = 1 / control_period "
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
        Schema(
            "telemetry_gate",
            [
                Field(
                    "limit_factor",
                    10.0,
                    "encoder/effort reports above this many times velocity_limit (speed, and position "
                    "jump per elapsed time) or the effort of current_limit are dropped as implausible",
                    lo=1.0,
                ),
                Field(
                    "reject_run",
                    5,
                    "consecutive implausible encoder or effort reports that latch a fault (drive "
                    "disabled until ~/enable)",
                    lo=1,
                    hi=1000000,
                ),
            ],
            doc="plausibility gate of the drive's telemetry",
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
    joint_type, lead = v.get("joint_type", "revolute"), v.get("lead", 0.0)
    if joint_type == "prismatic" and not lead > 0:
        raise ParameterError(
            "joint_type = prismatic needs lead > 0 [m/rev]: the travel per motor turn (screw lead / "
            "gear ratio), which converts motor turns to m"
        )
    if joint_type == "revolute" and lead:
        raise ParameterError(
            f"lead = {lead:g} [m/rev] is for a prismatic joint: set joint_type: prismatic or drop lead"
        )
    with units_of(joint_type):
        return _axis_config(v, control_rate_hz, lead)


def _axis_config(v: Mapping[str, Any], control_rate_hz: float, lead: float) -> AxisConfig:
    ranges = mitc.MitRanges(**{f.name: v[f"mit.{f.name}"] for f in dataclasses.fields(mitc.MitRanges)})
    return AxisConfig(
        protocol=v["protocol"],
        node_id=v["node_id"],
        mit_master_id=v["mit.master_id"],
        mit_ranges=ranges,
        conversion=JointConversion(
            v["gear_ratio"], v["torque_constant"], v["direction"], v["zero_offset"], lead
        ),
        torque_limit=v["torque_limit"],
        current_limit=v["current_limit"],
        velocity_limit=v["velocity_limit"],
        command_timeout=v["command_timeout"],
        telemetry_period=1.0 / (v["telemetry_rate_hz"] or control_rate_hz),
        telemetry_timeout=v["telemetry_timeout"],
        effort_source=v["effort_source"],
        request_telemetry=v["request_telemetry"],
        limit_factor=v["telemetry_gate.limit_factor"],
        reject_run=v["telemetry_gate.reject_run"],
        cia402=tuple((k, v[f"cia402.{k}"]) for k in CIA402_KEYS),
    )
