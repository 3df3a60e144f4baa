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
Encoder bound: one count reads as ``count_velocity = resolution / max(filter, period)`` in
the measured velocity; ``K_d count_velocity <= (torque_limit - |load|) / 2``, else both gains are
scaled down (same zero, lower crossover). The velocity loop of the experiment is the same law on
the velocity error's integral (its ``p`` is the PD's ``K_d``, its ``i`` the PD's ``K_p``), which is
why it doubles as the position-loop gains of the plateaus.

**Experiment rule** (seed 004 B.3 procedures, seed 003 A.3 excitation, scaled), ``F_b`` the
breakaway estimate, ``F_c`` the Coulomb level, ``v_s`` the Stribeck velocity (1/e of the drop):

* control period = the joint's (the preset's ``control_period``);
* plateau settle ``max(0.2 s, 10 tau, 50 T, 10 / w_c)``; fastest plateau
  ``v_max = min(0.4 v_limit, T_a / (2 (B + 2 J / settle)), travel / (2 (settle + hold)))`` with
  ``T_a = torque_limit - |load| - F_b`` (reached within half the settle, held against damping);
* below ``v_s`` the joint sticks until the loop's integral has risen by ``F_b - F_c``: the
  reference runs ahead by ``d = (F_b - F_c) / K_p`` and stick-slip repeats about every ``d``.
  Every plateau settles over at least ``1.5 d`` and holds over at least ``max(5 d, 10 counts)``
  (``settle_travel``/``hold_travel``), so its mean speed is within ~20 % even when it stick-slips;
  lowest plateau ``v_min = max(v_s / 2, min(v_d, 0.8 v_s))`` with ``v_d`` the speed covering that
  distance in 8 s (quick) / 16 s (default); ``max(v_d, 1e-3 v_limit)`` when ``v_s`` is unknown;
  5 (quick) / 8 (default) log-spaced speeds, both directions, so the joint returns;
* coarse encoder (the slowest plateau sees isolated counts: ``count_velocity > 10 v_min``): both
  velocity-loop gains are scaled so that one count of error commands at most ``F_b``
  (``K_i q + K_v count_velocity <= F_b``, :func:`plateau_loop_softening`), the loop gets the
  feed-forward ``B v + F_c sgn(v)`` and the settle covers two of its slowest time constants;
* torque ceiling ``max_torque = min(torque_limit, 4 F_b + |load| + 2 J v_max / settle + 1.5 B v_max)``;
* breakaway ramp: preload ``0.5 F_b``, up to ``min(3 F_b, max_torque - |load|)``, steps from ``F_b / 200``
  (coarser if the ramp would exceed its time budget) held long enough that the joint, once it
  slides, moves 2 counts within one step (``(step / J) t^2 / 2 >= 2 resolution``); the detection
  lag (one step plus the excess torque that moves 2 counts within one step) goes with the ramp;
* presliding and chirp torques as fractions of ``F_b`` (0.4/0.8 or 0.3/0.6/0.85, and 1.3 -> 0.5);
* the random velocity's RMS amplitude ``min(v_max / 2, max(3 v_min, v_max / 10))``;
* limits: travel, speed (at least 1.5 counts per period), the torque ceiling;
* a constant load (gravity) is added to every open-loop torque (``bias``) so the ramps and cycles
  are centred on the torque that holds the joint; the velocity loop's integral holds it too.
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
#: share of the available torque one encoder count may command through the derivative gain
ENCODER_TORQUE_SHARE = 0.5
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


