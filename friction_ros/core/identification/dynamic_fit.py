"""Output-error fitting on the recorded trajectory (seed 003 A.3; BAM's simulate-and-compare).

For a candidate ``theta`` the friction model is *simulated* along the measured velocity trajectory
(its internal states -- bristle deflection, Maxwell-slip element forces -- are never measured) and
the predicted joint torque ``tau_hat = J a + F_hat`` (seed 003 eq. 1) is compared with the measured
torque; the inertia ``J`` is identified jointly, as in seed 003. The cost is the mean squared torque
error on the training data.

Optimisation:

1. global search over the few nonlinear coefficients (log10 space for scale parameters) with
   scipy's ``differential_evolution`` (population vectorised: one compiled, multi-threaded batch
   simulation per generation) or seed 001's GA (:mod:`ga`);
2. local refinement with Nelder-Mead (seed 003's optimiser), bounded;
3. the linear coefficients are solved exactly per candidate (variable projection, :mod:`linsolve`).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import differential_evolution, minimize

from friction_ros.core.identification.data import JointData
from friction_ros.core.identification.ga import run_ga
from friction_ros.core.identification.linsolve import solve_grams
from friction_ros.core.identification.models import FitSpec
from friction_ros.core.validation import check_choice


@dataclass
class DynamicFit:
    """Result of one time-domain fit."""

    spec: FitSpec
    theta: np.ndarray
    beta: np.ndarray
    coefficients: dict
    train_mse: float
    evaluations: int
    seconds: float
    optimizer: str
    history: list[float] = field(default_factory=list)

    def predict(self, data: JointData) -> np.ndarray:
        """Predicted joint torque J a + F_hat over a record (states start from rest)."""
        X = self.spec.design(self.theta, data.velocity, data.acceleration, data.dt)
        return X @ self.beta

    def friction(self, data: JointData) -> np.ndarray:
        """Predicted friction torque F_hat (without the inertial term)."""
        X = self.spec.design(self.theta, data.velocity, data.acceleration, data.dt)
        return X[:, :-1] @ self.beta[:-1]


class _Cost:
    """MSE(theta) with the linear part solved; vectorised over a population in search space."""

    def __init__(self, spec: FitSpec, records: list[JointData]):
        self.spec = spec
        self.records = records
        self.n = sum(r.n for r in records)
        self.evals = 0

    def grams(self, thetas: np.ndarray) -> np.ndarray:
        g = None
        for r in self.records:
            gi = self.spec.grams(thetas, r.velocity, r.acceleration, r.torque, r.dt)
            g = gi if g is None else g + gi
        return g

    def batch_theta(self, thetas: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        self.evals += thetas.shape[0]
        betas, sse = solve_grams(self.grams(thetas))
        mse = sse / self.n
        return np.where(np.isfinite(mse), mse, np.inf), betas

    def batch_search(self, X: np.ndarray) -> np.ndarray:
        """Cost of search-space points X (npop x d)."""
        return self.batch_theta(self.spec.from_search(X))[0]


def fit_time_domain(
    spec: FitSpec,
    records: JointData | list[JointData],
    *,
    optimizer: str = "de",
    maxiter: int | None = None,
    popsize: int = 12,
    seed: int | None = 3,
    x0: np.ndarray | None = None,
    local: str = "nelder-mead",
    local_maxfev: int | None = None,
    time_limit: float | None = None,
    progress: Callable[[float], None] | None = None,
) -> DynamicFit:
    """Fit ``spec`` to the training record(s); see the module docstring for the method.

    ``progress(fraction)`` is called as the search advances (for progress bars).
    """
    optimizer = check_choice("optimizer", optimizer, ["de", "ga", "none"])
    records = [records] if isinstance(records, JointData) else list(records)
    t0 = time.perf_counter()
    cost = _Cost(spec, records)
    d = len(spec.nonlinear)
    history: list[float] = []
    if d == 0:
        mse, betas = cost.batch_theta(np.zeros((1, 0)))
        if progress:
            progress(1.0)
        return DynamicFit(
            spec,
            np.zeros(0),
            betas[0],
            spec.coefficients(np.zeros(0), betas[0]),
            float(mse[0]),
            1,
            time.perf_counter() - t0,
            "linear",
        )
    bounds = spec.search_bounds()
    lo = np.array([b[0] for b in bounds])
    hi = np.array([b[1] for b in bounds])
    xs0 = None if x0 is None else np.clip(spec.to_search(x0), lo, hi)
    if maxiter is None:
        maxiter = 40 + 15 * d
    best_x = xs0 if xs0 is not None else 0.5 * (lo + hi)
    if optimizer == "de":
        it = [0]

        def cb(*_args, **_kw):
            it[0] += 1
            if progress:
                progress(min(0.9 * it[0] / maxiter, 0.9))
            if time_limit is not None and time.perf_counter() - t0 > 0.8 * time_limit:
                return True
            return False

        res = differential_evolution(
            lambda X: cost.batch_search(np.atleast_2d(X.T)),
            bounds,
            vectorized=True,
            updating="deferred",
            popsize=popsize,
            maxiter=maxiter,
            tol=0.01,
            atol=0.0,
            seed=seed,
            polish=False,
            init="sobol",
            x0=xs0,
            callback=cb,
        )
        best_x = res.x
        history.append(float(res.fun))
    elif optimizer == "ga":
        # seed 001 GA in search coordinates shifted to be positive: its abs() repair then acts as a
        # reflection at the lower bound; initialisation ranges = the bounds.
        shift = lo - 0.01

        def ga_cost(P):
            return cost.batch_search(np.clip(P + shift, lo - 1.0, hi + 1.0))

        ga_lo, ga_hi = lo - shift, hi - shift
        init = None
        if xs0 is not None:
            rng = np.random.default_rng(seed)
            init = ga_lo + (ga_hi - ga_lo) * rng.random((10, d))
            init[0] = xs0 - shift
        gens = max(maxiter * 3, 100)
        res = run_ga(
            ga_cost,
            ga_lo,
            ga_hi,
            initial=init,
            max_generations=gens,
            stagnation=max(gens // 3, 50),
            seed=seed,
            time_limit=None if time_limit is None else 0.8 * time_limit,
            callback=(lambda g, f: progress(min(0.9 * g / gens, 0.9))) if progress else None,
        )
        best_x = res.best + shift
        history = res.history
    if local and local != "none":
        check_choice("local", local, ["nelder-mead", "none"])
        maxfev = local_maxfev or 60 * (d + 1)
        r = minimize(
            lambda x: float(cost.batch_search(np.clip(x, lo, hi)[None, :])[0]),
            np.clip(best_x, lo, hi),
            method="Nelder-Mead",
            bounds=bounds,
            options={"maxfev": maxfev, "xatol": 1e-5, "fatol": 1e-12, "adaptive": d > 4},
        )
        best_x = np.clip(r.x, lo, hi)
    theta = spec.from_search(best_x)
    mse, betas = cost.batch_theta(theta[None, :])
    if progress:
        progress(1.0)
    return DynamicFit(
        spec,
        theta,
        betas[0],
        spec.coefficients(theta, betas[0]),
        float(mse[0]),
        cost.evals,
        time.perf_counter() - t0,
        optimizer,
        history,
    )
