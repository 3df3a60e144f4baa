"""Non-negative linear least squares from Gram matrices (the linear half of variable projection).

Given ``G = [X y]^T [X y]`` the residual sum of squares of ``y - X beta`` is
``y'y - 2 beta' X'y + beta' X'X beta``. Every linear coefficient here (static level, element
weights, micro-damping, viscous coefficient, inertia) is physically non-negative, so the solution
is the NNLS one: the unconstrained solution when it is non-negative, otherwise scipy's NNLS on the
Cholesky factor (same objective up to a constant).
"""

from __future__ import annotations

import numpy as np
from scipy.optimize import nnls


def solve_gram(G: np.ndarray, ridge: float = 1e-12) -> tuple[np.ndarray, float]:
    """Return (beta >= 0, residual sum of squares) for one Gram matrix of [X y]."""
    XtX = G[:-1, :-1]
    Xty = G[:-1, -1]
    yty = G[-1, -1]
    d = np.sqrt(np.maximum(np.diag(XtX), 1e-300))
    A = XtX / np.outer(d, d) + ridge * np.eye(len(d))
    b = Xty / d
    try:
        z = np.linalg.solve(A, b)
    except np.linalg.LinAlgError:
        z = np.full(len(d), -1.0)
    if not np.all(np.isfinite(z)) or np.any(z < 0):
        try:
            L = np.linalg.cholesky(A)
            z, _ = nnls(L.T, np.linalg.solve(L, b), maxiter=50 * len(d))
        except (np.linalg.LinAlgError, RuntimeError):
            z = np.zeros(len(d))
    beta = z / d
    sse = float(yty - 2.0 * beta @ Xty + beta @ XtX @ beta)
    return beta, max(sse, 0.0)


def solve_grams(grams: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Vectorised :func:`solve_gram` over a stack of Gram matrices: (betas, sse)."""
    n = grams.shape[0]
    m = grams.shape[1] - 1
    XtX = grams[:, :-1, :-1]
    Xty = grams[:, :-1, -1]
    yty = grams[:, -1, -1]
    d = np.sqrt(np.maximum(np.einsum("pii->pi", XtX), 1e-300))
    A = XtX / (d[:, :, None] * d[:, None, :]) + 1e-12 * np.eye(m)
    b = Xty / d
    with np.errstate(all="ignore"):
        try:
            z = np.linalg.solve(A, b[:, :, None])[:, :, 0]
        except np.linalg.LinAlgError:
            z = np.full((n, m), -1.0)
    betas = z / d
    bad = ~np.all(np.isfinite(betas) & (betas >= 0), axis=1)
    sse = np.empty(n)
    for p in np.nonzero(bad)[0]:
        betas[p], sse[p] = solve_gram(grams[p])
    good = ~bad
    if np.any(good):
        bg = betas[good]
        sse[good] = (
            yty[good]
            - 2.0 * np.einsum("pi,pi->p", bg, Xty[good])
            + np.einsum("pi,pij,pj->p", bg, XtX[good], bg)
        )
    return betas, np.maximum(sse, 0.0)
