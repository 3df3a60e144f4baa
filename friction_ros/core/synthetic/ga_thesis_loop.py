"""GA friction thesis 2002's identification set-up: unity-feedback loop, position output error, GA.

Plant with the modified Exponential friction model (thesis eqs. 20-21, GA friction thesis 2002 section 1.2-1.3):

    J_m phi'' + B_m phi' = (u - phi) - F_Exp(phi'),
    F_Exp(v) = (F_kmin + (F_ST - F_kmin) exp(-(gamma |v|)^delta) + sigma |v|) sgn(v),  sgn(0) = 0

driven by the decreasing-amplitude chirp (variant A, GA friction thesis 2002 section 4.2)
``u(t) = (pi - 0.01 t) sin(0.3 t + 0.003 t^2)`` sampled at 0.01 s, integrated with explicit
Euler sub-steps (GA friction thesis 2002 section 9 item 4). Fitness, eq. (17): ``Fit = sum_k (theta[k] - phi[k])^2``
(positions only). Genes ``P = {F_ST, gamma, delta, F_kmin, sigma, J_m, B_m}``; GA per :mod:`ga`
with 10 Parents x 8 Children, initialisation U[0.01, 1.5], age threshold 4.

Identifiability: sigma |v| sgn(v) = sigma v is the same regressor as B_m v, so only sigma + B_m is
identifiable (GA friction thesis 2002 section 3.8); :func:`identifiability_report` shows it from the Jacobian.
"""

from __future__ import annotations

import math

import numpy as np

from friction_ros.core.identification.fit import identifiability
from friction_ros.core.identification.fit.ga import GAResult, run_ga
from friction_ros.core.synthetic.ga_thesis_loop_kernels import (
    ga_thesis_loop_fit_batch,
    ga_thesis_loop_simulate,
)

GENES = ["F_ST", "gamma", "delta", "F_kmin", "sigma", "J_m", "B_m"]
#: Tables 5.2 / 5.3 of the thesis (GA friction thesis 2002 section 5)
THESIS = np.array([1.5281, 4.3743, 0.1992, 0.3303, 0.0588, 0.2734, 0.2738])


def chirp_input(duration: float = 200.0, dt: float = 0.01) -> np.ndarray:
    """Variant-A decreasing-amplitude chirp (GA friction thesis 2002 section 4.2)."""
    t = np.arange(int(round(duration / dt))) * dt
    return (math.pi - 0.01 * t) * np.sin(0.3 * t + 0.003 * t**2)


def simulate(P, u, dt: float = 0.01, substeps: int = 10) -> np.ndarray:
    """Simulated position phi[k] for genes P on input u (ZOH, explicit-Euler sub-steps)."""
    return ga_thesis_loop_simulate(np.asarray(P, float), np.asarray(u, float), substeps, dt / substeps)


def fit(u, theta, dt: float = 0.01, substeps: int = 10, **ga_options) -> GAResult:
    """Run GA friction thesis 2002's GA on (u, theta); ``ga_options`` go to :func:`ga.run_ga`."""
    u = np.ascontiguousarray(u, float)
    theta = np.ascontiguousarray(theta, float)
    h = dt / substeps
    opts = {"n_parents": 10, "n_children": 8, "age_threshold": 4, "seed": 1}
    opts.update(ga_options)
    lo = np.full(7, 0.01)
    hi = np.full(7, 1.5)
    return run_ga(
        lambda P: ga_thesis_loop_fit_batch(np.ascontiguousarray(P), u, theta, substeps, h), lo, hi, **opts
    )


def friction_curve(P, v) -> np.ndarray:
    """Total dissipative curve F_Exp(v) + B_m v (what the data determine; GA friction thesis 2002 section 9 item 5d)."""
    f_st, gamma, delta, f_kmin, sigma, _jm, bm = P
    av = np.abs(v)
    return (f_kmin + (f_st - f_kmin) * np.exp(-((gamma * av) ** delta)) + sigma * av) * np.sign(v) + bm * v


def identifiability_report(P, u, theta, dt: float = 0.01) -> dict:
    """Identifiability of the 7 genes at P from the force balance along the measured trajectory.

    The position output error of this loop is not smooth in P (stick chatter through sgn(v)), so
    finite differences of the simulated position are noise at small steps. The torque-level
    residual ``r = J_m w' + B_m w + F_Exp(w) - (u - theta)`` with w, w' differentiated from the
    measured theta has exact, smooth sensitivities; its Jacobian exposes structural collinearity
    (sigma and B_m both multiply w).
    """
    P = np.asarray(P, float)
    th = np.asarray(theta, float)
    w = np.gradient(th, dt)
    wd = np.gradient(w, dt)
    m = w != 0
    w, wd, e_in = w[m], wd[m], (np.asarray(u, float) - th)[m]

    def resid(Q):
        return Q[5] * wd + Q[6] * w + friction_curve(np.r_[Q[:6], 0.0], w) - e_in

    base = resid(P)
    cols = []
    for i in range(7):
        h = 1e-6 * max(abs(P[i]), 1e-3)
        Q1, Q2 = P.copy(), P.copy()
        Q1[i] += h
        Q2[i] -= h
        cols.append((resid(Q1) - resid(Q2)) / (2 * h))
    return identifiability.analyse(np.column_stack(cols), base, GENES, P, tol=1e-6)
