"""Wear alarms: a one-sided CUSUM on a joint's temperature-normalised coefficient against its own
baseline (Page, "Continuous inspection schemes", Biometrika 41, 1954; Montgomery, "Introduction to
Statistical Quality Control", ch. 9).

Per joint and coefficient, the baseline (the runs of its first days) gives a robust level and
run-to-run scatter of the normalised coefficient c_n:

    mu_0 = median(c_n),   sigma_0 = max(1.4826 MAD(c_n), median(se_n))

(``se_n`` the run's propagated standard error, :mod:`.temperature_law`). Every run i is standardised,
with its own uncertainty added when it exceeds the baseline's typical one,

    z_i = (c_n,i - mu_0) / s_i,   s_i = sqrt(sigma_0^2 + max(0, se_n,i^2 - median(se_n)^2)),

clipped to [-:data:`Z_CLIP`, :data:`Z_CLIP`] (one bad fit cannot raise an alarm alone), and summed
by the upper CUSUM S_i = max(0, S_{i-1} + z_i - k). Wear raises friction, so only increases alarm.
The alarm is the first run with S_i > h: its date, the statistic S_i, the size
100 (mean c_n of that day / mu_0 - 1) [%], and the estimated change start (the last run with S = 0).

False-alarm design (:func:`design`): k = delta / 2 is optimal for a shift of delta = 2 sigma_0
(k = 1). h follows from Siegmund's approximation of the in-control average run length (runs between
false alarms) of a CUSUM with reference k on N(0, 1) data,

    ARL_0(k, h) = (exp(2 k b) - 2 k b - 1) / (2 k^2),   b = h + 1.166,

evaluated not at the nominal k but at the worst case one standard error of the baseline estimates
away: the median's standard error 1.2533 / sqrt(n) biases z by that much, and the MAD's relative
standard error 1.1664 / sqrt(n) (asymptotic efficiency 0.37 of the MAD) scales it, so h solves
ARL_0(k', h') = arl0 with k' = (k - 1.2533 / sqrt(n)) (1 - 1.1664 / sqrt(n)) and
h' = h (1 - 1.1664 / sqrt(n)). A shorter baseline gives a larger h.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import brentq

from friction_ros.core.fleet.temperature_law import robust_sigma

Z_CLIP = 4.0  # |z| limit per run [baseline sigmas]
DEFAULT_K = 1.0  # reference value [baseline sigmas]: half the 2-sigma shift detected fastest
DEFAULT_ARL0 = 1e7  # in-control runs between false alarms on one healthy coefficient
MEDIAN_SE = 1.2533  # sqrt(pi / 2): standard error of a normal sample's median x sqrt(n) / sigma
MAD_RSE = 1.1664  # relative standard error of the MAD x sqrt(n) (normal data)


def siegmund_arl(k: float, h: float, shift: float = 0.0) -> float:
    """Siegmund's approximation of the average run length of an upper CUSUM with reference ``k``
    and decision interval ``h`` on N(shift, 1) data (module docstring; Delta = shift - k)."""
    d = shift - k
    b = h + 1.166
    if abs(d) < 1e-9:
        return b * b
    return (math.exp(-2 * d * b) + 2 * d * b - 1) / (2 * d * d)


@dataclass(frozen=True)
class CusumDesign:
    """``k``, ``h`` [baseline sigmas] and what they were derived from."""

    k: float
    h: float
    arl0: float
    baseline_runs: int

    def to_dict(self) -> dict:
        return {"k": self.k, "h": self.h, "arl0_runs": self.arl0, "baseline_runs": self.baseline_runs}


def design(baseline_runs: int, arl0: float = DEFAULT_ARL0, k: float = DEFAULT_K) -> CusumDesign:
    """The decision interval h for ``arl0`` in-control runs at the worst case one standard error of
    a ``baseline_runs``-run baseline (module docstring)."""
    n = max(int(baseline_runs), 4)
    shrink = 1.0 - MAD_RSE / math.sqrt(n)
    k_eff = max((k - MEDIAN_SE / math.sqrt(n)) * max(shrink, 0.05), 0.05)
    h_eff = brentq(lambda h: siegmund_arl(k_eff, h) - arl0, 0.0, 300.0 / k_eff)
    return CusumDesign(k=k, h=float(h_eff / max(shrink, 0.05)), arl0=float(arl0), baseline_runs=n)


@dataclass
class Detection:
    """CUSUM of one coefficient: baseline level and scatter, per-run z and S, and the alarm."""

    mu0: float
    sigma0: float
    z: np.ndarray
    statistic: np.ndarray
    alarm: int | None = None  # run index of the first S > h
    start: int | None = None  # run index where the change is estimated to start
    size_percent: float = math.nan  # change on the alarm day vs baseline [%]
    design: CusumDesign | None = None
    notes: list[str] = field(default_factory=list)


def baseline_level(values, stderr) -> tuple[float, float, float]:
    """(mu_0, sigma_0, median se) of a baseline's normalised values (module docstring)."""
    v = np.asarray(values, float)
    se = np.asarray(stderr, float)
    ok = np.isfinite(v)
    se_med = float(np.median(se[ok & np.isfinite(se)])) if np.any(ok & np.isfinite(se)) else 0.0
    sigma = max(robust_sigma(v[ok]), se_med)
    return float(np.median(v[ok])), sigma, se_med


def detect(day, values, stderr, baseline, arl0: float = DEFAULT_ARL0, k: float = DEFAULT_K) -> Detection:
    """Upper CUSUM of ``values`` (normalised coefficient, time order) against the runs flagged in
    ``baseline`` (bool array); ``day`` (integer day of each run) dates the alarm and its size.
    Runs with a non-finite value get z = 0 (they neither raise nor reset the statistic)."""
    day = np.asarray(day)
    v = np.asarray(values, float)
    se = np.asarray(stderr, float)
    base = np.asarray(baseline, bool) & np.isfinite(v)
    n_base = int(base.sum())
    des = design(n_base, arl0, k)
    if n_base < 4:
        return Detection(
            math.nan,
            math.nan,
            np.zeros(v.size),
            np.zeros(v.size),
            design=des,
            notes=[f"baseline has {n_base} usable runs (at least 4 needed): no alarm possible"],
        )
    mu0, sigma0, se_med = baseline_level(v[base], se[base])
    if not sigma0 > 0:
        sigma0 = max(abs(mu0) * 1e-6, 1e-300)
    s = np.sqrt(sigma0**2 + np.maximum(0.0, np.nan_to_num(se, nan=0.0) ** 2 - se_med**2))
    z = np.clip(np.where(np.isfinite(v), (v - mu0) / s, 0.0), -Z_CLIP, Z_CLIP)
    stat = np.zeros(v.size)
    acc = 0.0
    alarm = start = None
    last_zero = -1
    for i in range(v.size):
        acc = 0.0 if base[i] else max(0.0, acc + z[i] - des.k)
        stat[i] = acc
        if acc == 0.0:
            last_zero = i
        if alarm is None and acc > des.h:
            alarm, start = i, last_zero + 1
    det = Detection(mu0, sigma0, z, stat, alarm, start, design=des)
    if alarm is not None and mu0 != 0:
        same_day = (day == day[alarm]) & np.isfinite(v)
        det.size_percent = float(100.0 * (np.mean(v[same_day]) / mu0 - 1.0))
    return det
