"""Breakaway torques of a record.

**Breakaway** (AI friction chapter B.3 experiment 1): the torque at the first sample where the position
   has moved ``breakaway_counts`` (AI friction chapter: 2) encoder counts from rest, inside ``breakaway``
   segments or automatically after a dwell at rest.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from friction_ros.core.experiment.events import completed_segments, start_lag
from friction_ros.core.identification.data.data_scale import velocity_scale
from friction_ros.core.identification.data.records import JointData


@dataclass
class Breakaway:
    """Torque at which the joint left rest (AI friction chapter: 2 encoder counts of motion)."""

    time: float
    torque: float
    direction: int
    source: str = "auto"
    lag: float = math.nan  # torque the detection may have needed beyond the breakaway (ramp START note)


def nd_after(data: JointData) -> int:
    """Samples looked at after a segment's end for the sliding that follows (50 ms)."""
    return max(int(round(0.05 / data.dt)), 2)


def _gross_sliding_onset(pos: np.ndarray, i_rest: int, i_end: int, thr: float, start: int | None = None):
    """First sample ``j`` that is ``thr`` from ``pos[i_rest]`` and after which the joint keeps going:
    within the next 50 samples it reaches 3 ``thr`` in the same direction (gross sliding). Presliding
    deflection under a preload stops short of that and is skipped."""
    i_end = min(i_end, pos.size)
    k = i_rest if start is None else start
    ref = pos[i_rest]
    while k < i_end:
        moved = np.nonzero(np.abs(pos[k:i_end] - ref) >= thr)[0]
        if not moved.size:
            return None
        j = k + int(moved[0])
        d = np.sign(pos[j] - ref)
        ahead = pos[j : min(j + 50, pos.size)]
        if ahead.size and np.max(d * (ahead - ref)) >= 3.0 * thr:
            return j
        k = j + 1
        ref = pos[j]  # the deflection so far was presliding: count from here
    return None


def find_breakaways(data: JointData, *, counts: int = 2, dwell: float = 0.2) -> list[Breakaway]:
    """Breakaway torques (AI friction chapter B.3): from the experiment's breakaway END events (their
    ``target`` is the torque of the step that moved the joint ``counts`` counts), else the peak
    torque of a rising ramp (``dwell`` seconds without sliding before) at the onset of gross
    sliding: more than 30 encoder counts within 50 ms, which the elastic creep under a preload
    (presliding, often tens of counts over the ramp) never reaches."""
    q = data.resolution if data.resolution > 0 else 1e-4 * velocity_scale(data)
    thr = counts * q * 0.999
    pos, tau, dt = data.position, data.torque, data.dt
    out: list[Breakaway] = []
    pairs = completed_segments(data.events, "breakaway")
    if pairs:
        for s, e in pairs:
            i0 = int(np.searchsorted(data.t, s.time))
            i1 = int(np.searchsorted(data.t, e.time))
            if math.isfinite(e.target) and e.target != 0.0:
                # the experiment measured it (motion counted per ramp step, after the preload)
                j = min(max(i1, 0), data.n - 1)
                out.append(
                    Breakaway(float(e.time), float(e.target), int(np.sign(e.target)), "events", start_lag(s))
                )
                continue
            if i1 - i0 < 2:
                continue
            j = _gross_sliding_onset(pos, i0, i1 + nd_after(data), thr)
            if j is not None:
                out.append(
                    Breakaway(float(data.t[j]), float(tau[j]), int(np.sign(pos[j] - pos[i0])), "events")
                )
        return out
    # without events: a torque ramp under which the joint creeps (presliding) or rests, then gross
    # sliding: more than 30 counts within 50 ms, which presliding under a slow ramp never does
    nd = max(int(round(dwell / dt)), 2)
    w = max(int(round(0.05 / dt)), 2)
    n = data.n
    slide = np.zeros(n, bool)
    slide[w:] = np.abs(pos[w:] - pos[:-w]) > 30.0 * q
    i = nd
    while i < n:
        hits = np.nonzero(slide[i:])[0]
        if not hits.size:
            break
        j = i + int(hits[0])
        quiet = not np.any(slide[j - nd + w : j])  # no sliding in the ramp window before
        # onset: the first sample of that 50 ms window that moved more than 2 counts from its start
        k0 = j - w
        moved = np.nonzero(np.abs(pos[k0 : j + 1] - pos[k0]) >= thr)[0]
        k = k0 + int(moved[0]) if moved.size else j
        d = int(np.sign(pos[j] - pos[k0]))
        # the torque pushed towards the motion and rose during the dwell (a ramp, not a release)
        pre = d * tau[j - nd : j + 1]
        rising = pre[-w:].max() > pre[:w].mean() + 0.02 * abs(pre).max()
        base = max(k - w, 0)
        peak = base + int(np.argmax(d * tau[base : k + 1]))
        if quiet and rising and d != 0 and d * tau[peak] > 0:
            out.append(Breakaway(float(data.t[k]), float(tau[peak]), d))
        i = j + nd
    return out