def _pd_design(scale: JointScale, phase_margin_deg: float, a: float) -> tuple[float, float, float]:
    """``(K_p, K_d, w_c)`` of the phase-margin rule with the encoder bound (see tracking_gains)."""
    ratio = scale.inertia / scale.damping if scale.damping > 0 else math.inf
    wc = crossover(scale.current_lag, scale.loop_delay, phase_margin_deg, a, ratio)
    lag_gain = 1.0 / math.sqrt(1.0 + (wc * scale.current_lag) ** 2)
    # |C(j w_c)| |P(j w_c)| g = 1 with |C| = K_d w_c sqrt(1 + 1/a^2), |P| = 1 / (w_c |B + j J w_c|)
    plant = math.hypot(scale.damping, scale.inertia * wc)
    kd = plant / (math.sqrt(1.0 + 1.0 / (a * a)) * lag_gain)
    kp = kd * wc / a
    k = ENCODER_TORQUE_SHARE * (scale.torque_limit - abs(scale.load)) / (kd * scale.count_velocity)
    if k >= 1.0:
        return kp, kd, wc
    # lower gains, same zero w_z = w_c / a: the crossover falls to w_c' where
    # K_d' |j w_c' + w_z| = w_c' |B + j J w_c'| (the lag and delay phase only shrink)
    kd_b, wz = kd * k, wc / a
    lo, hi = 0.0, wc
    for _ in range(100):
        w = 0.5 * (lo + hi)
        gain = kd_b * math.hypot(w, wz) / (w * math.hypot(scale.damping, scale.inertia * w))
        lo, hi = (w, hi) if gain > 1.0 else (lo, w)
    return kd_b * wz, kd_b, lo


def tracking_gains(
    scale: JointScale, phase_margin_deg: float = DEFAULT_PHASE_MARGIN, a: float = ZERO_RATIO
) -> dict[str, float]:
    """PD gains ``{"p": K_p, "d": K_d}`` for position tracking (module docstring's phase-margin rule).

    Encoder bound: the derivative acts on the measured velocity, in which one encoder count reads
    as ``count_velocity``; ``K_d count_velocity <= (torque_limit - |load|) / 2`` keeps a single count
    from saturating the drive (a coarse encoder otherwise drives a count-sized limit cycle). When it
    binds, both gains are scaled down together (same zero, lower crossover, more phase margin).
    """
    kp, kd, _ = _pd_design(scale, phase_margin_deg, a)
    return {"p": kp, "d": kd}


def tracking_crossover(scale: JointScale, phase_margin_deg: float = DEFAULT_PHASE_MARGIN) -> float:
    """Crossover [rad/s] of the loop closed with :func:`tracking_gains` (encoder bound included)."""
    return _pd_design(scale, phase_margin_deg, ZERO_RATIO)[2]


