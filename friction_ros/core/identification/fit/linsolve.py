"""Non-negative linear least squares from Gram matrices (the linear half of variable projection).

Given ``G = [X y]^T [X y]`` the residual sum of squares of ``y - X beta`` is
``y'y - 2 beta' X'y + beta' X'X beta``. Every linear coefficient here (static level, element
weights, micro-damping, viscous coefficient, inertia) is physically non-negative, so the solution
is the NNLS one: the unconstrained solution when it is non-negative, otherwise scipy's NNLS on the
Cholesky factor (same objective up to a constant).

Coefficients of either sign (a gravity amplitude's sine and cosine parts, a constant offset, a
spring, ripple harmonics: :mod:`~friction_ros.core.identification.fit.load_terms`) are marked ``free``
and eliminated first (Frisch-Waugh-Lovell): with the Gram blocks of the sign-constrained columns
``C``, the free columns ``F`` and the target ``y``, the free part is optimal at
``z = G_FF^-1 (G_Fy - G_FC beta)`` for any ``beta``, so the constrained problem sees the Schur
complement ``G' = G_[C y] - G_[C y]F G_FF^-1 G_F[C y]`` (the Gram of the columns with the free
columns projected out) and NNLS on ``G'`` gives the same minimum as the joint problem.
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


def solve_grams(grams: np.ndarray, free: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Vectorised :func:`solve_gram` over a stack of Gram matrices: (betas, sse).

    ``free``: boolean mask over the linear coefficients that may take either sign (eliminated by
    the Schur complement of the module docstring); None = all non-negative.
    """
    if free is not None and np.any(free):
        return _solve_with_free(grams, np.asarray(free, bool))
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


def _solve_with_free(grams: np.ndarray, free: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """:func:`solve_grams` with the ``free`` coefficients eliminated first (module docstring)."""
    m = grams.shape[1] - 1
    fi = np.nonzero(free)[0]
    ci = np.concatenate([np.nonzero(~free)[0], [m]])  # constrained columns + target
    Gff = grams[:, fi][:, :, fi]
    Gfc = grams[:, fi][:, :, ci]
    d = np.sqrt(np.maximum(np.einsum("pii->pi", Gff), 1e-300))
    A = Gff / (d[:, :, None] * d[:, None, :]) + 1e-10 * np.eye(fi.size)
    with np.errstate(all="ignore"):
        W = np.linalg.solve(A, Gfc / d[:, :, None]) / d[:, :, None]  # G_FF^-1 G_F[C y]
    reduced = grams[:, ci][:, :, ci] - np.einsum("pfi,pfj->pij", Gfc, W)
    reduced = 0.5 * (reduced + np.transpose(reduced, (0, 2, 1)))
    n = grams.shape[0]
    betas = np.zeros((n, m))
    if ci.size > 1:
        bc, sse = solve_grams(reduced)
    else:
        bc, sse = np.zeros((n, 0)), np.maximum(reduced[:, 0, 0], 0.0)
    betas[:, ci[:-1]] = bc
    # z = G_FF^-1 (G_Fy - G_FC beta): W's last column minus W's constrained columns times beta
    betas[:, fi] = W[:, :, -1] - np.einsum("pfc,pc->pf", W[:, :, :-1], bc)
    bad = ~np.all(np.isfinite(betas), axis=1)
    betas[bad] = 0.0
    sse = np.where(bad, np.inf, sse)
    return betas, sse
