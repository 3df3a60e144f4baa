"""Content-based selection of a long log's samples: a bounded, informative part for the fit.

A long log holds far more samples than a fit needs, and the fit's cost grows with every sample it
simulates. :func:`bound_records` keeps at most ``max_samples`` samples in all (shared between the
records by their length). Each record is cut into pieces of a few seconds, cut where possible at a
velocity reversal from + to - (the pieces are joined back to back, and there the motion and the
friction state on either side of a join match best). Pieces holding an experiment segment (event
markers), a constant-velocity plateau or a breakaway are kept first, whole (up to half the
budget, by content when there are more); the rest of the budget
goes to the pieces that add the most content not yet covered: speeds in both directions,
accelerations, positions and velocity reversals (greedy on square-root returns, so the kept part
covers the whole range rather than repeating the commonest motion). The choice depends only on
the data: the same log always gives the same samples. The kept part is one record per input
record, with a warning saying what was used ("used N of M samples: ...").
"""

from __future__ import annotations

import math

import numpy as np

from friction_ros.core.experiment.events import Event, completed_segments
from friction_ros.core.identification.data.records import JointData

#: samples a fit keeps by default (5 min at 1 kHz: an identification experiment is used whole; a
#: robot's hour-long log is cut down): ~10 s of training, the rest validation
DEFAULT_MAX_SAMPLES = 300_000
PIECES = 24  # pieces per budget: enough for variety, few joins
PIECE_SECONDS = (1.0, 10.0)  # a piece lasts this long at least / at most [s]
PLATEAU_SHARE = 0.05  # detected plateaus covering this share of a record make it a plateau experiment
FORCED_SHARE = 0.5  # at most this share of the budget goes to segments, plateaus and breakaways first
_V_BINS, _A_BINS, _Q_BINS = 12, 3, 16


def bound_records(records: list[JointData], max_samples: int | None = DEFAULT_MAX_SAMPLES) -> list[JointData]:
    """``records`` with at most ``max_samples`` samples in all (None or <= 0: unchanged)."""
    total = sum(r.n for r in records)
    if not max_samples or max_samples <= 0 or total <= max_samples:
        return list(records)
    out = []
    for r in records:
        budget = max(int(max_samples * r.n / total), 1)
        out.append(r if r.n <= budget else decimate(r, budget))
    return out


