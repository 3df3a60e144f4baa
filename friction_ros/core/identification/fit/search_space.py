"""The fit's search space follows the log: where a coefficient is searched, given these data.

* :func:`velocity_grid`: the speeds the steady-state maps are drawn and compared on;
* :func:`slowest_stribeck_velocity`: a Stribeck velocity no lower than the slowest moving samples;
* :func:`static_linear_zone`: with load terms, the linear zone of sgn(v) of a static map is at least
  the load terms' (the samples slower than it are not fitted).
"""

from __future__ import annotations

import numpy as np

from friction_ros.core.identification.data.data_scale import velocity_scale
from friction_ros.core.identification.data.records import JointData
from friction_ros.core.identification.data.velocity_regimes import motion_floor


def velocity_grid(records: list[JointData]) -> np.ndarray:
    v = np.concatenate([np.abs(r.velocity) for r in records])
    vmax = float(np.max(v))
    vsc = velocity_scale(records[0])
    moving = v[v > 1e-6 * vsc]
    vmin = max(float(np.percentile(moving, 1)) if moving.size else 1e-4 * vsc, 1e-4 * vsc, vmax * 1e-4)
    g = np.geomspace(vmin, max(vmax, vmin * 10), 60)
    return np.concatenate([-g[::-1], g])


def slowest_stribeck_velocity(spec, train) -> None:
    """A Stribeck velocity ``vs`` is searched no lower than the slowest 1 % of the moving training
    samples: a Stribeck peak narrower than almost every sample's speed is fitted to a handful of
    samples and its level ``fs`` runs away (1e24 N on a ball-screw log)."""
    if "vs" not in spec.nonlinear:
        return
    v = np.abs(np.concatenate([r.velocity for r in train]))
    moving = v[v > motion_floor(v, train[0].resolution)]
    if moving.size < 10:
        return
    i = spec.nonlinear.index("vs")
    spec.lower[i] = max(spec.lower[i], float(np.percentile(moving, 1)))
    spec.upper[i] = max(spec.upper[i], spec.lower[i] * 10.0)


def static_linear_zone(spec, load_eps: float) -> None:
    """With load terms a static map is fitted without the samples slower than the terms' sign zone
    (``FitSpec.grams``), so those samples cannot determine a narrower linear zone of sgn(v): the
    zone is at least ``load_eps`` (a fitted ``eps`` is bounded below by it). Without this the zone
    lands anywhere below it and the map mispredicts every reversal it is scored on."""
    spec.eps = max(spec.eps, load_eps)
    if "eps" in spec.nonlinear:
        i = spec.nonlinear.index("eps")
        spec.lower[i] = max(spec.lower[i], load_eps)
        spec.upper[i] = max(spec.upper[i], spec.lower[i] * 1.001)
