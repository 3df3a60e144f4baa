"""Experiments and gains sized to the joint: one scale in, an excitation program and tracking gains out.

A joint is described by what a short safe probe measures (or a plant preset provides):
:class:`JointScale` (breakaway torque, inertia, torque/speed/travel limits, encoder resolution,
current-loop lag, delays, a constant load). Everything else is derived from it, so the same rules
serve every preset in ``params/``, a preset a user writes, and a real joint.

**Loop tuning rule** (used for the experiment's velocity loop and the tracking PD). The loop is
``L(s) = C(s) / (J s^2) * e^{-s T} / (1 + s tau)`` with ``tau`` the current-loop lag plus the
velocity filter's time constant and ``T`` the pure delay: one control period (the command answers
the previous sample) plus half a period (zero-order hold) plus measurement and actuation delays.
With viscous damping ``B`` (friction's viscous part, back-EMF of a voltage drive) the plant is
``1 / (s (J s + B))``. For a PD ``C = K_p + K_d s`` with the zero at ``w_c / a``
(``K_p = K_d w_c / a``) the phase at the crossover ``w_c`` is
``-90 - atan(w_c J / B) + atan(a) - atan(w_c tau) - w_c T``. Requiring the phase margin ``PM``
gives ``atan(w_c J/B) + atan(w_c tau) + w_c T = 90 + atan(a) - PM``, solved for ``w_c`` by
bisection; then ``|L(j w_c)| = 1`` gives ``K_d = |B + j J w_c| / (sqrt(1 + 1/a^2) g)`` with ``g``
the lag's gain at ``w_c``. Defaults: ``PM = 45 deg``, ``a = 4`` (zero a factor four below the crossover).
The velocity loop of the experiment is the same law on the velocity error's integral (its ``p``
is the PD's ``K_d``, its ``i`` the PD's ``K_p``), which is why it doubles as the position-loop
gains of the plateaus.

**Experiment rule** (seed 004 B.3 procedures, seed 003 A.3 excitation, scaled):

* torque ceiling ``max_torque = min(torque_limit, 4 F_b + |load| + 2 J v_max / settle + 1.5 B v_max)``;
* plateau speeds log-spaced from ``v_min`` to ``v_max``: ``v_min`` is the larger of what the
  encoder resolves (``20`` counts over the hold) and a fifth of the Stribeck velocity when it is
  known (so the lowest plateaus lie below it); ``v_max = min(0.4 v_limit, travel / (2 (settle +
  hold)))``; hold long enough for ``v_min`` to cover 20 counts (at most 2 s);
* breakaway ramp: preload ``0.5 F_b``, up to ``min(3 F_b, max_torque)``, steps from ``F_b / 200``
  (coarser if the ramp would exceed its time budget) held long enough that the joint, once it
  slides, moves 2 counts within one step (``(step / J) t^2 / 2 >= 2 resolution``);
* presliding and chirp torques as fractions of ``F_b`` (0.4/0.8, and 1.2 -> 0.5);
* the random velocity's RMS amplitude ``min(v_max / 2, ...)``;
* a constant load (gravity) is added to every open-loop torque (``bias``) so the ramps and cycles
  are centred on the torque that holds the joint.
"""

from __future__ import annotations

import copy
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
DEFAULT_PHASE_MARGIN = 45.0
ZERO_RATIO = 4.0


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
    def from_preset(cls, preset, period: float = 1e-3, **overrides: Any) -> JointScale:
        """A simulated joint: the scale a probe would measure on ``preset`` (a loaded Preset)."""
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
        if p.velocity_filter_hz > 0:
            lag += 1.0 / (2.0 * math.pi * p.velocity_filter_hz)
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
        )
        return replace(scale, **overrides) if overrides else scale

    @property
    def loop_delay(self) -> float:
        """Pure delay of a sampled loop: one period of answer delay + half a period of hold + delays."""
        return 1.5 * self.period + self.delay


