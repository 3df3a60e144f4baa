"""Data preparation for friction identification: arrays in, a uniform, differentiated record out.

Pipeline (all SI, REP-103 signs):

1. **Torque**: ``sensor_msgs/JointState.effort`` is the joint torque [N*m]; or a current [A]
   converted as ``tau = K_t * N * i`` (torque constant x gear ratio; seed 003 A.1: "the measured
   current is assumed to correspond to the torque").
2. **Time alignment**: messages are sorted by stamp, duplicates dropped, and everything (also a
   current from another topic) is linearly interpolated onto one uniform grid with the median
   sample period (``dt``) of the joint states.
3. **Velocity / acceleration** from position by Savitzky-Golay differentiation (polynomial order 3,
   zero phase, so no lag offline): velocity window ``velocity_window`` (default 21 ms),
   acceleration window ``acceleration_window`` (default 41 ms). With the seed 003 encoder
   (1.05e-4 rad) at 1 kHz the velocity noise is ~1e-3 rad/s and the -3 dB bandwidth ~30 Hz, well
   above the 4 Hz excitation. If only a velocity field exists, it is used and differentiated.
4. **Plateaus** (constant-velocity segments, seed 004 B.3 experiment 2): from ExperimentEvent
   START/END markers (program containing ``plateau``) when present, otherwise detected
   automatically as runs where the velocity stays within a tolerance of its running mean; the first
   ``settle`` seconds (seed 004: 0.2 s) of each are discarded; each gives (mean v, mean tau,
   spread).
5. **Breakaway** (seed 004 B.3 experiment 1): the torque at the first sample where the position
   has moved ``breakaway_counts`` (seed 004: 2) encoder counts from rest, inside ``breakaway``
   segments or automatically after a dwell at rest.
6. **Train/validation split**: seed 003 A.3 trains on the first 10 s and validates on the rest.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field

import numpy as np
from scipy.signal import savgol_filter

from friction_ros.core.validation import ParameterError, check_real

START, END, ABORT = 0, 1, 2


class ExcitationError(ParameterError):
    """The data lack something a fit needs; the message says what and which experiment provides it."""


@dataclass
class Event:
    """One friction_msgs/ExperimentEvent marker."""

    time: float
    program: str
    segment: str
    index: int
    event: int
    target: float = math.nan
    note: str = ""


@dataclass
class Plateau:
    """A constant-velocity segment: mean velocity and torque with their spread (seed 004)."""

    t_start: float
    t_end: float
    velocity: float
    torque: float
    torque_std: float
    velocity_std: float
    n: int
    source: str = "auto"


@dataclass
class Breakaway:
    """Torque at which the joint left rest (seed 004: 2 encoder counts of motion)."""

    time: float
    torque: float
    direction: int
    source: str = "auto"
    lag: float = math.nan  # torque the detection may have needed beyond the breakaway (ramp START note)


@dataclass
class JointData:
    """A uniform record of one joint: time, position, velocity, acceleration, torque."""

    t: np.ndarray
    position: np.ndarray
    velocity: np.ndarray
    acceleration: np.ndarray
    torque: np.ndarray
    dt: float
    events: list[Event] = field(default_factory=list)
    resolution: float = 0.0
    t0: float = 0.0
    meta: dict = field(default_factory=dict)

    @property
    def n(self) -> int:
        return int(self.t.shape[0])

    @property
    def duration(self) -> float:
        return float(self.n * self.dt)

    def slice(self, i0: int, i1: int) -> JointData:
        """Samples i0..i1-1 (events kept when inside)."""
        t0, t1 = (self.t[i0] if i0 < self.n else np.inf), (self.t[i1 - 1] if i1 > i0 else -np.inf)
        return JointData(
            self.t[i0:i1],
            self.position[i0:i1],
            self.velocity[i0:i1],
            self.acceleration[i0:i1],
            self.torque[i0:i1],
            self.dt,
            [e for e in self.events if t0 <= e.time <= t1],
            self.resolution,
            self.t0,
            dict(self.meta),
        )


def _window(seconds: float, dt: float, order: int) -> int:
    w = int(round(seconds / dt)) | 1
    return max(w, order + 2 + ((order + 2) % 2 == 0))


def quantization_velocity_noise(data: JointData) -> float:
    """Standard deviation [rad/s] that encoder quantization alone puts on the velocity estimate.

    Uniform quantization error of resolution q has sigma q / sqrt(12); the Savitzky-Golay
    derivative (order 3, ``velocity_window_s``) multiplies it by the norm of its coefficients / dt.
    0 when the position is continuous or the velocity was measured.
    """
    if data.resolution <= 0 or not str(data.meta.get("velocity_source", "Savitzky")).startswith("Savitzky"):
        return 0.0
    from scipy.signal import savgol_coeffs

    w = _window(float(data.meta.get("velocity_window_s", 0.021)), data.dt, 3)
    gain = float(np.linalg.norm(savgol_coeffs(w, 3, deriv=1, delta=data.dt)))
    return data.resolution / math.sqrt(12.0) * gain


def estimate_resolution(position: np.ndarray) -> float:
    """Encoder resolution estimated as the smallest common non-zero position step (0 if continuous)."""
    d = np.abs(np.diff(position))
    d = d[d > 1e-12]
    if d.size < 10:
        return 0.0
    q = float(np.percentile(d, 1))
    # quantised data: most steps are integer multiples of q
    ratio = d / q
    if np.mean(np.abs(ratio - np.round(ratio)) < 0.05) > 0.9:
        return q
    return 0.0


#: a gap between joint-state stamps above this (and 1e4 sample periods) is another clock [s]
CLOCK_JUMP_SECONDS = 3600.0


def prepare(
    t,
    position=None,
    velocity=None,
    effort=None,
    *,
    current=None,
    current_t=None,
    torque_constant: float | None = None,
    gear_ratio: float = 1.0,
    events: list[Event] | None = None,
    velocity_window: float = 0.021,
    acceleration_window: float = 0.041,
    torque_delay: float = 0.0,
    source: str = "arrays",
) -> JointData:
    """Build a uniform :class:`JointData` from raw arrays (see module docstring for the steps).

    ``t`` are message stamps [s]; ``position`` [rad], ``velocity`` [rad/s] and ``effort`` [N*m]
    are per-message arrays (None when absent). When ``effort`` is None, ``current`` [A] (with its
    own stamps ``current_t`` if from another topic) times ``torque_constant`` [N*m/A] times
    ``gear_ratio`` gives the joint torque. ``torque_delay`` [s] aligns a torque that lags the
    motion (e.g. half a sample period plus the current-loop time constant of a simulated plant).
    """
    t = np.asarray(t, dtype=float)
    if t.ndim != 1 or t.size < 3:
        raise ExcitationError(
            f"samples = {t.size}: need at least 3 joint-state messages; record a run with the "
            "identification experiment (friction-experiment) first"
        )
    order = np.argsort(t, kind="stable")
    t = t[order]
    keep = np.concatenate([[True], np.diff(t) > 0])

    def pick(x):
        if x is None:
            return None
        x = np.asarray(x, dtype=float)[order][keep]
        return x

    ts = t[keep]
    pos, vel, eff = pick(position), pick(velocity), pick(effort)
    # stamps from another clock (wall time among simulated time) would stretch the uniform grid
    # over decades: keep the largest run of samples without such a jump and say what was left out
    clock_note = ""
    steps = np.diff(ts)
    jump = max(CLOCK_JUMP_SECONDS, 1e4 * float(np.median(steps)))
    cuts = np.nonzero(steps > jump)[0]
    if cuts.size:
        bounds = np.concatenate([[0], cuts + 1, [ts.size]])
        b = int(np.argmax(np.diff(bounds)))
        sl = slice(int(bounds[b]), int(bounds[b + 1]))
        clock_note = (
            f"{ts.size - (sl.stop - sl.start)} joint states stamped up to {float(steps[cuts].max()):.3g} s away "
            "from the rest (a clock mix-up) were left out"
        )
        ts = ts[sl]
        pos, vel, eff = (None if x is None else x[sl] for x in (pos, vel, eff))
        if ts.size < 3:
            raise ExcitationError("time: fewer than 3 joint states share one clock")
    if eff is None or not np.any(np.isfinite(eff)):
        if current is None:
            raise ExcitationError(
                "torque: the joint states carry no effort and no current was given; pass the current "
                "topic/field with --current-field, --torque-constant and --gear-ratio"
            )
        kt = check_real("torque_constant", torque_constant, 0.0, lo_open=True, unit="N*m/A")
        n_ratio = check_real("gear_ratio", gear_ratio, 0.0, lo_open=True)
        ct = ts if current_t is None else np.asarray(current_t, dtype=float)
        cur = np.asarray(current, dtype=float)
        co = np.argsort(ct, kind="stable")
        eff = np.interp(ts, ct[co], cur[co]) * kt * n_ratio
    if pos is None and vel is None:
        raise ExcitationError("motion: the joint states carry neither position nor velocity")
    dts = np.diff(ts)
    dt = float(np.median(dts))
    if not dt > 0:
        raise ExcitationError("time: joint-state stamps do not increase")
    n = int(math.floor((ts[-1] - ts[0]) / dt + 1e-6)) + 1
    grid = ts[0] + dt * np.arange(n)

    def interp(x):
        ok = np.isfinite(x)
        return np.interp(grid, ts[ok], x[ok])

    # a torque measured ``torque_delay`` after the motion it causes (current-loop lag, a torque that
    # is the average over the sample period ...) is shifted back: tau(t) := tau_meas(t + delay)
    ok = np.isfinite(eff)
    tau = np.interp(grid + torque_delay, ts[ok], eff[ok])
    resolution = 0.0
    notes: list[str] = [clock_note] if clock_note else []
    if pos is not None and np.any(np.isfinite(pos)):
        p = interp(pos)
        resolution = estimate_resolution(pos[np.isfinite(pos)])
        wv = _window(velocity_window, dt, 3)
        wa = _window(acceleration_window, dt, 3)
        if n > wa:
            v = savgol_filter(p, wv, 3, deriv=1, delta=dt, mode="interp")
            a = savgol_filter(p, wa, 3, deriv=2, delta=dt, mode="interp")
        else:
            v = np.gradient(p, dt)
            a = np.gradient(v, dt)
        velocity_source = "Savitzky-Golay differentiation of the position"
        if np.mean(np.isfinite(pos)) < 0.9:
            notes.append(
                f"{100 * np.mean(~np.isfinite(pos)):.0f} % of the positions are not finite: interpolated over"
            )
    else:
        if vel is None or not np.any(np.isfinite(vel)):
            raise ExcitationError("motion: every position and velocity sample is missing or not finite")
        velocity_source = "the messages' velocity field (no finite position)"
        notes.append(
            "the joint states carry no finite position: velocity is the messages' velocity field, position "
            "is its integral, and no encoder resolution is known"
        )
        v = interp(vel)
        p = np.concatenate([[0.0], np.cumsum(0.5 * (v[1:] + v[:-1]) * dt)])
        wa = _window(acceleration_window, dt, 3)
        a = savgol_filter(v, wa, 3, deriv=1, delta=dt, mode="interp") if n > wa else np.gradient(v, dt)
    evs = sorted(events or [], key=lambda e: e.time)
    evs = [Event(e.time - ts[0], e.program, e.segment, e.index, e.event, e.target, e.note) for e in evs]
    return JointData(
        grid - ts[0],
        p,
        v,
        a,
        tau,
        dt,
        evs,
        resolution,
        float(ts[0]),
        {
            "source": source,
            "velocity_source": velocity_source,
            "warnings": notes,
            "velocity_window_s": velocity_window,
            "acceleration_window_s": acceleration_window,
        },
    )


def concatenate(records: list[JointData]) -> list[JointData]:
    """Several bags are kept as separate records (dynamic states restart per record)."""
    return list(records)


def concat_records(records: list[JointData]) -> JointData:
    """One record with the samples of ``records`` back to back (a single record is returned as is).

    For pooled statistics and plots: events and metadata are dropped, ``dt`` and ``resolution`` are
    the first record's.
    """
    if len(records) == 1:
        return records[0]

    def cat(k: str) -> np.ndarray:
        return np.concatenate([getattr(r, k) for r in records])

    return JointData(
        cat("t"),
        cat("position"),
        cat("velocity"),
        cat("acceleration"),
        cat("torque"),
        records[0].dt,
        [],
        records[0].resolution,
    )


# ------------------------------------------------------------------------------ split
def split(data: JointData, train_seconds: float = 10.0) -> tuple[JointData, JointData]:
    """Seed 003 A.3: the first ``train_seconds`` for training, the remainder for validation."""
    check_real("train_seconds", train_seconds, 0.0, lo_open=True, unit="s")
    i = int(round(train_seconds / data.dt))
    if i >= data.n - 10:
        raise ExcitationError(
            f"train_seconds = {train_seconds:g} leaves no validation data in a {data.duration:.1f} s record: "
            "record longer (seed 003: 50 s, 10 s train + 40 s validation) or lower --train-seconds"
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
            "record longer (seed 003: 50 s, 10 s train + 40 s validation) or lower --train-seconds"
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
            "record longer (seed 003: 50 s, 10 s train + 40 s validation) or lower --train-seconds"
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


# ------------------------------------------------------------------------------ velocity regimes
def velocity_envelope(v: np.ndarray, dt: float, window: float = 1.0) -> np.ndarray:
    """Moving RMS of the velocity over ``window`` seconds (centred), a proxy of seed 003's envelope."""
    w = max(int(round(window / dt)), 1)
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

    At rest the friction equals whatever torque holds the joint (anywhere within +-fs, seed 004
    B.3; a drive switched off at the end of a log holds 0), so a standstill before, between or
    after the experiments carries no information an output-error model can be scored on; the
    whole run is left out. Shorter stops (reversals, pauses between plateaus) are kept.
    """
    v = np.asarray(v, dtype=float)
    rest = ~moving_mask(v, resolution, dt)
    out = np.zeros(v.shape, bool)
    skip = max(int(round(dwell / dt)), 1)
    for i0, i1 in _runs(rest):
        if i1 - i0 > skip:
            out[i0:i1] = True
    return out


def high_velocity_mask(
    v: np.ndarray, dt: float, threshold: float | None = None, moving: np.ndarray | None = None
) -> tuple[np.ndarray, float]:
    """Classify *moving* samples as high (envelope above threshold) or low velocity (seed 003 Table 1).

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


