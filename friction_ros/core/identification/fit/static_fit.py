"""Static friction maps fitted to constant-velocity plateaus (AI friction chapter B.3 experiment 2).

At a plateau the acceleration is zero, so the mean torque is the steady-sliding friction
``F(v)``. The exponential Stribeck family (AI friction chapter eq. 5; ABB M19-S paper A.2.2)

    F(v) = [F_C + (F_S - F_C) exp(-|v/v_S|^delta)] sgn(v) + F_v v

(Coulomb: F_S = F_C, F_v = 0; Coulomb+viscous: F_S = F_C) is fitted by robust nonlinear least
squares (scipy ``least_squares``, soft-L1 loss, so one bad plateau cannot drag the fit), started
from a variable-projection grid over (v_S, delta) with F_C, F_S - F_C, F_v by NNLS. Fitted per
jointly (|F| against |v|); per direction the levels (F_C, F_v, and F_S unless a breakaway ramp
measured it) are re-solved by linear least squares on the joint fit's shape (v_S, delta), which
stays well posed with two plateaus per direction. The model is flagged asymmetric when mirrored
(+v, -v) plateau pairs differ by more than 2 % of the friction level and 3 standard errors of the
pair differences (without pairs: when the per-direction F_C or F_S differ by as much), and only
when each direction's levels are determined (standard error below the value).
Standard errors from the Jacobian: cov = s^2 (J^T J)^-1.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import least_squares, nnls

from friction_ros.core.identification.data.data_scale import decade
from friction_ros.core.identification.data.plateau_detection import Plateau, mirrored_pairs
from friction_ros.core.identification.data.records import ExcitationError


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
        for vs in np.geomspace(max(av.min() / 3, 1e-5 * decade(av.max())), av.max(), 40):
            for delta in (0.5, 1.0, 1.5, 2.0, 3.0):
                A = np.column_stack([np.ones_like(av), np.exp(-((av / vs) ** delta)), av])
                x, rn = nnls(A, af)
                if best is None or rn < best[0]:
                    best = (rn, [x[0], x[0] + x[1], vs, delta, x[2]])
        x0 = np.array(best[1])

        def res(p):
            fc, fs, vs, delta, fv = p
            return fc + (fs - fc) * np.exp(-((av / vs) ** delta)) + fv * av - af

        vd = decade(av.max())  # vs bounds relative to the plateau speeds (data_scale)
        lo = [0.0, 0.0, 1e-6 * vd, 0.2, 0.0]
        hi = [np.inf, np.inf, 10.0 * vd, 5.0, np.inf]
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
    for vs in np.geomspace(max(av.min() / 30, 1e-6 * decade(av.max())), av.max(), 50):
        for delta in (0.5, 1.0, 1.5, 2.0, 3.0):
            e = np.exp(-((av / vs) ** delta))
            A = np.column_stack([1.0 - e, av])
            x, rn = nnls(A, af - fs * e)
            if best is None or rn < best[0]:
                best = (rn, [x[0], vs, delta, x[1]])

    def res(p):
        fc, vs, delta, fv = p
        return fc + (fs - fc) * np.exp(-((av / vs) ** delta)) + fv * av - af

    vd = decade(av.max())
    lo = [0.0, 1e-6 * vd, 0.2, 0.0]
    hi = [np.inf, 10.0 * vd, 5.0, np.inf]
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
    if pos.sum() >= 2 and neg.sum() >= 2:
        cp, sp = _fit_direction(av[pos], af[pos], model, coefs, brk.get(1))
        cn, sn = _fit_direction(av[neg], af[neg], model, coefs, brk.get(-1))
        per = {"positive": cp, "negative": cn, "positive_stderr": sp, "negative_stderr": sn}
        asym = directions_differ(plateaus)
        if asym is None:  # no mirrored speeds: compare the per-direction levels
            asym = False
            for k in ("fc", "fs"):
                if k in cp:
                    diff = abs(cp[k] - cn[k])
                    tol = max(3 * np.hypot(sp.get(k, 0.0), sn.get(k, 0.0)), 0.02 * 0.5 * (cp[k] + cn[k]))
                    asym |= bool(diff > tol)
        # each direction's own levels must be determined by its plateaus, or the difference is noise
        asym = asym and _determined(cp, sp, av.max(), coefs) and _determined(cn, sn, av.max(), coefs)
    return StaticFit(model, coefs, se, per, asym, rms, len(v), time.perf_counter() - t0)


def _determined(c: dict, se: dict, vmax: float, joint: dict) -> bool:
    """No level of one direction's fit has a standard error above its value; a level near zero
    passes when its uncertainty is within 2 % of the joint friction at the top speed (fv counts as
    its torque at that speed)."""
    level = abs(joint.get("fc", 0.0)) + abs(joint.get("fv", 0.0)) * vmax
    for k in ("fc", "fs", "fv"):
        if k not in c:
            continue
        w = vmax if k == "fv" else 1.0
        s = float(se.get(k, 0.0)) * w
        if not np.isfinite(s) or s > max(abs(c[k]) * w, 0.02 * level):
            return False
    return True


def directions_differ(plateaus: list[Plateau], rel: float = 0.02) -> bool | None:
    """True when mirrored (+v, -v) plateau pairs show direction-dependent friction: the mean of
    ``(|tau(+v)| - |tau(-v)|) / mean level`` exceeds ``rel`` and 3 standard errors (across pairs,
    or of the plateau means with one pair); None without a mirrored pair."""
    pairs = mirrored_pairs(plateaus)
    if not pairs:
        return None
    level = np.array([0.5 * (abs(a.torque) + abs(b.torque)) for a, b in pairs])
    d = np.array([abs(a.torque) - abs(b.torque) for a, b in pairs]) / np.maximum(level, 1e-300)
    if len(d) >= 2:
        se = float(np.std(d, ddof=1) / np.sqrt(len(d)))
    else:
        a, b = pairs[0]
        se = float(
            np.hypot(a.torque_std / np.sqrt(max(a.n, 1)), b.torque_std / np.sqrt(max(b.n, 1))) / level[0]
        )
    m = abs(float(np.mean(d)))
    return bool(m > rel and m > 3.0 * se)


def _fit_direction(
    av: np.ndarray, af: np.ndarray, model: str, joint: dict, fs: float | None
) -> tuple[dict, dict]:
    """One direction's levels on the joint fit's shape: ``|F| = F_C (1 - e) + F_S e + F_v |v|``
    with ``e = exp(-(|v|/v_S)^delta)`` from ``joint`` (Coulomb: the median), by NNLS; ``fs``: the
    direction's breakaway level if measured."""
    if model == "coulomb":
        c, s, _ = _fit_magnitude(av, af, "coulomb")
        return c, s
    if model == "coulomb_viscous":
        cols, names, target = [np.ones_like(av), av], ["fc", "fv"], af
    else:
        e = np.exp(-((av / joint["vs"]) ** joint["delta"]))
        if fs is not None:
            cols, names, target = [1.0 - e, av], ["fc", "fv"], af - fs * e
        else:
            cols, names, target = [1.0 - e, e, av], ["fc", "fs", "fv"], af
    A = np.column_stack(cols)
    x, _ = nnls(A, target)
    r = A @ x - target
    dof = max(len(af) - len(x), 1)
    try:
        se = np.sqrt(np.maximum(np.diag(float(r @ r) / dof * np.linalg.pinv(A.T @ A)), 0.0))
    except np.linalg.LinAlgError:
        se = np.full(len(x), np.nan)
    c, s = dict(zip(names, map(float, x))), dict(zip(names, map(float, se)))
    if model == "stribeck":
        c = {
            "fc": c["fc"],
            "fs": fs if fs is not None else c["fs"],
            "vs": joint["vs"],
            "delta": joint["delta"],
            "fv": c["fv"],
        }
        c["fs"] = max(c["fs"], c["fc"])
        s.setdefault("fs", 0.0)
    return c, s
