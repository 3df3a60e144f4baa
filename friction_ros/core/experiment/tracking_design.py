"""Tracking gains and reference sized to a joint (:class:`~friction_ros.core.experiment.joint_scale.JointScale`).

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
"""

from __future__ import annotations

import math
from typing import Any

from friction_ros.core.experiment.joint_scale import JointScale
from friction_ros.core.validation import ParameterError

#: phase margin of the loop tuning rule [deg]
DEFAULT_PHASE_MARGIN = 45.0
#: share of the available torque one encoder count may command through the derivative gain
ENCODER_TORQUE_SHARE = 0.5
ZERO_RATIO = 4.0


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
