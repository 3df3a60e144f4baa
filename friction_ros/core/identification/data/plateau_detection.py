"""Constant-velocity plateaus of a record and what they say about the load.

**Plateaus** (constant-velocity segments, AI friction chapter B.3 experiment 2): from ExperimentEvent
   START/END markers (program containing ``plateau``) when present, otherwise detected
   automatically as runs where the velocity stays within a tolerance of its running mean; the first
   ``settle`` seconds (AI friction chapter: 0.2 s) of each are discarded; each gives (mean v, mean tau,
   spread).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from friction_ros.core.experiment.events import completed_segments, start_settle
from friction_ros.core.identification.data.data_scale import velocity_scale
from friction_ros.core.identification.data.records import JointData, quantization_velocity_noise
from friction_ros.core.identification.data.velocity_regimes import mask_runs


@dataclass
class Plateau:
    """A constant-velocity segment: mean velocity and torque with their spread (AI friction chapter)."""

    t_start: float
    t_end: float
    velocity: float
    torque: float
    torque_std: float
    velocity_std: float
    n: int
    source: str = "auto"


def find_plateaus(
    data: JointData,
    *,
    settle: float | None = None,
    min_duration: float = 0.3,
    rel_tol: float = 0.05,
    min_speed: float | None = None,
    dropped: list[str] | None = None,
) -> list[Plateau]:
    """Constant-velocity plateaus: from ``plateau`` event markers if any, else automatic detection.

    ``dropped``: if given, a line per marked plateau left out, with its speed, time and why.

    ``settle`` [s]: the transient discarded at each plateau's start; None = what each START marker
    says (``settle=<s>``: the experiment sizes it per plateau), else 0.2 s.

    Automatic: a sample belongs to a plateau when the 0.25 s running mean of the velocity is steady
    within ``max(rel_tol |v|, 3 noise)``, the samples scatter by less than 60 % around it
    (stick-slip at low speed is allowed) and |v| > ``min_speed``; runs shorter
    than ``settle + min_duration`` are dropped and the first ``settle`` seconds discarded.

    A marked plateau whose two halves' mean torques differ by more than 4 standard errors is
    dropped: not steady sliding (intermittent stick-slip at the low end of the loop's stable range);
    only where the strict stick-slip test applies (velocity noise of the encoder below the 60 %).
    """
    v, tau, dt = data.velocity, data.torque, data.dt
    out: list[Plateau] = []
    pairs = completed_segments(data.events, "plateau")
    if pairs:
        # a coarse encoder makes the differentiated velocity noisy without any stick-slip
        q_noise = quantization_velocity_noise(data)
        for s, e in pairs:
            i0 = int(
                np.searchsorted(data.t, s.time + (settle if settle is not None else start_settle(s, 0.2)))
            )
            i1 = int(np.searchsorted(data.t, e.time))

            def drop(why: str, s=s, e=e) -> None:
                if dropped is not None:
                    at = f"{s.target:+.4g}" if math.isfinite(s.target) else "?"
                    dropped.append(f"plateau {at} (t {s.time:.2f}-{e.time:.2f} s): {why}")

            if i1 - i0 < max(int(min_duration / dt / 3), 5):
                drop("too short after its settling time")
                continue
            vv, tt = v[i0:i1], tau[i0:i1]
            # not at the commanded speed (stuck or stick-slip below the breakaway): not a plateau
            if math.isfinite(s.target) and abs(vv.mean() - s.target) > 0.2 * abs(s.target):
                drop(
                    f"mean speed {vv.mean():.4g}, more than 20 % off the commanded speed (stuck or stick-slip)"
                )
                continue
            # stick-slip scatters the velocity by more than 60 % of its mean; when encoder quantization
            # alone would (a coarse encoder), only scatter beyond 3x that noise counts
            limit = 0.6 * abs(vv.mean())
            if vv.std() > (limit if q_noise < limit else 3.0 * q_noise):
                drop(f"speed scatter {vv.std():.3g} over 60 % of its mean (stick-slip, not steady sliding)")
                continue
            if q_noise < limit and _drifting(tt):  # a coarse encoder's plateaus keep the relaxed test
                drop("its two halves' mean torques differ by more than 4 standard errors (not steady)")
                continue
            out.append(
                Plateau(
                    data.t[i0],
                    data.t[i1 - 1],
                    float(vv.mean()),
                    float(tt.mean()),
                    float(tt.std()),
                    float(vv.std()),
                    i1 - i0,
                    "events",
                )
            )
        return out
    w = max(int(round(0.25 / dt)), 3)
    k = np.ones(w) / w
    vm = np.convolve(v, k, mode="same")
    dev = np.sqrt(np.convolve((v - vm) ** 2, k, mode="same"))
    noise = float(np.median(np.abs(np.diff(v)))) / math.sqrt(2) + 1e-12
    if min_speed is None:
        min_speed = max(10 * noise, 1e-3 * velocity_scale(data))
    # the 0.25 s running mean must be steady; the samples may scatter (stick-slip at low speed)
    drift = np.abs(vm - np.convolve(vm, k, mode="same"))
    steady = (drift < np.maximum(rel_tol * np.abs(vm), 3 * noise)) & (
        dev < np.maximum(0.6 * np.abs(vm), 3 * noise)
    )
    steady &= np.abs(vm) > min_speed
    sign = np.sign(vm)
    settle = 0.2 if settle is None else settle
    for i0, i1 in mask_runs(steady):
        # split a run wherever the mean velocity drifts by more than rel_tol
        i0s = i0 + int(round(settle / dt))
        if i1 - i0s < int(round(min_duration / dt)):
            continue
        seg_v = v[i0s:i1]
        if np.any(sign[i0s:i1] != sign[i0s]):
            continue
        ref = np.median(seg_v)
        if np.max(np.abs(vm[i0s:i1] - ref)) > max(3 * rel_tol * abs(ref), 6 * noise):
            continue
        tt = tau[i0s:i1]
        out.append(
            Plateau(
                data.t[i0s],
                data.t[i1 - 1],
                float(seg_v.mean()),
                float(tt.mean()),
                float(tt.std()),
                float(seg_v.std()),
                i1 - i0s,
            )
        )
    return out


def _drifting(tau: np.ndarray, k: float = 4.0) -> bool:
    """True when the torque means of a plateau's two halves differ by more than ``k`` standard
    errors: the joint is not in steady sliding (at the low end of a velocity loop's stable range it
    stick-slips for part of the plateau, the velocity reversing under a scatter that still passes
    the 60 % test, and the mean torque drops below the steady-state curve: -10 mN*m at 0.024 rad/s on
    the ABB preset, one half -3, the other -17, where steady plateaus' halves agree within 1.2)."""
    h = len(tau) // 2
    if h < 10:
        return False
    a, b = tau[:h], tau[h : 2 * h]
    se = math.sqrt((a.var() + b.var()) / h)
    return bool(abs(a.mean() - b.mean()) > k * se)


def chattering_plateaus(plateaus: list[Plateau]) -> list[Plateau]:
    """Plateaus whose torque scatters by more than its mean (load removed): the loop was chattering
    (measured: 0.6-6 % on six presets, 2-20x on a 60-count joint encoder whose velocity loop flips
    the torque across a count edge), so the joint reverses within the plateau and the mean torque
    is not the friction at the mean speed."""
    load, _ = load_offset(plateaus)
    return [p for p in plateaus if p.torque_std > abs(p.torque - load)]


def mirrored_pairs(plateaus: list[Plateau], rel_tol: float = 0.05) -> list[tuple[Plateau, Plateau]]:
    """(+v, -v) plateau pairs whose speeds agree within ``rel_tol`` (each positive plateau with the
    first matching negative one)."""
    pos = [p for p in plateaus if p.velocity > 0]
    neg = [p for p in plateaus if p.velocity < 0]
    out = []
    for a in pos:
        for b in neg:
            if abs(abs(b.velocity) - a.velocity) <= rel_tol * a.velocity:
                out.append((a, b))
                break
    return out


def load_offset(plateaus: list[Plateau], rel_tol: float = 0.05) -> tuple[float, str]:
    """A constant load torque (gravity on a vertical axis, a spring preload) seen in the plateaus.

    For plateau pairs at +v and -v (speeds within ``rel_tol``), friction is odd and a constant
    load even: ``c = mean((tau(+v) + tau(-v)) / 2)``. Asymmetric friction looks the same, so ``c``
    is taken as a load only when it is larger than half the friction level
    ``mean((tau(+v) - tau(-v)) / 2)`` (no plausible asymmetry does that). Returns ``(c, note)`` or
    ``(0.0, "")``.
    """
    pairs = mirrored_pairs(plateaus, rel_tol)
    sums = [0.5 * (a.torque + b.torque) for a, b in pairs]
    diffs = [0.5 * (a.torque - b.torque) for a, b in pairs]
    if len(sums) < 2:
        return 0.0, ""
    c, f = float(np.mean(sums)), float(np.mean(np.abs(diffs)))
    if abs(c) <= 0.5 * f:
        return 0.0, ""
    return c, (
        f"a constant load torque of {c:+.4g} N*m (mean of the +v/-v plateau pairs, {len(sums)} pairs; "
        f"friction level {f:.4g}) was removed before fitting and is exported as load_feedforward"
    )
