"""What one demo run measures: tracking runs through the ROS graph, their metrics, the encoder cap,
the fitted map's error against the preset's truth, and the per-preset :class:`DemoResult`."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from friction_ros.core.control_period import DEFAULT_CONTROL_PERIOD

# the ROS graph's control period (plant_simulator / compensating_controller / experiment default)
GRAPH_PERIOD = DEFAULT_CONTROL_PERIOD


def refusal_warning(mode: str, reason: str) -> str:
    """The demo's warning for a compensation mode the safety gate refused (one wording, one place)."""
    return f"{mode} compensation refused by the safety gate: {reason}"


@dataclass
class TrackingRun:
    """One closed-loop tracking run through the ROS graph (every control period, in order)."""

    label: str
    t: np.ndarray
    reference: np.ndarray
    reference_velocity: np.ndarray
    position: np.ndarray
    velocity: np.ndarray
    error: np.ndarray
    command: np.ndarray
    friction: np.ndarray
    wall_seconds: float
    enabled: bool = True
    reason: str = ""
    metrics: dict = field(default_factory=dict)
    #: 1 where the controller's compensation watch had switched compensation off (terms file)
    fallback: np.ndarray | None = None
    #: control periods of the run the controller did not compute (real time only; lockstep: 0)
    missing_periods: int = 0
    #: why the run's figures are not a measurement (real time: too many periods missed), else ""
    invalid: str = ""

    @classmethod
    def from_terms(cls, label: str, t: np.ndarray, col, wall: float, missing_periods: int = 0) -> TrackingRun:
        """A run from the controller's terms file: ``col(name)`` gives a column over the run's rows."""
        return cls(
            label=label,
            t=t,
            reference=col("reference_position"),
            reference_velocity=col("reference_velocity"),
            position=col("position"),
            velocity=col("velocity"),
            error=col("error"),
            command=col("command"),
            friction=col("friction_feedforward") + col("friction_feedback"),
            fallback=col("compensation_fallback"),
            wall_seconds=wall,
            missing_periods=missing_periods,
        )

    @property
    def rms(self) -> float:
        return float(np.sqrt(np.mean(self.error**2)))

    @property
    def max(self) -> float:
        return float(np.max(np.abs(self.error)))

    @property
    def samples(self) -> int:
        return int(self.t.size)

    def fallback_time(self) -> float | None:
        """Time after which the friction terms stayed exactly zero while they were active before
        (the controller's run-time limit-cycle fallback), else None; from the controller's own record
        of the fallback when the run has it."""
        if self.fallback is not None:
            on = np.nonzero(self.fallback > 0)[0]
            return float(self.t[on[0]]) if on.size else None
        active = self.friction != 0.0
        if not active.any() or active[-1]:
            return None
        last = int(np.nonzero(active)[0][-1])
        return float(self.t[last + 1]) if last + 1 < self.t.size else None


@dataclass
class DemoResult:
    preset: str = ""
    bag: str = ""
    bag_digest: str = ""
    fit_dir: str = ""
    params_file: str = ""
    model: str = ""
    recommendation: dict = field(default_factory=dict)
    fit_nmse: dict = field(default_factory=dict)
    gate: dict = field(default_factory=dict)
    gains: dict = field(default_factory=dict)
    reference: dict = field(default_factory=dict)
    runs: dict[str, TrackingRun] = field(default_factory=dict)
    encoder_cap: float = 100.0  # largest reduction [%] the encoder lets the measured error show
    warnings: list[str] = field(default_factory=list)
    files: list[str] = field(default_factory=list)
    timings: dict[str, float] = field(default_factory=dict)
    map_error: dict = field(default_factory=dict)
    #: "lockstep", or "real time" with ``can`` (protocol, the drive's state after each step)
    timing: str = "lockstep"
    can: dict = field(default_factory=dict)

    def reduction(self, label: str) -> float:
        base = self.runs["none"].rms
        return 100.0 * (1.0 - self.runs[label].rms / base) if base > 0 else 0.0

    @property
    def best(self) -> str:
        """The enabled mode with the lowest RMS error ("none" when no mode is enabled)."""
        enabled = [k for k, r in self.runs.items() if k != "none" and r.enabled and not r.invalid]
        return min(enabled, key=lambda k: self.runs[k].rms) if enabled else "none"

    def summary(self) -> dict:
        return {
            "preset": self.preset,
            "bag": self.bag,
            "bag_digest": self.bag_digest,
            "model": self.model,
            "recommendation": self.recommendation,
            "fit_nmse_percent": self.fit_nmse,
            "map_error_vs_truth": self.map_error,
            "params_file": self.params_file,
            "control_period": GRAPH_PERIOD,
            "timing": self.timing,
            **({"can": self.can} if self.can else {}),
            "gains": self.gains,
            "reference": self.reference,
            "gate": self.gate,
            "runs": {
                k: {
                    "rms_mrad": r.rms * 1e3,
                    "max_mrad": r.max * 1e3,
                    "wall_seconds": r.wall_seconds,
                    "enabled": r.enabled,
                    "reason": r.reason,
                    "samples": r.samples,
                    "fallback_s": r.fallback_time(),
                    "missing_periods": r.missing_periods,
                    "invalid": r.invalid,
                    **{f"{m}": v for m, v in r.metrics.items()},
                }
                for k, r in self.runs.items()
            },
            "best": self.best,
            "reduction_percent": {k: self.reduction(k) for k in self.runs},
            "encoder_cap_percent": self.encoder_cap,
            "warnings": self.warnings,
            "timings_s": self.timings,
        }