# ------------------------------------------------------------------------------ plateaus
def _runs(mask: np.ndarray) -> list[tuple[int, int]]:
    m = np.concatenate([[False], mask, [False]]).astype(np.int8)
    d = np.diff(m)
    return list(zip(np.nonzero(d == 1)[0], np.nonzero(d == -1)[0]))


def _segment_pairs(events: list[Event], key: str) -> list[tuple[Event, Event]]:
    out = []
    open_: dict[tuple[str, int], Event] = {}
    for e in events:
        if key not in e.program.lower() and key not in e.segment.lower():
            continue
        k = (e.program, e.index)
        if e.event == START:
            open_[k] = e
        elif e.event == END and k in open_:
            out.append((open_.pop(k), e))
        elif e.event == ABORT:
            open_.pop(k, None)
    return out


_SETTLE_NOTE = re.compile(r"settle=([0-9.eE+-]+)")
_LAG_NOTE = re.compile(r"\blag=([0-9.eE+-]+)")


def start_lag(event: Event) -> float:
    """The detection lag a breakaway ramp's START marker states (``lag=<N*m>``), else NaN."""
    m = _LAG_NOTE.search(event.note or "")
    return float(m.group(1)) if m else math.nan


def start_settle(event: Event, default: float) -> float:
    """The transient a plateau's START marker says to discard (``settle=<s>`` in its note) [s]."""
    m = _SETTLE_NOTE.search(event.note or "")
    return float(m.group(1)) if m else default