def tracking_reference(scale: JointScale, duration: float = 20.0, seed: int = 1) -> dict[str, Any]:
    """Band-limited random position reference sized to the joint (``references`` config format).

    The RMS speed of a band-limited random signal of amplitude ``A`` and cut-off ``f_c`` is about
    ``A 2 pi f_c / sqrt(3)``. ``f_c`` = 1 Hz or a decade below the crossover of
    :func:`tracking_gains`, whichever is lower; ``A`` so that the RMS speed is three Stribeck
    velocities (2 % of the speed limit when unknown, at least 30 counts/s), and at least three times
    the PD's dead band ``F_b / K_p`` (a smaller reference would leave the joint stuck); within a fifth
    of the travel; ``f_c`` lowered if the RMS speed would exceed a tenth of the speed limit. The
    joint then reverses about ``2 f_c`` times a second and spends its time at friction-dominated
    speeds.
    """
    kp, _, wc = _pd_design(scale, DEFAULT_PHASE_MARGIN, ZERO_RATIO)
    cutoff = min(1.0, wc / (2.0 * math.pi) / 10.0)
    v_target = (
        3.0 * scale.stribeck_velocity if math.isfinite(scale.stribeck_velocity) else 0.02 * scale.speed_limit
    )
    v_target = min(v_target, 0.1 * scale.speed_limit)
    v_target = max(v_target, 30.0 * scale.resolution)  # 30 counts per second at least
    amp = v_target * math.sqrt(3.0) / (2.0 * math.pi * cutoff)
    amp = min(max(amp, 3.0 * scale.breakaway / kp), 0.2 * scale.travel)
    v_rms = amp * 2.0 * math.pi * cutoff / math.sqrt(3.0)
    if v_rms > 0.1 * scale.speed_limit:
        cutoff *= 0.1 * scale.speed_limit / v_rms
    return {
        "type": "band_limited_random",
        "amplitude": float(amp),
        "cutoff": float(cutoff),
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


def _force_to_move(x: float, t: float, J: float, B: float) -> float:
    """Force that moves ``J`` against damping ``B`` by ``x`` within ``t`` from rest (the inverse of
    :func:`_time_to_move`): ``x B / (t - tau (1 - e^{-t/tau}))``, ``2 x J / t^2`` for ``B = 0``."""
    if B <= 0:
        return 2.0 * x * J / (t * t)
    tau = J / B
    return x * B / max(t - tau * (1.0 - math.exp(-t / tau)), 1e-300)


#: torque one encoder count of error may command in the plateau velocity loop, as a share of F_b
COUNT_TORQUE_SHARE = 1.0
#: the plateau loop is softened only when the slowest plateau sees isolated counts: one count reads
#: as more than this many times its speed (seed000_gearhead: 101, chatters; seed002: 3.3 and
#: abb_m19s: 4.1, plateau torque scatter 0.6-6 % of the mean with the full gains)
ISOLATED_COUNTS = 10.0


def plateau_loop_softening(scale: JointScale, kv: float, ki: float) -> float:
    """Factor (<= 1) for both velocity-loop gains so that one encoder count of error commands at most
    ``COUNT_TORQUE_SHARE F_b``: ``K_i q + K_v count_velocity <= F_b``.

    Measured on the 60-count joint encoder of seed000_gearhead: unbounded (1.6 N*m per count,
    45 times F_b) the loop chatters on a count edge, the joint reverses in 23-54 % of every slow
    plateau and the plateau means miss the friction by -75..+21 %; bounded (factor 0.022) no
    reversal, means within +2..+4 %. A factor 0.3 of that bound is too soft to follow the
    plateaus at all. Fine encoders are not affected (factor 1)."""
    count_torque = ki * scale.resolution + kv * scale.count_velocity
    if count_torque <= 0 or not math.isfinite(scale.breakaway) or scale.breakaway <= 0:
        return 1.0
    return float(min(1.0, COUNT_TORQUE_SHARE * scale.breakaway / count_torque))


def experiment_config(scale: JointScale, profile: str = "quick") -> dict[str, Any]:
    """An excitation-program config (``friction_ros.core.excitation`` format) sized to ``scale``."""
    from friction_ros.core.excitation import profile_defaults

    c = copy.deepcopy(profile_defaults(profile))
    quick = profile == "quick"
    Fb = scale.breakaway
    load = scale.load
    J, B = scale.inertia, scale.damping
    g = tracking_gains(scale)  # the velocity loop is the same law: p = K_d, i = K_p
    kv, ki = float(g["d"]), float(g["p"])
    wc = tracking_crossover(scale)
    counts = 10  # counts a plateau hold must cover: the hold's mean speed is then within 10 %
    low_time = 8.0 if quick else 16.0  # settle + hold of the lowest plateau at most [s]
    settle = max(0.2, 10.0 * scale.current_lag, 50.0 * scale.loop_delay, 10.0 / wc)
    # below the Stribeck velocity the joint sticks until the loop's integral (K_p times the position
    # error) has risen from the Coulomb level to the breakaway torque: the reference runs ahead by
    # d = (F_b - F_c) / K_p, whatever the speed, and stick-slip repeats about every d of travel.
    # A plateau settles over 1.5 d and holds over 5 d (and `counts` counts), so its mean is within
    # about 20 % even when it stick-slips; the lowest speed keeps that within `low_time`.
    drop = max(Fb - scale.coulomb, 0.0) if math.isfinite(scale.coulomb) else 0.0
    vs = scale.stribeck_velocity

    def travels(ki: float) -> tuple[float, float, float]:
        d_stick = drop / ki
        settle_travel = 1.5 * d_stick
        hold_travel = max(counts * scale.resolution, 5.0 * d_stick)
        v_time = (settle_travel + hold_travel) / low_time
        if math.isfinite(vs):
            v_min = max(0.5 * vs, min(v_time, 0.8 * vs))
        else:
            v_min = max(v_time, 1e-3 * scale.speed_limit)
        return settle_travel, hold_travel, v_min

    settle_travel, hold_travel, v_min = travels(ki)
    soft = plateau_loop_softening(scale, kv, ki) if scale.count_velocity > ISOLATED_COUNTS * v_min else 1.0
    if soft < 1.0:
        # coarse encoder: the slow plateaus see isolated counts, and one count must not command more
        # than the breakaway torque, else the loop chatters across a count edge and the joint
        # reverses within a plateau; the softened loop gets the damping and Coulomb level as
        # feed-forward and settles over two of its slowest time constants (J s^2 + (B + K_v) s + K_i)
        kv, ki = kv * soft, ki * soft
        poles = np.roots([J, B + kv, ki])
        if np.all(poles.real < 0):
            settle = max(settle, 2.0 / float(np.min(-poles.real)))
        settle_travel, hold_travel, v_min = travels(ki)
    hold = 0.5
    # fastest plateau: a fraction of the speed limit that the torque left after load and breakaway
    # can reach within half the settle (inertia) and hold (damping): v (B + 2 J / settle) <= T_a / 2
    t_avail = max(scale.torque_limit - abs(load) - Fb, 0.0)
    v_cap = min(0.4 * scale.speed_limit, 0.5 * t_avail / (B + 2.0 * J / settle))
    # ramps to 3x breakaway (4x ceiling), plus what accelerates the inertia to the fastest plateau
    t_max = min(scale.torque_limit, 4.0 * Fb + abs(load) + 2.0 * J * v_cap / settle + 1.5 * B * v_cap)
    c["dt"] = scale.period
    c["velocity_loop"].update(p=kv, i=ki, torque_limit=float(t_max - abs(load)), inertia=float(J))
    if soft < 1.0:
        fc = scale.coulomb if math.isfinite(scale.coulomb) else Fb
        c["velocity_loop"].update(damping=float(B), coulomb=float(fc))
    p = c["plateaus"]
    v_max = min(v_cap, 0.5 * scale.travel / (settle + hold))
    if v_max <= v_min * 1.5:
        v_min = v_max / 10.0
    count = 5 if quick else 8
    p.update(
        v_min=float(v_min),
        v_max=float(v_max),
        count=count,
        settle=float(settle),
        hold=float(hold),
        settle_travel=float(settle_travel),
        hold_travel=float(hold_travel),
    )
    p["repeats"] = 1 if quick else 2
    # breakaway ramps: a step must move the joint `counts` counts within one step once it breaks
    # away, x = (step / J) t^2 / 2 >= counts * resolution, so the step time follows from the step;
    # the ramp from 0.5 F_b to 2.5 F_b must fit the time budget (coarse steps for a coarse encoder)
    b = c["breakaway"]
    counts = 2  # seed 004 B.3: "moves" = at least 2 encoder counts
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
        detection_lag=float(step + _force_to_move(thr, step_time, scale.inertia, scale.damping)),
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


#: share of ``limits.max_travel`` one plateau (or the random program's excursion) may use, and of
#: ``limits.max_velocity`` the fastest commanded speed may reach (room for overshoot)
LIMIT_SHARE = 0.5


def plateau_travel(plateaus: dict, v: float) -> float:
    """Distance [rad] one plateau at speed ``v`` covers (settle + hold, at least their travels)."""
    p = plateaus
    return max(v * p["settle"], p["settle_travel"]) + max(v * p["hold"], p["hold_travel"])


def fit_to_limits(config: dict[str, Any], keep: set[str] | frozenset[str] = frozenset()) -> dict[str, Any]:
    """``config`` (a complete excitation config, ``excitation.resolve_config``) with its speeds
    re-derived within its limits, so the program does not run into them.

    Plateaus go out and back, so one plateau may cover ``LIMIT_SHARE`` of ``limits.max_travel``
    (:func:`plateau_travel`) and the fastest may run at ``LIMIT_SHARE`` of ``limits.max_velocity``;
    ``plateaus.v_max`` is lowered to fit and ``v_min`` with it (same span). The random program's
    amplitude is lowered until its excursion (the integral of its velocity) and its peak speed fit
    the same shares. Dotted keys in ``keep`` (what the user set) are not changed: if one of them
    does not fit, ParameterError names it, the limit and what would fit (bad input, not an abort
    after the run started). Torque-driven programs (breakaway, chirp, presliding) are left as they
    are: their travel depends on the joint.
    """
    from friction_ros.core.excitation import random_velocity

    c = copy.deepcopy(config)
    lim = c["limits"]
    travel, speed = LIMIT_SHARE * lim["max_travel"], LIMIT_SHARE * lim["max_velocity"]
    names = c["sequence"] if c["program"] == "sequence" else [c["program"]]
    p = c["plateaus"]
    if "plateaus" in names:
        fit = min(p["v_max"], speed)
        if plateau_travel(p, fit) > travel:  # travel grows with v: bisect the fastest that fits
            lo, hi = 0.0, fit
            for _ in range(60):
                mid = 0.5 * (lo + hi)
                lo, hi = (mid, hi) if plateau_travel(p, mid) <= travel else (lo, mid)
            fit = lo
        if fit < p["v_max"]:
            if "plateaus.v_max" in keep or fit <= 0.0:
                why = (
                    f"{plateau_travel(p, p['v_max']):.4g} rad per plateau, more than {LIMIT_SHARE:g} x "
                    f"limits.max_travel = {lim['max_travel']:g} rad"
                    if plateau_travel(p, p["v_max"]) > travel
                    else f"more than {LIMIT_SHARE:g} x limits.max_velocity = {lim['max_velocity']:g} rad/s"
                )
                hint = f"at most {fit:.4g} rad/s" if fit > 0 else "lower plateaus.settle_travel/hold_travel"
                raise ParameterError(
                    f"plateaus.v_max = {p['v_max']:g} rad/s is out of range for the limits: {why}; "
                    f"must be {hint} (or raise the limit)"
                )
            ratio = fit / p["v_max"]
            p["v_max"] = float(fit)
            if "plateaus.v_min" not in keep:
                p["v_min"] = float(p["v_min"] * ratio)
            if p["v_min"] > p["v_max"]:
                raise ParameterError(
                    f"plateaus.v_min = {p['v_min']:g} rad/s is out of range: must be <= plateaus.v_max = "
                    f"{p['v_max']:.4g} rad/s, the fastest plateau that fits the limits"
                )
    if "random" in names:
        r = c["random"]
        unit = random_velocity({**c, "random": {**r, "amplitude": 1.0}})
        excursion = float(np.max(np.abs(np.cumsum(unit)))) * c["dt"]
        peak = float(np.max(np.abs(unit)))
        fit = min(r["amplitude"], travel / max(excursion, 1e-300), speed / max(peak, 1e-300))
        if fit < r["amplitude"]:
            if "random.amplitude" in keep:
                raise ParameterError(
                    f"random.amplitude = {r['amplitude']:g} rad/s is out of range for the limits: its excursion "
                    f"{r['amplitude'] * excursion:.4g} rad and peak {r['amplitude'] * peak:.4g} rad/s must stay "
                    f"within {LIMIT_SHARE:g} x limits.max_travel = {lim['max_travel']:g} rad and "
                    f"{LIMIT_SHARE:g} x limits.max_velocity = {lim['max_velocity']:g} rad/s: at most {fit:.4g}"
                )
            r["amplitude"] = float(fit)
    return c
