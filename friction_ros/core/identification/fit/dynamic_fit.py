"""Output-error fitting on the recorded trajectory (ABB M19-S paper A.3; BAM's simulate-and-compare).

For a candidate ``theta`` the friction model is *simulated* along the measured velocity trajectory
(its internal states -- bristle deflection, Maxwell-slip element forces -- are never measured) and
the predicted joint torque ``tau_hat = J a + F_hat`` (ABB M19-S paper eq. 1) is compared with the measured
torque; the inertia ``J`` is identified jointly, as in the ABB M19-S paper. The cost is the mean squared torque
error on the training data, after a causal low-pass applied alike to the torque and to every
regressor (GMS: states driven by a narrow-window velocity, see :class:`Signals`).

Optimisation:

1. global search over the few nonlinear coefficients (log10 space for scale parameters) with
   scipy's ``differential_evolution`` (population vectorised: one compiled, multi-threaded batch
   simulation per generation; stopped early once its best cost stalls, see STALL_GENERATIONS) or
   GA friction thesis 2002's GA (:mod:`ga`);
2. local refinement with Nelder-Mead (ABB M19-S paper's optimiser), bounded;
3. the linear coefficients are solved exactly per candidate (variable projection, :mod:`linsolve`).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
from scipy import signal
from scipy.optimize import differential_evolution, minimize
from scipy.signal import savgol_filter

from friction_ros.core.identification.data.data_scale import torque_scale
from friction_ros.core.identification.data.decimation import piecewise_derivatives
from friction_ros.core.identification.data.records import JointData
from friction_ros.core.identification.fit.ga import run_ga
from friction_ros.core.identification.fit.linsolve import solve_grams
from friction_ros.core.identification.fit.models import FitSpec
from friction_ros.core.validation import check_choice

#: the global search (DE) stops when its best cost fell by less than STALL_TOL (relative) over the last
#: STALL_GENERATIONS generations: further generations only reshuffle a converged population, and the
#: local Nelder-Mead refinement that follows finishes the descent at one simulation per step. A
#: damped GMS-4 can sit 10 generations on one best before it moves on (a 10-generation window cut
#: its fit short: feed-forward RMS 11.7 % off the truth's instead of < 10 %), hence 20.
STALL_GENERATIONS = 20
STALL_TOL = 1e-3


@dataclass
class Signals:
    """How the output-error fit derives its signals from a record (see :func:`fit_signals`).

    ``velocity_window`` [s]: Savitzky-Golay (cubic) window on the position for the velocity that
    drives the model states and the acceleration of the inertial term; narrow, because presliding
    oscillations (the joint ringing on the element stiffnesses, ~100 Hz) must survive. None = use
    the record's (smoother) velocity/acceleration. ``filter_hz``: cut-off of a causal Butterworth
    low-pass ``L`` (order ``filter_order``) applied alike to the torque and to every regressor
    column; since the model is linear in (element weights, viscous coefficient, J),
    ``L tau = sum beta_j L phi_j + F_v L v + J L a`` is exact, so the noise of the raw acceleration
    and torque is removed without the lag/attenuation mismatch of differentiating with one filter
    and not the other. None = no filter.
    """

    velocity_window: float | None = 0.005
    filter_hz: float | None = 20.0
    filter_order: int = 2

    def sos(self, dt: float) -> np.ndarray | None:
        if not self.filter_hz or self.filter_hz >= 0.45 / dt:
            return None
        return signal.butter(self.filter_order, self.filter_hz, fs=1.0 / dt, output="sos")


DEFAULT_SIGNALS = Signals()
# Static maps switch on sgn(v): a narrow-window velocity flips sign on encoder noise near rest, so
# they keep the record's smooth velocity and acceleration (no filter). Dahl/LuGre too: their single
# bristle stiffness cannot follow the multi-element presliding ringing of a GMS-like joint, and
# fitted to it (narrow window) their validation NMSE rose from 4.6 to 29 % on the 50 s benchmark.
SMOOTH_SIGNALS = Signals(velocity_window=None, filter_hz=None)


def default_signals(spec: FitSpec) -> Signals:
    """DEFAULT_SIGNALS for a family with ``narrow_signals`` (GMS), SMOOTH_SIGNALS for the others."""
    return DEFAULT_SIGNALS if spec.model.narrow_signals else SMOOTH_SIGNALS


def fit_signals(data: JointData, sig: Signals | None = None) -> tuple[np.ndarray, np.ndarray]:
    """(velocity, acceleration) for the output-error fit of ``data`` (see :class:`Signals`)."""
    sig = DEFAULT_SIGNALS if sig is None else sig
    if sig.velocity_window is None:
        return data.velocity, data.acceleration
    w = max(int(round(sig.velocity_window / data.dt)) | 1, 5)
    if data.n <= w:
        return data.velocity, data.acceleration
    if (pieces := piecewise_derivatives(data, w)) is not None:  # a long log cut down: joins
        return pieces
    v = savgol_filter(data.position, w, 3, deriv=1, delta=data.dt, mode="interp")
    a = savgol_filter(data.position, w, 3, deriv=2, delta=data.dt, mode="interp")
    return v, a


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
    signals: Signals = field(default_factory=Signals)

    def _design(self, data: JointData) -> np.ndarray:
        # the same signals as the fit: the inertial term must carry the same bandwidth as the
        # friction states (presliding ringing appears in both and cancels in the measured torque)
        v, a = fit_signals(data, self.signals)
        return self.spec.design(self.theta, v, a, data.dt, self.spec.load_matrix(data, v))

    def predict(self, data: JointData) -> np.ndarray:
        """Predicted joint torque J a + F_hat over a record (states start from rest)."""
        return self._design(data) @ self.beta

    def friction(self, data: JointData) -> np.ndarray:
        """Predicted friction torque F_hat (without the inertial and the load-torque terms; with the
        load- and position-dependent friction)."""
        X = self._design(data)
        b = self.beta.copy()
        b[-1] = 0.0
        for i, n in enumerate(self.spec.linear_all):
            if n.startswith(("gravity_", "offset", "spring")):
                b[i] = 0.0
        return X @ b

    @property
    def load_coefficients(self) -> dict:
        return self.spec.load_coefficients(self.beta)


class _Cost:
    """MSE(theta) with the linear part solved; vectorised over a population in search space."""

    def __init__(self, spec: FitSpec, records: list[JointData], sig: Signals | None = None):
        self.spec = spec
        self.records = records
        self.sig = DEFAULT_SIGNALS if sig is None else sig
        self.inputs = []
        for r in records:
            v, a = fit_signals(r, self.sig)
            self.inputs.append((v, a, r.torque, r.dt, self.sig.sos(r.dt), spec.load_matrix(r, v)))
        self.free = spec.free
        self.n = sum(r.n for r in records)
        self.evals = 0

    def grams(self, thetas: np.ndarray) -> np.ndarray:
        g = None
        for v, a, tau, dt, sos, load in self.inputs:
            gi = self.spec.grams(thetas, v, a, tau, dt, sos, load)
            g = gi if g is None else g + gi
        return g

    def batch_theta(self, thetas: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        self.evals += thetas.shape[0]
        betas, sse = solve_grams(self.grams(thetas), self.free)
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
    signals: Signals | None = None,
) -> DynamicFit:
    """Fit ``spec`` to the training record(s); see the module docstring for the method.

    ``progress(fraction)`` is called as the search advances (for progress bars).
    """
    optimizer = check_choice("optimizer", optimizer, ["de", "ga", "none"])
    records = [records] if isinstance(records, JointData) else list(records)
    t0 = time.perf_counter()
    signals = default_signals(spec) if signals is None else signals
    cost = _Cost(spec, records, signals)
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
            signals=signals,
        )
    bounds = spec.search_bounds()
    # costs in the log's own effort unit squared: the same numbers (and tolerances) at any scale
    tnorm = torque_scale(records[0]) ** 2
    lo = np.array([b[0] for b in bounds])
    hi = np.array([b[1] for b in bounds])
    xs0 = None if x0 is None else np.clip(spec.to_search(x0), lo, hi)
    if maxiter is None:
        maxiter = 40 + 15 * d
    best_x = xs0 if xs0 is not None else 0.5 * (lo + hi)
    if optimizer == "de":
        it = [0]

        best: list[float] = []  # the best cost after each generation (the first: the initial population)

        def generation(X):
            c = cost.batch_search(np.atleast_2d(X.T)) / tnorm
            best.append(min(float(np.min(c)), best[-1] if best else np.inf))
            return c

        def cb(*_args, **_kw):
            it[0] += 1
            if len(best) > STALL_GENERATIONS and best[-1] > (1.0 - STALL_TOL) * best[-1 - STALL_GENERATIONS]:
                return True  # converged: Nelder-Mead refines from here
            if progress:
                progress(min(0.9 * it[0] / maxiter, 0.9))
            if time_limit is not None and time.perf_counter() - t0 > 0.8 * time_limit:
                return True
            return False

        res = differential_evolution(
            generation,
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
        # GA friction thesis 2002 GA in search coordinates shifted to be positive: its abs() repair then acts as a
        # reflection at the lower bound; initialisation ranges = the bounds.
        shift = lo - 0.01

        def ga_cost(P):
            return cost.batch_search(np.clip(P + shift, lo - 1.0, hi + 1.0)) / tnorm

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
            lambda x: float(cost.batch_search(np.clip(x, lo, hi)[None, :])[0]) / tnorm,
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
        signals,
    )
