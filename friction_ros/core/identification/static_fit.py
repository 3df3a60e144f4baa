"""Static friction maps fitted to constant-velocity plateaus (seed 004 B.3 experiment 2).

At a plateau the acceleration is zero, so the mean torque is the steady-sliding friction
``F(v)``. The exponential Stribeck family (seed 004 eq. 5; seed 003 A.2.2)

    F(v) = [F_C + (F_S - F_C) exp(-|v/v_S|^delta)] sgn(v) + F_v v

(Coulomb: F_S = F_C, F_v = 0; Coulomb+viscous: F_S = F_C) is fitted by robust nonlinear least
squares (scipy ``least_squares``, soft-L1 loss, so one bad plateau cannot drag the fit), started
from a variable-projection grid over (v_S, delta) with F_C, F_S - F_C, F_v by NNLS. Fitted per
direction (|F| against |v|) and jointly; the model is flagged asymmetric when the two directions'
Coulomb or static levels differ by more than 3 standard errors and 2 %.
Standard errors from the Jacobian: cov = s^2 (J^T J)^-1.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import least_squares, nnls

from friction_ros.core.identification.data import ExcitationError, Plateau

STATIC_MODELS = ("coulomb", "coulomb_viscous", "stribeck")


@dataclass
class StaticFit:
    model: str
    coefficients: dict
    stderr: dict
    per_direction: dict = field(default_factory=dict)
    asymmetric: bool = False
    rms: float = 0.0
    n_points: int = 0
    seconds: float = 0.0

    def steady_state(self, v) -> np.ndarray:
        return stribeck_map(np.asarray(v, dtype=float), self.coefficients)


def stribeck_map(v: np.ndarray, c: dict) -> np.ndarray:
    """F(v) of the (possibly degenerate) Stribeck family from a coefficient dict."""
    fc = c.get("fc", 0.0)
    fs = c.get("fs", fc)
    vs = c.get("vs", 1.0)
    delta = c.get("delta", 2.0)
    fv = c.get("fv", 0.0)
    av = np.abs(v)
    return (fc + (fs - fc) * np.exp(-((av / vs) ** delta))) * np.sign(v) + fv * v


def _fit_magnitude(
    av: np.ndarray, af: np.ndarray, model: str, fs_fixed: float | None = None
) -> tuple[dict, dict, float]:
    """Fit |F| against |v| > 0 for one direction or both (mirrored); ``fs_fixed``: the static level
    measured by breakaway ramps (the Stribeck peak is then not extrapolated from the plateaus)."""
    if model == "stribeck" and fs_fixed is not None:
        return _fit_stribeck_fixed_peak(av, af, float(fs_fixed))
    if model == "coulomb":
        fc = float(np.median(af))
        s = float(np.std(af - fc, ddof=1) / np.sqrt(len(af))) if len(af) > 1 else 0.0
        return {"fc": fc}, {"fc": s}, float(np.sqrt(np.mean((af - fc) ** 2)))
    if model == "coulomb_viscous":
        A = np.column_stack([np.ones_like(av), av])

        def res(p):
            return A @ p - af

        x0, _ = nnls(A, af)
        r = least_squares(res, x0, bounds=([0, 0], [np.inf, np.inf]), loss="soft_l1", f_scale=_scale(res(x0)))
        names = ["fc", "fv"]
    else:
        best = None
        for vs in np.geomspace(max(av.min() / 3, 1e-5), av.max(), 40):
            for delta in (0.5, 1.0, 1.5, 2.0, 3.0):
                A = np.column_stack([np.ones_like(av), np.exp(-((av / vs) ** delta)), av])
                x, rn = nnls(A, af)
                if best is None or rn < best[0]:
                    best = (rn, [x[0], x[0] + x[1], vs, delta, x[2]])
        x0 = np.array(best[1])

        def res(p):
            fc, fs, vs, delta, fv = p
            return fc + (fs - fc) * np.exp(-((av / vs) ** delta)) + fv * av - af

        lo = [0.0, 0.0, 1e-6, 0.2, 0.0]
        hi = [np.inf, np.inf, 10.0, 5.0, np.inf]
        x0 = np.clip(x0, np.array(lo) + 1e-12, hi)
        r = least_squares(res, x0, bounds=(lo, hi), loss="soft_l1", f_scale=_scale(res(x0)), x_scale="jac")
        names = ["fc", "fs", "vs", "delta", "fv"]
    p = r.x
    resid = r.fun
    dof = max(len(af) - len(p), 1)
    s2 = float(np.sum(resid**2) / dof)
    try:
        cov = s2 * np.linalg.pinv(r.jac.T @ r.jac)
        se = np.sqrt(np.maximum(np.diag(cov), 0.0))
    except np.linalg.LinAlgError:
        se = np.full(len(p), np.nan)
    coefs = dict(zip(names, map(float, p)))
    if "fs" in coefs and coefs["fs"] < coefs["fc"]:
        coefs["fs"] = coefs["fc"]
    return coefs, dict(zip(names, map(float, se))), float(np.sqrt(np.mean(resid**2)))


def _fit_stribeck_fixed_peak(av: np.ndarray, af: np.ndarray, fs: float) -> tuple[dict, dict, float]:
    """Stribeck curve with F_S fixed: ``|F| - F_S e = F_C (1 - e) + F_v |v|``, ``e = exp(-|v/v_S|^delta)``."""
    best = None
    for vs in np.geomspace(max(av.min() / 30, 1e-6), av.max(), 50):
        for delta in (0.5, 1.0, 1.5, 2.0, 3.0):
            e = np.exp(-((av / vs) ** delta))
            A = np.column_stack([1.0 - e, av])
            x, rn = nnls(A, af - fs * e)
            if best is None or rn < best[0]:
                best = (rn, [x[0], vs, delta, x[1]])

    def res(p):
        fc, vs, delta, fv = p
        return fc + (fs - fc) * np.exp(-((av / vs) ** delta)) + fv * av - af

    lo = [0.0, 1e-6, 0.2, 0.0]
    hi = [np.inf, 10.0, 5.0, np.inf]
    x0 = np.clip(np.array(best[1]), np.array(lo) + 1e-12, hi)
    r = least_squares(res, x0, bounds=(lo, hi), loss="soft_l1", f_scale=_scale(res(x0)), x_scale="jac")
    fc, vs, delta, fv = map(float, r.x)
    dof = max(len(af) - 4, 1)
    s2 = float(np.sum(r.fun**2) / dof)
    try:
        se = np.sqrt(np.maximum(np.diag(s2 * np.linalg.pinv(r.jac.T @ r.jac)), 0.0))
    except np.linalg.LinAlgError:
        se = np.full(4, np.nan)
    coefs = {"fc": min(fc, fs), "fs": fs, "vs": vs, "delta": delta, "fv": fv}
    stderr = {"fc": float(se[0]), "fs": 0.0, "vs": float(se[1]), "delta": float(se[2]), "fv": float(se[3])}
    return coefs, stderr, float(np.sqrt(np.mean(r.fun**2)))


def _scale(r: np.ndarray) -> float:
    mad = float(np.median(np.abs(r - np.median(r)))) * 1.4826
    return max(mad, 1e-3 * max(float(np.max(np.abs(r))), 1e-9), 1e-9)


def fit_plateaus(
    plateaus: list[Plateau], model: str = "stribeck", breakaway: dict[int, float] | None = None
) -> StaticFit:
    """Fit a static model to plateau means, per direction and jointly (see module docstring).

    ``breakaway``: measured breakaway torque magnitudes per direction (``{+1: ..., -1: ...}``, seed
    004 B.3 experiment 1). With them the Stribeck peak ``F_S`` is the breakaway level and only
    ``F_C, v_S, delta, F_v`` come from the plateaus: plateaus that do not reach below the Stribeck
    velocity (the joint sticks and slips there under a velocity loop) say nothing about the peak,
    and a free ``F_S`` is then an extrapolation.
    """
    t0 = time.perf_counter()
    v = np.array([p.velocity for p in plateaus])
    f = np.array([p.torque for p in plateaus])
    need = {"coulomb": 1, "coulomb_viscous": 2, "stribeck": 4}[model]
    if len(v) < need + 1 or np.sum(v > 0) + np.sum(v < 0) < need + 1:
        raise ExcitationError(
            f"{model}: {len(v)} constant-velocity plateaus, need at least {need + 1}: run the 'plateaus' "
            "experiment (log-spaced speeds in both directions)"
        )
    av, af = np.abs(v), f * np.sign(v)
    brk = {d: float(x) for d, x in (breakaway or {}).items() if x and np.isfinite(x)}
    fs_all = float(np.mean(list(brk.values()))) if brk else None
    coefs, se, rms = _fit_magnitude(av, af, model, fs_all)
    per = {}
    asym = False
    pos, neg = v > 0, v < 0
    if pos.sum() > need and neg.sum() > need:
        cp, sp, _ = _fit_magnitude(av[pos], af[pos], model, brk.get(1, fs_all))
        cn, sn, _ = _fit_magnitude(av[neg], af[neg], model, brk.get(-1, fs_all))
        per = {"positive": cp, "negative": cn, "positive_stderr": sp, "negative_stderr": sn}
        for k in ("fc", "fs"):
            if k in cp:
                diff = abs(cp[k] - cn[k])
                tol = max(3 * np.hypot(sp.get(k, 0.0), sn.get(k, 0.0)), 0.02 * 0.5 * (cp[k] + cn[k]))
                asym |= bool(diff > tol)
    return StaticFit(model, coefs, se, per, asym, rms, len(v), time.perf_counter() - t0)