def find_plateaus(
    data: JointData,
    *,
    settle: float | None = None,
    min_duration: float = 0.3,
    rel_tol: float = 0.05,
    min_speed: float | None = None,
) -> list[Plateau]:
    """Constant-velocity plateaus: from ``plateau`` event markers if any, else automatic detection.

    ``settle`` [s]: the transient discarded at each plateau's start; None = what each START marker
    says (``settle=<s>``: the experiment sizes it per plateau), else 0.2 s.

    Automatic: a sample belongs to a plateau when the 0.25 s running mean of the velocity is steady
    within ``max(rel_tol |v|, 3 noise)``, the samples scatter by less than 60 % around it
    (stick-slip at low speed is allowed) and |v| > ``min_speed``; runs shorter
    than ``settle + min_duration`` are dropped and the first ``settle`` seconds discarded.
    """
    v, tau, dt = data.velocity, data.torque, data.dt
    out: list[Plateau] = []
    pairs = _segment_pairs(data.events, "plateau")
    if pairs:
        # a coarse encoder makes the differentiated velocity noisy without any stick-slip
        q_noise = quantization_velocity_noise(data)
        for s, e in pairs:
            i0 = int(
                np.searchsorted(data.t, s.time + (settle if settle is not None else start_settle(s, 0.2)))
            )
            i1 = int(np.searchsorted(data.t, e.time))
            if i1 - i0 < max(int(min_duration / dt / 3), 5):
                continue
            vv, tt = v[i0:i1], tau[i0:i1]
            # not at the commanded speed (stuck or stick-slip below the breakaway): not a plateau
            if math.isfinite(s.target) and abs(vv.mean() - s.target) > 0.2 * abs(s.target):
                continue
            # stick-slip scatters the velocity by more than 60 % of its mean; when encoder quantization
            # alone would (a coarse encoder), only scatter beyond 3x that noise counts
            limit = 0.6 * abs(vv.mean())
            if vv.std() > (limit if q_noise < limit else 3.0 * q_noise):
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
        min_speed = max(10 * noise, 1e-3)
    # the 0.25 s running mean must be steady; the samples may scatter (stick-slip at low speed)
    drift = np.abs(vm - np.convolve(vm, k, mode="same"))
    steady = (drift < np.maximum(rel_tol * np.abs(vm), 3 * noise)) & (
        dev < np.maximum(0.6 * np.abs(vm), 3 * noise)
    )
    steady &= np.abs(vm) > min_speed
    sign = np.sign(vm)
    settle = 0.2 if settle is None else settle
    for i0, i1 in _runs(steady):
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