def decimate(data: JointData, budget: int) -> JointData:
    """The pieces of ``data`` chosen by content (module docstring), joined into one record."""
    dt = data.dt
    L = int(np.clip(budget // PIECES, round(PIECE_SECONDS[0] / dt), round(PIECE_SECONDS[1] / dt)))
    L = max(min(L, budget), 2)
    edges = piece_edges(data.velocity, L)
    groups = _groups(data, edges)
    features = _features(data, edges)
    chosen, forced_dropped = _select(groups, features, edges, budget)
    keep = [(int(edges[a]), int(edges[b])) for a, b in chosen]
    if not keep:  # every piece is larger than the budget (one long segment): its first samples
        keep = [(0, min(budget, data.n))]
    out = splice(data, keep)
    used = out.n
    n_forced = sum(1 for g in groups if g[2])
    kept_forced = sum(1 for g in groups if g[2] and (g[0], g[1]) in set(chosen))
    merged = _merged(keep)
    spans = ", ".join(f"{data.t[a]:.0f}-{data.t[b - 1]:.0f} s" for a, b in merged[:8])
    more = f" and {len(merged) - 8} more" if len(merged) > 8 else ""
    special = ""
    if n_forced:
        special = f", with {kept_forced} of {n_forced} experiment segments, plateaus and breakaways" + (
            " (the budget does not hold them all)" if forced_dropped else ""
        )
    note = (
        f"used {used} of {data.n} samples ({100.0 * used / data.n:.1f} %, {used * dt:.0f} of {data.n * dt:.0f} s): "
        f"{len(merged)} stretches chosen for their content (velocity reversals, speeds in both directions, "
        f"accelerations, positions){special}, joined back to back; kept: {spans}{more}; "
        "raise --max-samples to use more"
    )
    out.meta["warnings"] = list(out.meta.get("warnings", [])) + [note]
    out.meta["decimation"] = {
        "used": used,
        "of": data.n,
        "kept": [[int(a), int(b)] for a, b in merged],
    }
    return out


def piece_edges(velocity: np.ndarray, length: int) -> np.ndarray:
    """Piece boundaries about ``length`` samples apart, moved to a + to - velocity reversal within a
    quarter piece when there is one (first and last edge: 0 and n)."""
    n = velocity.size
    down = np.flatnonzero((velocity[:-1] > 0) & (velocity[1:] <= 0)) + 1
    edges = [0]
    nominal = length
    while nominal < n - length // 2:
        lo, hi = np.searchsorted(down, [nominal - length // 4, nominal + length // 4])
        cut = nominal
        if hi > lo:  # the reversal nearest the nominal edge
            cand = down[lo:hi]
            cut = int(cand[np.argmin(np.abs(cand - nominal))])
        if cut - edges[-1] >= max(length // 2, 2):
            edges.append(cut)
        nominal = max(cut, edges[-1]) + length
    edges.append(n)
    return np.asarray(edges, dtype=np.int64)


def _must_keep(data: JointData, block_seconds: float = 120.0) -> list[tuple[float, float, int]]:
    """(t0, t1 [s], priority) kept whole: experiment segments (priority 2); detected plateaus when they
    make up a plateau experiment (>= PLATEAU_SHARE of the record; the odd constant-speed moment of
    ordinary motion is not one, and keeping those would turn the fit into a plateau fit) and
    breakaways as instants (priority 1: their piece is kept; they join no pieces). Searched in blocks of ``block_seconds`` overlapping by
    10 s: the searches cost more than linear time on a long record."""
    from friction_ros.core.identification.data.breakaway_detection import find_breakaways
    from friction_ros.core.identification.data.plateau_detection import find_plateaus

    spans = [(s.time - 0.05, e.time + 0.2, 2) for s, e in completed_segments(data.events, "")]
    step, over = int(round(block_seconds / data.dt)), int(round(10.0 / data.dt))
    plateaus = []
    for i0 in range(0, data.n, step):
        part = data.slice(i0, min(i0 + step + over, data.n))
        if part.n < 3:
            continue
        plateaus += [(p.t_start - 1.0, p.t_end + 0.3, 1) for p in find_plateaus(part)]
        spans += [(b.time, b.time, 1) for b in find_breakaways(part)]
    if sum(t1 - t0 - 1.3 for t0, t1, _ in plateaus) >= PLATEAU_SHARE * data.duration:
        spans += plateaus
    return spans


def _groups(data: JointData, edges: np.ndarray) -> list[tuple[int, int, int]]:
    """(first piece, end piece, priority) covering the record: a must-keep interval joins the pieces
    it touches into one group of its priority (0: none)."""
    m = edges.size - 1
    link = np.zeros(m, bool)  # link[k]: piece k and k+1 are one group
    forced = np.zeros(m, int)
    for t0, t1, prio in _must_keep(data):
        i0, i1 = np.searchsorted(data.t, [t0, t1])
        k0 = int(np.clip(np.searchsorted(edges, i0, side="right") - 1, 0, m - 1))
        k1 = int(np.clip(np.searchsorted(edges, max(i1, i0 + 1), side="left") - 1, k0, m - 1))
        forced[k0 : k1 + 1] = np.maximum(forced[k0 : k1 + 1], prio)
        if t1 > t0:
            link[k0:k1] = True
    out, a = [], 0
    for k in range(m):
        if not link[k] or k == m - 1:
            out.append((a, k + 1, int(forced[a : k + 1].max())))
            a = k + 1
    return out


def _features(data: JointData, edges: np.ndarray, block: int = 1 << 18) -> np.ndarray:
    """Per piece: sample counts in (velocity x acceleration) bins, position bins, and reversals
    (computed in blocks of samples: a long record needs no full-length temporaries)."""
    v, a, q = data.velocity, data.acceleration, data.position
    scale = float(np.percentile(np.abs(v), 99.5)) or 1.0
    v_lo = max(scale * 1e-3, 1e-6)
    a_cut = np.percentile(np.abs(a), [50, 90])
    q_cut = np.percentile(q, np.linspace(0, 100, _Q_BINS + 1)[1:-1])
    n_joint = (2 * _V_BINS + 1) * 2 * _A_BINS
    m = edges.size - 1
    feats = np.zeros((m, n_joint + _Q_BINS + 1))
    last_sign = 0.0
    for i0 in range(0, v.size, block):
        sl = slice(i0, min(i0 + block, v.size))
        vv, aa = v[sl], a[sl]
        av = np.abs(vv)
        moving = av > v_lo
        mag = np.log(np.maximum(av, v_lo) / v_lo) * (_V_BINS / math.log(scale / v_lo))
        vb = np.where(moving, np.where(vv > 0, 1, _V_BINS + 1) + np.clip(mag, 0, _V_BINS - 1).astype(int), 0)
        ab = np.searchsorted(a_cut, np.abs(aa)) * 2 + (aa > 0)
        piece = np.searchsorted(edges, np.arange(sl.start, sl.stop), side="right") - 1
        np.add.at(feats, (piece, vb * (2 * _A_BINS) + ab), 1.0)
        np.add.at(feats, (piece, n_joint + np.searchsorted(q_cut, q[sl])), 1.0)
        s = np.sign(np.where(moving, vv, 0.0))
        nz = np.flatnonzero(s)
        if nz.size:
            prev = np.concatenate([[last_sign], s[nz[:-1]]])
            flips = nz[(prev != 0) & (prev != s[nz])]
            np.add.at(feats, (piece[flips], -1), 200.0)  # a reversal counts like 200 samples
            last_sign = float(s[nz[-1]])
    return feats


def _select(groups, feats: np.ndarray, edges: np.ndarray, budget: int) -> tuple[list[tuple[int, int]], bool]:
    """Groups chosen greedily within ``budget``: experiment segments and plateaus, then breakaways (these
    two up to FORCED_SHARE of it), then any, each time the largest content gain per sample."""
    gf = np.array([feats[a:b].sum(axis=0) for a, b, _ in groups])
    cost = np.array([int(edges[b] - edges[a]) for a, b, _ in groups], dtype=float)
    prio = np.array([f for _, _, f in groups], int)
    covered = np.zeros(feats.shape[1])
    taken = np.zeros(len(groups), bool)
    used = 0
    dropped = False
    for phase in (2, 1, 0):
        limit = int(budget * FORCED_SHARE) if phase else budget
        while True:
            ok = ~taken & (cost <= limit - used) & (prio >= phase)
            if not ok.any():
                break
            gain = (np.sqrt(covered + gf) - np.sqrt(covered)).sum(axis=1) / cost
            gain[~ok] = -np.inf
            k = int(np.argmax(gain))
            taken[k] = True
            covered += gf[k]
            used += int(cost[k])
        if phase and ((prio >= phase) & ~taken).any():
            dropped = True
    return [(a, b) for (a, b, _), t in zip(groups, taken) if t], dropped


def _merged(keep: list[tuple[int, int]]) -> list[tuple[int, int]]:
    out: list[list[int]] = []
    for a, b in sorted(keep):
        if out and a <= out[-1][1]:
            out[-1][1] = max(out[-1][1], b)
        else:
            out.append([a, b])
    return [(a, b) for a, b in out]


def splice(data: JointData, keep: list[tuple[int, int]]) -> JointData:
    """The sample ranges ``keep`` of ``data`` back to back on one uniform time grid (events moved along)."""
    keep = _merged(keep)
    idx = np.concatenate([np.arange(a, b) for a, b in keep])
    n = idx.size
    events: list[Event] = []
    pos = 0
    joins = []
    for a, b in keep:
        if pos:
            joins.append(float(pos * data.dt))
        t0, t1 = data.t[a], data.t[b - 1]
        shift = pos * data.dt - t0
        events += [
            Event(e.time + shift, e.program, e.segment, e.index, e.event, e.target, e.note)
            for e in data.events
            if t0 <= e.time <= t1
        ]
        pos += b - a
    meta = dict(data.meta)
    meta["joins_t"] = joins  # times [s] where a piece starts: derivatives must not reach across
    return JointData(
        data.dt * np.arange(n),
        data.position[idx],
        data.velocity[idx],
        data.acceleration[idx],
        data.torque[idx],
        data.dt,
        events,
        data.resolution,
        data.t0,
        meta,
        None if data.transmitted is None else data.transmitted[idx],
    )


def piecewise_derivatives(data: JointData, window: int) -> tuple[np.ndarray, np.ndarray] | None:
    """Savitzky-Golay (cubic, ``window`` samples) velocity and acceleration of the position, taken
    piece by piece between the joins of a spliced record (a position step at a join is no motion);
    None when the record has no joins. A piece shorter than the window keeps the record's own."""
    from scipy.signal import savgol_filter

    cuts = np.searchsorted(data.t, data.meta.get("joins_t") or [])
    cuts = cuts[(cuts > 0) & (cuts < data.n)]
    if not cuts.size:
        return None
    v, a = data.velocity.copy(), data.acceleration.copy()
    for i0, i1 in zip([0, *cuts], [*cuts, data.n]):
        if i1 - i0 > window:
            q = data.position[i0:i1]
            v[i0:i1] = savgol_filter(q, window, 3, deriv=1, delta=data.dt, mode="interp")
            a[i0:i1] = savgol_filter(q, window, 3, deriv=2, delta=data.dt, mode="interp")
    return v, a
