"""Compiled (numba) kernels of GA friction thesis 2002's unity-feedback loop (:mod:`.ga_thesis_loop`).

Plant (thesis eqs. 20-21): ``J_m phi'' + B_m phi' = (u - phi) - F_Exp(phi')``, explicit-Euler
sub-steps (GA friction thesis 2002 section 9 item 4); fitness eq. (17) over a GA population.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

# the fitter's numba set-up (passive OpenMP wait policy) before a parallel kernel first runs
from friction_ros.core.identification.fit import kernels as _fit_kernels  # noqa: F401


@njit(cache=True, inline="always")
def exp_friction(w, f_st, gamma, delta, f_kmin, sigma):
    """GA friction thesis 2002 eq. (21): (F_kmin + (F_ST - F_kmin) exp(-(gamma |v|)^delta) + sigma |v|) sgn(v)."""
    if w == 0.0:
        return 0.0
    aw = abs(w)
    f = f_kmin + (f_st - f_kmin) * math.exp(-math.pow(gamma * aw, delta)) + sigma * aw
    return f if w > 0.0 else -f


@njit(cache=True)
def ga_thesis_loop_simulate(P, u, substeps, h):
    """Simulated output phi[k] of GA friction thesis 2002's loop J_m phi'' + B_m phi' = (u - phi) - F_Exp(phi').

    P = [F_ST, gamma, delta, F_kmin, sigma, J_m, B_m]; u is held over each sample (ZOH) and
    integrated with ``substeps`` explicit-Euler steps of size ``h`` (GA friction thesis 2002 section 9 item 4).
    """
    n = u.shape[0]
    out = np.empty(n)
    phi = 0.0
    w = 0.0
    for k in range(n):
        out[k] = phi
        uk = u[k]
        for _ in range(substeps):
            f = exp_friction(w, P[0], P[1], P[2], P[3], P[4])
            wd = (uk - phi - f - P[6] * w) / P[5]
            phi += h * w
            w += h * wd
    return out


@njit(cache=True, parallel=True)
def ga_thesis_loop_fit_batch(P, u, theta, substeps, h):
    """GA friction thesis 2002 eq. (17) Fit = sum_k (theta[k] - phi[k])^2 for every row of P (inf if invalid)."""
    npop = P.shape[0]
    n = u.shape[0]
    fits = np.empty(npop)
    for p in prange(npop):
        ok = True
        for j in range(P.shape[1]):
            if not (P[p, j] > 0.0) or not math.isfinite(P[p, j]):
                ok = False
        if not ok:
            fits[p] = np.inf
            continue
        f_st, gamma, delta, f_kmin, sigma, jm, bm = (
            P[p, 0],
            P[p, 1],
            P[p, 2],
            P[p, 3],
            P[p, 4],
            P[p, 5],
            P[p, 6],
        )
        phi = 0.0
        w = 0.0
        acc = 0.0
        for k in range(n):
            e = theta[k] - phi
            acc += e * e
            uk = u[k]
            for _ in range(substeps):
                f = exp_friction(w, f_st, gamma, delta, f_kmin, sigma)
                wd = (uk - phi - f - bm * w) / jm
                phi += h * w
                w += h * wd
            if not math.isfinite(phi) or abs(phi) > 1e6:
                acc = np.inf
                break
        fits[p] = acc
    return fits
