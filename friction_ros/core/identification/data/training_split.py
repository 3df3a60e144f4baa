"""Train/validation split of a record.

**Train/validation split**: ABB M19-S paper A.3 trains on the first 10 s and validates on the rest.
"""

from __future__ import annotations

import math

import numpy as np

from friction_ros.core.experiment.events import START
from friction_ros.core.identification.data.records import ExcitationError, JointData
from friction_ros.core.identification.data.velocity_regimes import moving_mask
from friction_ros.core.validation import check_real


def split(data: JointData, train_seconds: float = 10.0) -> tuple[JointData, JointData]:
    """ABB M19-S paper A.3: the first ``train_seconds`` for training, the remainder for validation."""
    check_real("train_seconds", train_seconds, 0.0, lo_open=True, unit="s")
    i = int(round(train_seconds / data.dt))
    if i >= data.n - 10:
        raise ExcitationError(
            f"train_seconds = {train_seconds:g} leaves no validation data in a {data.duration:.1f} s record: "
            "record longer (ABB M19-S paper: 50 s, 10 s train + 40 s validation) or lower --train-seconds"
        )
    return data.slice(0, i), data.slice(i, data.n)


def training_window(data: JointData, train_seconds: float = 10.0, step: float = 0.5) -> tuple[int, int]:
    """Sample range ``[i0, i1)`` of the ``train_seconds`` window that excites the model most.

    Chosen by content, not by the clock: every window (``step`` apart) is scored by its velocity
    reversals while moving (presliding and direction changes, capped at 100) plus the share of the
    record's speed range it covers (``max |v|`` in the window over the record's); ties go to the
    earliest window. A standstill (before, after or between programs) scores nothing.
    """
    check_real("train_seconds", train_seconds, 0.0, lo_open=True, unit="s")
    w = int(round(train_seconds / data.dt))
    n = data.n
    if w >= n - 10:
        raise ExcitationError(
            f"train_seconds = {train_seconds:g} leaves no validation data in a {data.duration:.1f} s record: "
            "record longer (ABB M19-S paper: 50 s, 10 s train + 40 s validation) or lower --train-seconds"
        )
    v = data.velocity
    mv = moving_mask(v, data.resolution, data.dt)
    sgn = np.where(mv, np.sign(v), 0.0)
    # reversal k: the sign of the last moving sample before k differs from the sign at k
    idx = np.nonzero(sgn)[0]
    rev = np.zeros(n)
    if idx.size > 1:
        flips = idx[1:][sgn[idx[1:]] != sgn[idx[:-1]]]
        rev[flips] = 1.0
    crev = np.concatenate([[0.0], np.cumsum(rev)])
    vmax_all = float(np.max(np.abs(v))) or 1.0
    stride = max(int(round(step / data.dt)), 1)
    best, best_i = -1.0, 0
    absv = np.abs(v)
    for i0 in range(0, n - w + 1, stride):
        r = min(crev[i0 + w] - crev[i0], 100.0) / 100.0
        cover = float(np.max(absv[i0 : i0 + w])) / vmax_all
        score = r + cover
        if score > best + 1e-12:
            best, best_i = score, i0
    return best_i, best_i + w


def training_segments(
    data: JointData, train_seconds: float = 10.0, chunk: float | None = None
) -> list[tuple[int, int]]:
    """Sample ranges ``[i0, i1)`` for training, stratified by content so that training and
    validation both see reversals, high and low speeds.

    Rule (systematic stratified sampling): the record is cut into chunks at the experiment's
    START events (one segment of the program each) and every ``chunk`` seconds (default
    ``train_seconds / 4``, >= 1 s) within them; chunks mostly at rest (< 20 % moving) go to
    validation. The others are sorted by (has a velocity reversal, RMS speed while moving) and
    ``k`` evenly spaced ones in that order train, ``k`` the chunks needed for ``train_seconds``
    but at most half of them, so both sets span the speed range, with and without reversals.
    Adjacent training chunks are merged (dynamic states restart once per range).
    """
    check_real("train_seconds", train_seconds, 0.0, lo_open=True, unit="s")
    n, dt = data.n, data.dt
    if int(round(train_seconds / dt)) >= n - 10:
        raise ExcitationError(
            f"train_seconds = {train_seconds:g} leaves no validation data in a {data.duration:.1f} s record: "
            "record longer (ABB M19-S paper: 50 s, 10 s train + 40 s validation) or lower --train-seconds"
        )
    L = max(int(round((chunk or max(train_seconds / 4.0, 1.0)) / dt)), 2)
    cuts = {0, n}
    for e in data.events:
        if e.event == START:
            cuts.add(int(np.clip(np.searchsorted(data.t, e.time), 0, n)))
    bounds = sorted(cuts)
    chunks = []
    for a, b in zip(bounds[:-1], bounds[1:]):
        k = max(int(round((b - a) / L)), 1)
        edges = np.linspace(a, b, k + 1).round().astype(int)
        chunks += [(int(x), int(y)) for x, y in zip(edges[:-1], edges[1:]) if y > x]
    v = data.velocity
    mv = moving_mask(v, data.resolution, dt)
    feats = []
    for a, b in chunks:
        m = mv[a:b]
        if np.mean(m) < 0.2:
            continue
        sv = np.sign(v[a:b][m])
        rms = float(np.sqrt(np.mean(v[a:b][m] ** 2)))
        feats.append((bool(np.any(sv[1:] != sv[:-1])), math.log(max(rms, 1e-12)), a, b))
    feats.sort()
    m = len(feats)
    mean_len = float(np.mean([f[3] - f[2] for f in feats])) if m else 1.0
    k = min(int(math.ceil(int(round(train_seconds / dt)) / mean_len)), int(math.ceil(m / 2)))
    picked = (
        [(feats[j][2], feats[j][3]) for j in sorted({int((i + 0.5) * m / k) for i in range(k)})] if k else []
    )
    if not picked:  # nothing moves in chunks: the most varied window
        return [training_window(data, train_seconds)]
    picked.sort()
    merged = [list(picked[0])]
    for a, b in picked[1:]:
        if a <= merged[-1][1]:
            merged[-1][1] = max(merged[-1][1], b)
        else:
            merged.append([a, b])
    return [(a, b) for a, b in merged]
