"""The scale of a joint: what sizing gains, references and experiments needs to know of it.

A joint is described by what a short safe probe measures (or a plant preset provides):
:class:`JointScale` (breakaway torque, inertia, torque/speed/travel limits, encoder resolution,
current-loop lag, delays, a constant load). Everything else is derived from it, so the same rules
serve every preset in ``params/``, a preset a user writes, and a real joint.

Gains and references are sized in :mod:`friction_ros.core.experiment.tracking_design`, excitation
programs in :mod:`friction_ros.core.experiment.experiment_sizing`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from friction_ros.core.validation import ParameterError, check_real

#: motor-side speed assumed when a preset names none [rad/s] (about 2900 rpm) [ASSUMED]
MOTOR_SPEED_LIMIT = 300.0
#: travel of a linear axis when none is given [m] [ASSUMED]
LINEAR_TRAVEL = 0.3
#: travel of a rotary joint when none is given [rad]
ROTARY_TRAVEL = 100.0


@dataclass(frozen=True)
class JointScale:
    """What sizing needs to know of a joint (joint units: rad or m; torque N*m or N)."""

    breakaway: float
    inertia: float
    torque_limit: float
    speed_limit: float
    travel: float
    resolution: float
    period: float = 1e-3
    current_lag: float = 0.0
    delay: float = 0.0
    load: float = 0.0
    stribeck_velocity: float = math.nan
    coulomb: float = math.nan
    viscous: float = 0.0
    damping: float = math.nan
    velocity_filter: float = 0.0

    def __post_init__(self) -> None:
        check_real("breakaway", self.breakaway, 0.0, lo_open=True, unit="N*m")
        check_real("inertia", self.inertia, 0.0, lo_open=True, unit="kg*m^2")
        check_real("torque_limit", self.torque_limit, 0.0, lo_open=True, unit="N*m")
        check_real("speed_limit", self.speed_limit, 0.0, lo_open=True, unit="rad/s")
        check_real("travel", self.travel, 0.0, lo_open=True, unit="rad")
        check_real("resolution", self.resolution, 0.0, lo_open=True, unit="rad")
        check_real("period", self.period, 1e-5, 0.1, unit="s")
        check_real("current_lag", self.current_lag, 0.0, unit="s")
        check_real("delay", self.delay, 0.0, unit="s")
        check_real("velocity_filter", self.velocity_filter, 0.0, unit="s")
        check_real("load", self.load, None, unit="N*m")
        if not math.isfinite(self.damping):
            object.__setattr__(self, "damping", float(self.viscous))
        if self.torque_limit <= abs(self.load) + self.breakaway:
            raise ParameterError(
                f"torque_limit = {self.torque_limit:g} is out of range: must exceed |load| + breakaway = "
                f"{abs(self.load) + self.breakaway:g} [N*m], or the joint cannot be moved both ways"
            )

    @classmethod
    def from_probe(
        cls,
        breakaway: float,
        inertia: float,
        torque_limit: float,
        speed_limit: float,
        travel: float,
        resolution: float,
        **more: Any,
    ) -> JointScale:
        """A real joint: the values a short safe probe measured (and its known limits)."""
        return cls(
            breakaway=breakaway,
            inertia=inertia,
            torque_limit=torque_limit,
            speed_limit=speed_limit,
            travel=travel,
            resolution=resolution,
            **more,
        )

    @classmethod
    def from_preset(cls, preset, period: float | None = None, **overrides: Any) -> JointScale:
        """A simulated joint: the scale a probe would measure on ``preset`` (a loaded Preset).

        ``period``: the control period [s], by default the preset's ``control_period`` (the plant
        node steps at it, so the program and the loops run at it too)."""
        if period is None:
            period = float(getattr(preset, "control_period", 0.0) or 1e-3)
        p = preset.params
        r = p.ratio
        eta = p.gear_efficiency
        gain = p.torque_constant * r * eta  # joint torque per motor current
        v = np.geomspace(1e-6, 100.0, 400) / max(r, 1.0)
        f_pos = np.abs(preset.joint_friction(v))
        f_neg = np.abs(preset.joint_friction(-v))
        both = np.maximum(f_pos, f_neg)
        breakaway = float(max(f_pos[0], f_neg[0], 1e-12))
        fmin = float(np.min(both))
        coulomb = float(both[np.argmin(both)])
        vs = math.nan
        drop = float(both[0]) - fmin
        if drop > 0.05 * float(both[0]):
            k = int(np.nonzero(both - fmin <= drop / math.e)[0][0])
            vs = float(v[k])
        viscous = r * r * eta * p.motor_damping + p.load_damping
        damping = viscous
        if p.actuation == "voltage" and p.resistance > 0:  # back-EMF: Kt Ke / R at the motor
            damping += r * r * eta * p.torque_constant * p.back_emf_constant / p.resistance
        # actuator: what the current (or voltage) limit allows at the joint
        if p.actuation == "current" and p.current_limit > 0:
            t_max = p.current_limit * gain
        elif p.actuation == "voltage" and p.voltage_limit > 0:
            i_max = p.voltage_limit / max(p.resistance, 1e-12)
            if p.current_limit > 0:
                i_max = min(i_max, p.current_limit)
            t_max = i_max * gain
        else:
            t_max = 10.0 * breakaway + abs(p.load_torque - p.gravity_force)
        speed = MOTOR_SPEED_LIMIT / r
        if p.actuation == "voltage" and p.voltage_limit > 0 and p.back_emf_constant > 0:
            speed = min(speed, 0.8 * p.voltage_limit / p.back_emf_constant / r)
        travel = LINEAR_TRAVEL if p.lead_pitch > 0 else ROTARY_TRAVEL
        if p.encoder_cpr > 0:
            counts_per_unit = p.encoder_cpr * p.encoder_ratio / (2.0 * math.pi)
            if p.encoder_location == "motor":
                counts_per_unit *= r
            resolution = 1.0 / counts_per_unit
        else:
            resolution = 1e-7
        lag = p.current_time_constant if p.actuation == "current" else 0.0
        if p.actuation == "voltage" and p.resistance > 0:
            lag = p.inductance / p.resistance
        v_filter = 1.0 / (2.0 * math.pi * p.velocity_filter_hz) if p.velocity_filter_hz > 0 else 0.0
        lag += v_filter
        J = p.reflected_inertia * r * r * eta
        scale = cls(
            breakaway=breakaway,
            inertia=J,
            torque_limit=t_max,
            speed_limit=speed,
            travel=travel,
            resolution=resolution,
            period=period,
            current_lag=lag,
            delay=p.measurement_delay + p.actuation_delay,
            load=p.load_torque - p.gravity_force,
            stribeck_velocity=vs,
            coulomb=coulomb,
            viscous=viscous,
            damping=damping,
            velocity_filter=v_filter,
        )
        return replace(scale, **overrides) if overrides else scale

    @property
    def count_velocity(self) -> float:
        """Velocity read when the encoder steps by one count [rad/s or m/s]: ``resolution /
        max(velocity_filter, period)`` (a differenced count, smoothed by the velocity filter)."""
        return self.resolution / max(self.velocity_filter, self.period)

    @property
    def loop_delay(self) -> float:
        """Pure delay of a sampled loop: one period of answer delay + half a period of hold + delays."""
        return 1.5 * self.period + self.delay
