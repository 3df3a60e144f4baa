"""Excitation programs sized to a joint (:class:`~friction_ros.core.experiment.joint_scale.JointScale`).

**Experiment rule** (AI friction chapter B.3 procedures, ABB M19-S paper A.3 excitation, scaled), ``F_b`` the
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
from typing import Any

import numpy as np

from friction_ros.core.experiment.joint_scale import JointScale
from friction_ros.core.experiment.tracking_design import tracking_crossover, tracking_gains
from friction_ros.core.validation import ParameterError


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
    """An excitation-program config (``friction_ros.core.experiment.excitation`` format) sized to ``scale``."""
    from friction_ros.core.experiment.excitation_config import profile_defaults

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
    c["control_period"] = scale.period
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
    counts = 2  # AI friction chapter B.3: "moves" = at least 2 encoder counts
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
    from friction_ros.core.experiment.velocity_programs import random_velocity

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
        excursion = float(np.max(np.abs(np.cumsum(unit)))) * c["control_period"]
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