def find_breakaways(data: JointData, *, counts: int = 2, dwell: float = 0.2) -> list[Breakaway]:
    """Breakaway torques (seed 004 B.3): from the experiment's breakaway END events (their
    ``target`` is the torque of the step that moved the joint ``counts`` counts), else the peak
    torque of a rising ramp (``dwell`` seconds without sliding before) at the onset of gross
    sliding: more than 30 encoder counts within 50 ms, which the elastic creep under a preload
    (presliding, often tens of counts over the ramp) never reaches."""
    q = data.resolution if data.resolution > 0 else 1e-4
    thr = counts * q * 0.999
    pos, tau, dt = data.position, data.torque, data.dt
    out: list[Breakaway] = []
    pairs = _segment_pairs(data.events, "breakaway")
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


# ------------------------------------------------------------------------------ excitation checks
@dataclass
class Excitation:
    """Summary of what a record excites."""

    max_speed_pos: float
    max_speed_neg: float
    reversals: int
    motion_range: float
    low_speed_fraction: float
    n_plateaus_pos: int
    n_plateaus_neg: int
    plateau_decades: float
    motion_floor: float = 1e-3


def excitation(data: JointData, plateaus: list[Plateau]) -> Excitation:
    v = data.velocity
    floor = motion_floor(v, data.resolution)
    moving = np.abs(v) > floor
    sv = np.sign(v[moving])
    rev = int(np.sum(sv[1:] != sv[:-1])) if sv.size > 1 else 0
    pv = [abs(p.velocity) for p in plateaus if abs(p.velocity) > 0]
    dec = math.log10(max(pv) / min(pv)) if len(pv) >= 2 else 0.0
    return Excitation(
        float(max(v.max(), 0.0)),
        float(max(-v.min(), 0.0)),
        rev,
        float(np.ptp(data.position)),
        float(np.mean(np.abs(v[moving]) < 0.05)) if moving.any() else 0.0,
        sum(p.velocity > 0 for p in plateaus),
        sum(p.velocity < 0 for p in plateaus),
        dec,
        floor,
    )


