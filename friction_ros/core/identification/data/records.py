"""Data preparation for friction identification: arrays in, a uniform, differentiated record out.

Steps (all SI, REP-103 signs):

1. **Torque**: ``sensor_msgs/JointState.effort`` is the joint torque [N*m]; or a current [A]
   converted as ``tau = K_t * N * i`` (torque constant x gear ratio; ABB M19-S paper A.1: "the measured
   current is assumed to correspond to the torque").
2. **Time alignment**: messages are sorted by stamp, duplicates dropped, and everything (also a
   current from another topic) is linearly interpolated onto one uniform grid with the median
   sample period (``dt``) of the joint states.
3. **Velocity / acceleration** from position by Savitzky-Golay differentiation (polynomial order 3,
   zero phase, so no lag offline): velocity window ``velocity_window`` (default 21 ms),
   acceleration window ``acceleration_window`` (default 41 ms). With the ABB M19-S paper encoder
   (1.05e-4 rad) at 1 kHz the velocity noise is ~1e-3 rad/s and the -3 dB bandwidth ~30 Hz, well
   above the 4 Hz excitation. If only a velocity field exists, it is used and differentiated.

The record (:class:`JointData`) is then searched for plateaus
(:mod:`~friction_ros.core.identification.data.plateau_detection`), breakaways
(:mod:`~friction_ros.core.identification.data.breakaway_detection`) and split for training
(:mod:`~friction_ros.core.identification.data.training_split`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from scipy.signal import savgol_filter

from friction_ros.core.experiment.events import Event
from friction_ros.core.validation import ParameterError, check_real


class ExcitationError(ParameterError):
    """The data lack something a fit needs; the message says what and which experiment provides it."""


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
    # torque the gear transmits to the link (load_terms.transmitted_torque), for load-dependent
    # friction; None until a load model has been estimated
    transmitted: np.ndarray | None = None

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
            None if self.transmitted is None else self.transmitted[i0:i1],
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
    if events and ts.size > 3:
        # a state or two stamped at the very start of the experiment, and none earlier, is its
        # initial state: a recorder catches it or misses it by a sample; left out, both recordings
        # give the same record (and the same grid, bit for bit). A log that starts well before its
        # first event keeps everything.
        first = min(e.time for e in events)
        after = ts > first
        lead = ts[~after]
        dt0 = float(np.median(np.diff(ts)))
        if 0 < lead.size <= 2 and float(first - lead[0]) <= 2.0 * dt0 and int(after.sum()) >= 3:
            ts = ts[after]
            pos, vel, eff = (None if x is None else x[after] for x in (pos, vel, eff))
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

    tr = None if any(r.transmitted is None for r in records) else cat("transmitted")
    return JointData(
        cat("t"),
        cat("position"),
        cat("velocity"),
        cat("acceleration"),
        cat("torque"),
        records[0].dt,
        [],
        records[0].resolution,
        meta={k: v for k, v in records[0].meta.items() if k in ("velocity_scale", "torque_scale")},
        transmitted=tr,
    )