def run_metrics(run: TrackingRun, resolution: float) -> dict:
    """Stick-slip and hunting of one run from the measured signals (harness.tracking_metrics)."""
    from friction_ros.core.harness import tracking_metrics

    v_stick = max(2.0 * resolution / 0.01, 1e-4)  # under two counts per 10 ms counts as stuck
    m = tracking_metrics(
        run.t,
        run.reference,
        run.position,
        run.velocity,
        run.reference_velocity,
        v_stick=v_stick,
        resolution=2.0 * resolution,
    )
    return {
        "stick_fraction": m["stick_fraction"],
        "stick_events": m["stick_events"],
        "hunting_reversals": m["hunting_reversals"],
        "hunting_amplitude_mrad": m["hunting_amplitude"] * 1e3,
    }


#: an encoder cap below this [%] is named in the demo's warnings
ENCODER_CAP_WARN = 90.0


def encoder_cap(run: TrackingRun, resolution: float) -> float:
    """The largest RMS reduction [%] any controller can show on this run's measured error: even a
    joint that tracked perfectly reads ``ref - q round(ref / q)`` through an encoder of resolution
    ``q``, so ``100 (1 - RMS(that) / RMS(run))`` (100 without an encoder)."""
    if resolution <= 0 or not run.rms > 0:
        return 100.0
    ref = np.asarray(run.reference, dtype=float)
    floor = float(np.sqrt(np.mean((ref - resolution * np.round(ref / resolution)) ** 2)))
    return 100.0 * (1.0 - floor / run.rms)


def map_error_vs_truth(fitted, truth, plateaus, excited: tuple[float, float] | None = None) -> dict:
    """Steady-state map of the fit against the preset's truth (both directions).

    ``map_percent``: largest relative error over the whole speed range the log excited
    (``excited`` = (slowest, fastest) moving speed, :func:`excited_speeds`), Stribeck region included.

    ``sliding_percent``: largest |f_fit(v) - f_true(v)| / |f_true(v)| over the plateau speed range
    (lowest to highest plateau speed); ``static_peak_percent``: signed relative error of the static
    peak, the largest |f(v)| for speeds from 1e-6 up to the lowest plateau speed (fs for a Stribeck
    curve), as (fit - truth) / truth, the worse direction.
    """
    speeds = sorted(abs(p.velocity) for p in plateaus if abs(p.velocity) > 0)
    lo, hi = (speeds[0], speeds[-1]) if speeds else (1e-2, 1.0)
    out = {"v_min": lo, "v_max": hi, "sliding_percent": math.nan, "static_peak_percent": math.nan}
    slide, peak = [], []
    for sign in (1.0, -1.0):
        v = sign * np.geomspace(lo, max(hi, lo * 1.0001), 200)
        ft, ff = np.asarray(truth(v)), np.asarray(fitted(v))
        ok = np.abs(ft) > 0
        if ok.any():
            slide.append(float(np.max(np.abs(ff[ok] - ft[ok]) / np.abs(ft[ok]))))
        vs = sign * np.geomspace(1e-6, lo, 200)
        pt, pf = float(np.max(np.abs(truth(vs)))), float(np.max(np.abs(fitted(vs))))
        if pt > 0:
            peak.append((pf - pt) / pt)
    if slide:
        out["sliding_percent"] = 100.0 * max(slide)
    if peak:
        out["static_peak_percent"] = 100.0 * max(peak, key=abs)
    if excited is not None and excited[1] > excited[0] > 0:
        errs = []
        for sign in (1.0, -1.0):
            v = sign * np.geomspace(excited[0], excited[1], 400)
            ft, ff = np.asarray(truth(v)), np.asarray(fitted(v))
            ok = np.abs(ft) > 0
            if ok.any():
                errs.append(float(np.max(np.abs(ff[ok] - ft[ok]) / np.abs(ft[ok]))))
        out["excited_v_min"], out["excited_v_max"] = excited
        out["map_percent"] = 100.0 * max(errs) if errs else math.nan
    return out


def excited_speeds(records) -> tuple[float, float]:
    """(slowest, fastest) speed a log excited: the 1st and 99th percentiles of |v| over the moving
    samples (|v| above 1e-3 of the 99th percentile)."""
    v = np.abs(np.concatenate([np.asarray(r.velocity, dtype=float) for r in records]))
    v = v[np.isfinite(v)]
    if not v.size:
        return (math.nan, math.nan)
    moving = v[v > 1e-3 * np.percentile(v, 99)]
    lo, hi = np.percentile(moving, [1, 99]) if moving.size else (math.nan, math.nan)
    return float(lo), float(hi)
