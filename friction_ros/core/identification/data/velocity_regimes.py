"""Velocity regimes of a record: moving, standstill, high velocity (boolean masks over samples)."""

from __future__ import annotations

import math

import numpy as np


def mask_runs(mask: np.ndarray) -> list[tuple[int, int]]:
    """``(start, stop)`` index pairs of the runs where ``mask`` is true (stop exclusive)."""
    m = np.concatenate([[False], mask, [False]]).astype(np.int8)
    d = np.diff(m)
    return list(zip(np.nonzero(d == 1)[0], np.nonzero(d == -1)[0]))


def velocity_envelope(v: np.ndarray, dt: float, window: float = 1.0) -> np.ndarray:
    """Moving RMS of the velocity over ``window`` seconds (centred), a proxy of ABB M19-S paper's envelope."""
    # a record shorter than the window (e.g. the part of a cut-off bag that survived): the whole record
    w = min(max(int(round(window / dt)), 1), max(len(v), 1))
    k = np.ones(w) / w
    return np.sqrt(np.convolve(np.asarray(v) ** 2, k, mode="same"))


def moving_mask(v: np.ndarray, resolution: float, dt: float) -> np.ndarray:
    """Samples where the joint moves: |v| above the velocity noise floor.

    The floor is the larger of 3x the robust velocity noise (median |dv| / sqrt 2) and one encoder
    count per 20 ms: below it a differentiated position is quantisation noise, not motion.
    """
    v = np.asarray(v, dtype=float)
    return np.abs(v) > motion_floor(v, resolution)


def motion_floor(v: np.ndarray, resolution: float) -> float:
    """The speed below which a differentiated position is noise (see :func:`moving_mask`)."""
    v = np.asarray(v, dtype=float)
    noise = float(np.median(np.abs(np.diff(v)))) / math.sqrt(2.0) if v.size > 1 else 0.0
    return max(3.0 * noise, resolution / 0.02 if resolution > 0 else 0.0, 1e-9)


def standstill_mask(v: np.ndarray, resolution: float, dt: float, dwell: float = 0.5) -> np.ndarray:
    """Samples of a standstill: a run at rest (not :func:`moving_mask`) longer than ``dwell`` s.

    At rest the friction equals whatever torque holds the joint (anywhere within +-fs, AI friction chapter
    B.3; a drive switched off at the end of a log holds 0), so a standstill before, between or
    after the experiments carries no information an output-error model can be scored on; the
    whole run is left out. Shorter stops (reversals, pauses between plateaus) are kept.
    """
    v = np.asarray(v, dtype=float)
    rest = ~moving_mask(v, resolution, dt)
    out = np.zeros(v.shape, bool)
    skip = max(int(round(dwell / dt)), 1)
    for i0, i1 in mask_runs(rest):
        if i1 - i0 > skip:
            out[i0:i1] = True
    return out


def high_velocity_mask(
    v: np.ndarray, dt: float, threshold: float | None = None, moving: np.ndarray | None = None
) -> tuple[np.ndarray, float]:
    """Classify *moving* samples as high (envelope above threshold) or low velocity (ABB M19-S paper Table 1).

    Default threshold: geometric mean of the 5th and 95th percentiles of the 1 s velocity RMS over
    the moving samples only (samples at rest, e.g. a standstill before or after the experiment,
    would otherwise pull the low percentile to the noise floor). Returns the high mask; the low set
    is ``moving & ~high``.
    """
    env = velocity_envelope(v, dt)
    if moving is None:
        moving = np.ones(env.shape, bool)
    if threshold is None:
        sel = env[moving] if np.any(moving) else env
        lo, hi = np.percentile(sel, [5, 95])
        threshold = float(math.sqrt(max(lo, 1e-9) * max(hi, 1e-9)))
    return (env > threshold) & moving, float(threshold)
