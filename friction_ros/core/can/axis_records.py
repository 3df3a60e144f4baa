"""Records of one drive axis: the latest telemetry, its counters, a joint sample, a period's result."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple

from friction_ros.core.can.faults import FaultEvent
from friction_ros.core.can.frame import Frame


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