def crossover(
    lag: float,
    delay: float,
    phase_margin_deg: float = DEFAULT_PHASE_MARGIN,
    a: float = ZERO_RATIO,
    damping_ratio: float = math.inf,
) -> float:
    """Crossover ``w_c`` [rad/s] solving ``atan(w J/B) + atan(w tau) + w T = 90 + atan(a) - PM``.

    ``damping_ratio = J / B`` (inertia over viscous damping; ``inf`` for a pure inertia, whose
    phase is then the -180 deg of ``1 / (J s^2)``)."""
    budget = math.pi / 2 + math.atan(a) - math.radians(phase_margin_deg)
    if budget <= math.pi / 2 if math.isinf(damping_ratio) else budget <= 0:
        raise ParameterError(
            f"phase_margin = {phase_margin_deg:g} deg is out of range: must be < {math.degrees(math.atan(a)):.1f}"
        )

    def phase(w):
        mech = math.pi / 2 if math.isinf(damping_ratio) else math.atan(w * damping_ratio)
        return mech + math.atan(w * lag) + w * delay

    lo, hi = 0.0, 1.0
    while phase(hi) < budget and hi < 1e9:
        hi *= 2.0
    for _ in range(100):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if phase(mid) < budget else (lo, mid)
    return lo


def tracking_gains(
    scale: JointScale, phase_margin_deg: float = DEFAULT_PHASE_MARGIN, a: float = ZERO_RATIO
) -> dict[str, float]:
    """PD gains for position tracking on ``J s^2`` with lag and delay (module docstring's rule)."""
    ratio = scale.inertia / scale.damping if scale.damping > 0 else math.inf
    wc = crossover(scale.current_lag, scale.loop_delay, phase_margin_deg, a, ratio)
    lag_gain = 1.0 / math.sqrt(1.0 + (wc * scale.current_lag) ** 2)
    # |C(j w_c)| |P(j w_c)| g = 1 with |C| = K_d w_c sqrt(1 + 1/a^2), |P| = 1 / (w_c |B + j J w_c|)
    plant = math.hypot(scale.damping, scale.inertia * wc)
    kd = plant / (math.sqrt(1.0 + 1.0 / (a * a)) * lag_gain)
    return {"p": kd * wc / a, "d": kd}


def tracking_reference(scale: JointScale, duration: float = 20.0, seed: int = 1) -> dict[str, Any]:
    """Band-limited random position reference sized to the joint.

    Amplitude: the RMS speed of a band-limited random signal of amplitude ``A`` and cut-off ``f_c``
    is about ``A 2 pi f_c / sqrt(3)``; ``f_c`` = 1 Hz or a decade below the tracking loop's
    crossover, whichever is lower, and ``A`` so that the RMS speed is a few
    Stribeck velocities (or 0.2 of the plateau range), within a fifth of the travel and a tenth of
    the speed limit: the joint reverses often and spends its time where friction dominates.
    """
    ratio = scale.inertia / scale.damping if scale.damping > 0 else math.inf
    wc = crossover(scale.current_lag, scale.loop_delay, damping_ratio=ratio)
    cutoff = min(1.0, wc / (2.0 * math.pi) / 10.0)  # a decade below the tracking loop's crossover
    v_target = (
        3.0 * scale.stribeck_velocity if math.isfinite(scale.stribeck_velocity) else 0.02 * scale.speed_limit
    )
    v_target = min(v_target, 0.1 * scale.speed_limit)
    v_target = max(v_target, 30.0 * scale.resolution)  # 30 counts per second at least
    amp = v_target * math.sqrt(3.0) / (2.0 * math.pi * cutoff)
    amp = min(amp, 0.2 * scale.travel)
    return {
        "type": "band_limited_random",
        "amplitude": float(amp),
        "cutoff": cutoff,
        "duration": float(duration),
        "seed": int(seed),
    }


def _time_to_move(x: float, force: float, J: float, B: float) -> float:
    """Time for ``force`` to move ``J`` against damping ``B`` by ``x`` from rest:
    ``x(t) = (F/B) (t - tau (1 - e^{-t/tau}))``, ``tau = J/B`` (``F t^2 / (2 J)`` for ``B = 0``)."""
    if B <= 0:
        return math.sqrt(2.0 * x * J / force)
    tau = J / B

    def dist(t):
        return force / B * (t - tau * (1.0 - math.exp(-t / tau)))

    lo, hi = 0.0, 1.0
    while dist(hi) < x and hi < 1e6:
        hi *= 2.0
    for _ in range(80):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if dist(mid) < x else (lo, mid)
    return hi


