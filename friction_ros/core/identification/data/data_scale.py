"""The scales of a log: every speed and effort threshold of the fitter is relative to them.

A joint's log can be in rad and N*m at link speeds of 0.05 rad/s, at motor speeds of 300 rad/s, or
in m and N on a ball-screw axis; the fitter's bounds, initial guesses and thresholds must follow the
data, not one joint's numbers. Each scale is the decade of a robust amplitude of the log::

    velocity_scale = 10^round(log10(sqrt(P5 * P95)))     [position unit / s]

(P5, P95: percentiles of the moving speeds |v| > 1e-3 P95 |v|: the log-centre of the speed range,
where a Stribeck velocity or a presliding distance is searched from)
    torque_scale   = 10^round(log10(P95 |tau - median tau|))   [effort unit]

Rounding to a decade keeps the figures of logs already near unit scale bit-identical (scale 1)
while a log re-expressed in other units (mm instead of m, kN instead of N) moves every bound by
exactly the same power of ten, so its fit is the same fit, scaled. A velocity bound written as
``b`` for a unit-scale joint is ``b * velocity_scale`` here; a position bound (presliding distance)
is ``b * velocity_scale`` too (position unit = velocity unit x 1 s).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np

#: the record meta keys that carry the scales (set by fit_records on every record it fits)
VELOCITY_KEY = "velocity_scale"
TORQUE_KEY = "torque_scale"


@dataclass(frozen=True)
class DataScale:
    velocity: float = 1.0  # [position unit / s]
    torque: float = 1.0  # [effort unit]

    def describe(self) -> str:
        return f"speed scale {self.velocity:g}, effort scale {self.torque:g}"


def decade(x: float) -> float:
    """10^round(log10 x); 1 for a value that is not finite and positive."""
    if not (math.isfinite(x) and x > 0):
        return 1.0
    return float(10.0 ** round(math.log10(x)))


def data_scale(records) -> DataScale:
    """The :class:`DataScale` of a list of records (JointData)."""
    v = np.concatenate([np.abs(np.asarray(r.velocity, dtype=float)) for r in records])
    tau = np.concatenate([np.asarray(r.torque, dtype=float) for r in records])
    v = v[np.isfinite(v)]
    tau = tau[np.isfinite(tau)]
    vs = 1.0
    if v.size:
        moving = v[v > 1e-3 * np.percentile(v, 95)]
        if moving.size:
            p5, p95 = np.percentile(moving, [5, 95])
            vs = math.sqrt(p5 * p95)
    ts = float(np.percentile(np.abs(tau - np.median(tau)), 95)) if tau.size else 1.0
    return DataScale(decade(vs), decade(ts))


def velocity_scale(data) -> float:
    """The velocity scale a record carries (1 when it was not set: a unit-scale joint)."""
    return float(getattr(data, "meta", {}).get(VELOCITY_KEY, 1.0))


def torque_scale(data) -> float:
    """The effort scale a record carries (1 when it was not set)."""
    return float(getattr(data, "meta", {}).get(TORQUE_KEY, 1.0))


def with_scale(records, scale: DataScale):
    """The records with the scales in their meta (new JointData objects; arrays shared)."""
    return [
        dataclasses.replace(r, meta={**r.meta, VELOCITY_KEY: scale.velocity, TORQUE_KEY: scale.torque})
        for r in records
    ]


#: the effort limit friction-fit writes without a plant preset: this many times the log's peak |effort|
EFFORT_LIMIT_MARGIN = 1.5


def effort_limit_of_log(records) -> float:
    """The torque (force) limit a parameter file gets from a log: ``EFFORT_LIMIT_MARGIN`` x the
    largest |effort| recorded, rounded up to two significant digits (nan for a log without effort).
    The joint did all of its identification run inside it; set the joint's rated limit when known."""
    peak = 0.0
    for r in records:
        tau = np.asarray(r.torque, dtype=float)
        tau = tau[np.isfinite(tau)]
        if tau.size:
            peak = max(peak, float(np.max(np.abs(tau))))
    if not peak > 0.0:
        return math.nan
    x = EFFORT_LIMIT_MARGIN * peak
    step = 10.0 ** (math.floor(math.log10(x)) - 1)
    return float(round(math.ceil(x / step - 1e-9) * step, 12))