def check_motion(data: JointData, label: str) -> None:
    """Raise ExcitationError if the joint never moved."""
    q = data.resolution if data.resolution > 0 else 1e-6
    if np.ptp(data.position) < 3 * q or not np.any(moving_mask(data.velocity, data.resolution, data.dt)):
        raise ExcitationError(
            f"{label}: no motion (position range {np.ptp(data.position):.3g} rad, max |v| "
            f"{np.max(np.abs(data.velocity)):.3g} rad/s); the joint must move: record the 'plateaus' "
            "experiment (constant-velocity plateaus in both directions) or seed 003's 'random' "
            "excitation (band-limited random velocity under a 10 s envelope)"
        )


def check_excitation(ex: Excitation, *, dynamic: bool, static_from_plateaus: bool, label: str) -> None:
    """Raise ExcitationError naming what is missing and the experiment that provides it."""
    missing = []
    floor = 2.0 * ex.motion_floor  # above what the encoder resolves, in the record's own units
    if ex.max_speed_pos < floor or ex.max_speed_neg < floor:
        d = "positive" if ex.max_speed_pos < floor else "negative"
        missing.append(f"motion in the {d} direction (run 'plateaus' in both directions)")
    if static_from_plateaus and (ex.n_plateaus_pos + ex.n_plateaus_neg) < 3:
        missing.append(
            f"constant-velocity plateaus (found {ex.n_plateaus_pos}+/{ex.n_plateaus_neg}-, need >= 3; "
            "run the 'plateaus' experiment over a log-spaced speed range)"
        )
    if dynamic and ex.reversals < 4:
        missing.append(
            f"velocity reversals for presliding dynamics (found {ex.reversals}, need >= 4; run seed 003's "
            "'random' excitation or the 'presliding' cycles)"
        )
    if missing:
        raise ExcitationError(f"{label}: too little excitation: missing " + "; ".join(missing))
