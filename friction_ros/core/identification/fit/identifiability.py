"""Honest identifiability: flag coefficients the data cannot separate, and confidence intervals.

From the Jacobian ``Jr`` of the residuals with respect to the coefficients (finite differences in
the search coordinates, analytic for the linear ones), scaled to unit column norm:

* singular values below ``tol`` x the largest reveal (near-)collinear directions; every coefficient
  with a large component in such a direction is flagged **not separately identifiable** and the
  combination that *is* identifiable is reported (GA friction thesis 2002 sec. 3.8: sigma and B_m enter as
  (sigma + B_m) v, exactly collinear; only their sum is identifiable);
* pairwise correlations |rho| > 0.99 of the covariance ``s^2 (Jr^T Jr)^+`` are listed;
* 95 % confidence intervals ``+- 1.96 sqrt(diag cov)``. They assume white residuals and are
  therefore optimistic for coloured (model-error) residuals.
"""

from __future__ import annotations

import numpy as np


def analyse(
    jac: np.ndarray,
    residuals: np.ndarray,
    names: list[str],
    values: np.ndarray,
    tol: float = 1e-6,
    corr_limit: float = 0.99,
) -> dict:
    """Identifiability report from a residual Jacobian (n x p) at the optimum."""
    jac = np.asarray(jac, dtype=float)
    p = jac.shape[1]
    n = jac.shape[0]
    norms = np.linalg.norm(jac, axis=0)
    norms = np.where(norms > 0, norms, 1.0)
    Js = jac / norms
    U, s, Vt = np.linalg.svd(Js, full_matrices=False)
    smax = s[0] if s.size else 1.0
    dof = max(n - p, 1)
    s2 = float(np.sum(np.asarray(residuals) ** 2) / dof)
    inv = np.linalg.pinv(Js.T @ Js, rcond=tol**2)
    cov = s2 * inv / np.outer(norms, norms)
    se = np.sqrt(np.maximum(np.diag(cov), 0.0))
    flagged: list[dict] = []
    unident = set()
    for k in range(s.size):
        if s[k] < tol * smax or s[k] == 0:
            vec = Vt[k]
            idx = [i for i in range(p) if abs(vec[i]) > 0.1]
            for i in idx:
                unident.add(names[i])
            flagged.append(
                {
                    "parameters": [names[i] for i in idx],
                    "null_direction": {names[i]: float(vec[i] / norms[i]) for i in idx},
                    "singular_value_ratio": float(s[k] / smax),
                }
            )
    d = np.sqrt(np.maximum(np.diag(cov), 1e-300))
    corr = cov / np.outer(d, d)
    pairs = []
    for i in range(p):
        for j in range(i + 1, p):
            if abs(corr[i, j]) > corr_limit:
                pairs.append({"a": names[i], "b": names[j], "rho": float(corr[i, j])})
    ci = {}
    for i, nme in enumerate(names):
        if nme in unident:
            ci[nme] = None
        else:
            ci[nme] = [float(values[i] - 1.96 * se[i]), float(values[i] + 1.96 * se[i])]
    useless = useless_intervals(ci, dict(zip(names, (float(v) for v in values))))
    return {
        "useless_ci": useless,
        "condition_number": float(smax / s[-1]) if s.size and s[-1] > 0 else float("inf"),
        "not_identifiable": sorted(unident),
        "collinear_groups": flagged,
        "high_correlations": pairs,
        "ci95": ci,
        "stderr": {nme: (None if nme in unident else float(se[i])) for i, nme in enumerate(names)},
    }


def useless_intervals(ci: dict, values: dict) -> list[str]:
    """Coefficients whose 95 % interval says nothing: missing, not finite, or wider than the value
    itself (half-width > |value|, i.e. the data cannot even tell the sign or the order of magnitude)."""
    out = []
    for name, iv in ci.items():
        v = values.get(name, float("nan"))
        if iv is None or not all(np.isfinite(iv)) or not np.isfinite(v):
            out.append(name)
        elif 0.5 * (iv[1] - iv[0]) > abs(v):
            out.append(name)
    return sorted(out)


def time_domain_jacobian(fit, records, rel_step: float = 1e-4):
    """Residual Jacobian of a DynamicFit w.r.t. its physical-ish coefficients.

    Columns: the nonlinear coefficients (finite differences in search space, reported per unit of
    the coefficient) and the linear ones (their regressors). Returns (jac, residuals, names, values).
    """
    from friction_ros.core.identification.fit.dynamic_fit import fit_signals

    spec = fit.spec
    x = spec.to_search(fit.theta)
    vel = [fit_signals(r, fit.signals)[0] for r in records]
    cols_res = []
    base = []
    regs = []
    for r, v in zip(records, vel):
        X = spec.design(fit.theta, v, r.acceleration, r.dt, spec.load_matrix(r, v))
        base.append(X @ fit.beta - r.torque)
        regs.append(X)
    res = np.concatenate(base)
    X = np.vstack(regs)
    for i in range(x.size):
        h = 1e-4 * max(1.0, abs(x[i]))
        xp = x.copy()
        xp[i] += h
        th = spec.from_search(xp)
        pred = np.concatenate(
            [
                spec.design(th, v, r.acceleration, r.dt, spec.load_matrix(r, v)) @ fit.beta
                for r, v in zip(records, vel)
            ]
        )
        dth = th[i] - fit.theta[i]
        cols_res.append((pred - (res + np.concatenate([r.torque for r in records]))) / dth)
    jac = np.column_stack(cols_res + [X[:, j] for j in range(X.shape[1])]) if cols_res else X
    names = list(spec.nonlinear) + spec.linear_all
    values = np.concatenate([fit.theta, fit.beta])
    return jac, res, names, values
