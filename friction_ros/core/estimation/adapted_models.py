"""The models the online estimator adapts by recursive least squares: one table entry per model.

Each :class:`AdaptedModel` is linear in its coefficients, ``F = phi(v) . c`` (regressors in the
filtered velocity; ``vs``, ``delta`` of the Stribeck shape held fixed, E = exp(-|v/vs|^delta)):

==============================  ==================================================================
``viscous``                     F = fv v  (AI friction chapter eq. (2))
``coulomb_viscous``             F = fc sgn(v) + fv v  (AI friction chapter eq. (3))
``asymmetric_coulomb_viscous``  F = positive.fc + positive.fv v (v > 0),
                                F = -negative.fc + negative.fv v (v < 0)  (AI friction chapter B.3)
``stribeck``                    F = [fc (1 - E) + fs E] sgn(v) + fv v  (AI friction chapter eq. (5))
``asymmetric_stribeck``         the same with a set per direction
==============================  ==================================================================

``config(c, vs, delta)`` gives the friction library config of coefficients ``c`` (already
projected to >= 0). Adding an entry here is all a new online-adapted model needs.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass


@dataclass(frozen=True)
class AdaptedModel:
    """An online-adapted (RLS) model: coefficient names, regressor and library config."""

    names: tuple[str, ...]
    regressor: Callable[[float, float, float], tuple[float, ...]]  # (v, vs, delta) -> phi
    config: Callable[[dict, float, float], dict]  # (coefficients, vs, delta) -> library config


def _sgn(v: float) -> float:
    return 1.0 if v > 0 else (-1.0 if v < 0 else 0.0)


def _e(v: float, vs: float, delta: float) -> float:
    return math.exp(-(abs(v / vs) ** delta))


def _strib(fc: float, fs: float, fv: float, vs: float, delta: float) -> dict:
    return {"fc": fc, "fs": max(fs, fc), "vs": vs, "delta": delta, "fv": fv}


def _stribeck_phi(v, vs, delta):
    s, e = _sgn(v), _e(v, vs, delta)
    return (s * (1.0 - e), s * e, v)


def _asym_stribeck_phi(v, vs, delta):
    e = _e(v, vs, delta)
    p, n = float(v > 0), float(v < 0)
    return (p * (1 - e), p * e, p * v, -n * (1 - e), -n * e, n * v)


def _asym_stribeck_config(c, vs, delta):
    sets = {d: _strib(c[f"{d}.fc"], c[f"{d}.fs"], c[f"{d}.fv"], vs, delta) for d in ("positive", "negative")}
    return {"model": "asymmetric", "base": "stribeck", **sets}


#: estimator model name -> its AdaptedModel (the ``lugre`` observer is not an RLS model)
ADAPTED: dict[str, AdaptedModel] = {
    "viscous": AdaptedModel(
        ("fv",), lambda v, vs, d: (v,), lambda c, vs, d: {"model": "viscous", "fv": c["fv"]}
    ),
    "coulomb_viscous": AdaptedModel(
        ("fc", "fv"),
        lambda v, vs, d: (_sgn(v), v),
        lambda c, vs, d: {"model": "coulomb_viscous", "fc": c["fc"], "fv": c["fv"]},
    ),
    "asymmetric_coulomb_viscous": AdaptedModel(
        ("positive.fc", "negative.fc", "positive.fv", "negative.fv"),
        lambda v, vs, d: (float(v > 0), -float(v < 0), float(v > 0) * v, float(v < 0) * v),
        lambda c, vs, d: {
            "model": "asymmetric",
            "base": "coulomb_viscous",
            "positive": {"fc": c["positive.fc"], "fv": c["positive.fv"]},
            "negative": {"fc": c["negative.fc"], "fv": c["negative.fv"]},
        },
    ),
    "stribeck": AdaptedModel(
        ("fc", "fs", "fv"),
        _stribeck_phi,
        lambda c, vs, d: {"model": "stribeck", **_strib(c["fc"], c["fs"], c["fv"], vs, d)},
    ),
    "asymmetric_stribeck": AdaptedModel(
        ("positive.fc", "positive.fs", "positive.fv", "negative.fc", "negative.fs", "negative.fv"),
        _asym_stribeck_phi,
        _asym_stribeck_config,
    ),
}