def experiment_config(scale: JointScale, profile: str = "quick") -> dict[str, Any]:
    """An excitation-program config (``friction_ros.core.excitation`` format) sized to ``scale``."""
    from friction_ros.core.excitation import profile_defaults

    c = copy.deepcopy(profile_defaults(profile))
    quick = profile == "quick"
    Fb = scale.breakaway
    load = scale.load
    settle = max(0.2, 10.0 * scale.current_lag, 50.0 * scale.loop_delay)
    v_cap = 0.4 * scale.speed_limit
    if scale.damping > 0:  # the speed the actuator can hold against viscous damping, with margin
        v_cap = min(v_cap, 0.4 * max(scale.torque_limit - abs(load) - Fb, 0.0) / scale.damping)
    # ramps to 3x breakaway (4x ceiling), plus what accelerates the inertia to the fastest plateau within the settle time
    t_max = min(
        scale.torque_limit,
        4.0 * Fb + abs(load) + 2.0 * scale.inertia * v_cap / settle + 1.5 * scale.damping * v_cap,
    )
    # velocity (= position) loop
    g = tracking_gains(scale)
    c["dt"] = scale.period
    c["velocity_loop"].update(
        p=float(g["d"]), i=float(g["p"]), torque_limit=float(t_max - abs(load)), inertia=float(scale.inertia)
    )
    # plateaus
    p = c["plateaus"]
    v_enc = 20.0 * scale.resolution / 1.0
    vs = scale.stribeck_velocity
    v_min = max(v_enc, vs / 5.0) if math.isfinite(vs) else max(v_enc, 1e-3 * scale.speed_limit)
    hold = min(max(0.5, 20.0 * scale.resolution / v_min), 2.0)
    v_max = min(v_cap, 0.5 * scale.travel / (settle + hold))
    if v_max <= v_min * 1.5:
        v_min = v_max / 10.0
        hold = min(max(0.5, 20.0 * scale.resolution / v_min), 2.0)
    count = 5 if quick else 8
    p.update(v_min=float(v_min), v_max=float(v_max), count=count, settle=float(settle), hold=float(hold))
    p["repeats"] = 1 if quick else 2
    # breakaway ramps: a step must move the joint `counts` counts within one step once it breaks
    # away, x = (step / J) t^2 / 2 >= counts * resolution, so the step time follows from the step;
    # the ramp from 0.5 F_b to 2.5 F_b must fit the time budget (coarse steps for a coarse encoder)
    b = c["breakaway"]
    counts = 2
    thr = counts * scale.resolution
    b_max = min(3.0 * Fb, t_max - abs(load))
    start = 0.5 * Fb
    budget = 8.0 if quick else 20.0  # seconds per ramp
    t_min = max(0.008, 8.0 * scale.period, 4.0 * (scale.current_lag + scale.loop_delay))
    step = Fb / 200.0
    for _ in range(60):
        step_time = min(max(_time_to_move(thr, step, scale.inertia, scale.damping), t_min), 0.5)
        if (b_max - start) / step * step_time <= budget:
            break
        step *= 1.25
    b.update(
        start=float(start),
        step=float(step),
        step_time=float(step_time),
        max=float(b_max),
        counts=counts,
        resolution=float(scale.resolution),
        preload_time=float(max(0.3, 20.0 * t_min)),
        release=float(max(0.3, 20.0 * t_min)),
    )
    # open-loop cycles and chirp
    c["presliding"]["amplitudes"] = (
        [float(0.4 * Fb), float(0.8 * Fb)] if quick else [float(a * Fb) for a in (0.3, 0.6, 0.85)]
    )
    c["presliding"]["frequency"] = 1.0
    ch = c["chirp"]
    ch.update(amplitude=float(min(1.3 * Fb, t_max - abs(load))), final_amplitude=float(0.5 * Fb))
    # random velocity
    r = c["random"]
    r["amplitude"] = float(min(0.5 * v_max, max(3.0 * v_min, 0.1 * v_max)))
    # limits
    # one encoder count within one period reads as resolution / period before the velocity filter: a
    # speed limit below that would trip on a single count of a coarse encoder
    c["limits"].update(
        max_travel=float(scale.travel),
        max_velocity=float(max(scale.speed_limit, 1.5 * scale.resolution / scale.period)),
        max_torque=float(t_max),
    )
    c["bias"] = float(-load)
    c.pop("profile", None)
    return c
