"""Fit specifications: each fittable model as (nonlinear search space) + (linear coefficients).

Every model predicts the measured joint torque as (ABB M19-S paper A.3, eq. 1 with tau_0 = 0)

    tau_hat = J a + F_hat(v trajectory),      F_hat = sum_j beta_j phi_j(v; theta) + fv v

where ``theta`` are the few coefficients that enter nonlinearly (searched globally, then refined)
and ``beta`` (static level, element weights, micro-damping), the viscous coefficient ``fv`` and
the inertia ``J`` enter linearly and are solved exactly by non-negative least squares for every
candidate ``theta`` (variable projection). What a family owns (its coefficients, bounds,
regressors, physical coefficients, library config) is its :class:`~.fit_model.FitModel` (built-in
families in :mod:`~.fit_families`, the compiled regressors in :mod:`kernels`); a :class:`FitSpec`
is one fit's search space built from it (bounds in the log's units, narrowed by the data, load
terms, constraints). :meth:`FitSpec.coefficients` returns the family's physical coefficients (the
friction library's names, docs/coefficients.md) plus the inertia ``J`` [kg*m^2].
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy import signal

from friction_ros.core.identification.fit.fit_model import (  # noqa: F401 (mid_velocity, sat_sign re-exported)
    FitModel,
    mid_velocity,
    sat_sign,
)
from friction_ros.core.identification.fit.fit_registry import LEARNED, fit_model, model_help
from friction_ros.core.identification.fit.load_terms import LoadTerms
from friction_ros.core.validation import ParameterError

DEFAULT_EPS = 1e-3  # [rad/s] width of the linear zone replacing sgn(v) (ABB M19-S paper A.2.1/A.2.2)
CONSTRAINT_WEIGHT = 1e6  # linear equality constraints: pseudo-observation weight (see FitSpec._constrain)


@dataclass
class FitSpec:
    """One fittable model: names, bounds and regressors of its nonlinear and linear parts."""

    model: FitModel  # the family's plugin (fit_model.FitModel): regressors, coefficients, export
    nonlinear: list[str]
    lower: np.ndarray
    upper: np.ndarray
    log: np.ndarray  # search in log10 space for this coefficient
    eps: float = DEFAULT_EPS
    mid_velocity: bool = True  # drive the states with the interval-mean velocity
    extra: dict = field(default_factory=dict)
    # equality constraints c . beta = d on the linear coefficients (order of linear_all), see
    # fix_steady_state; enforced in grams() as heavily weighted pseudo-observations
    linear_constraints: list[tuple[np.ndarray, float]] = field(default_factory=list)
    # load, gravity and position terms identified jointly (load_terms.LoadTerms); None = none
    load: LoadTerms | None = None
    # the unit of each nonlinear coefficient in the search (velocity_scale^power, see spec_for): the
    # optimiser sees the same numbers for a log re-expressed in other units; None = all 1
    unit: np.ndarray | None = None

    @property
    def name(self) -> str:
        return self.model.name

    @property
    def family(self) -> str:
        return self.model.family

    @property
    def linear(self) -> list[str]:
        """The model's own linear coefficients (``fv``, load terms and ``J`` are appended)."""
        return self.model.linear()

    @property
    def viscous(self) -> bool:
        return self.model.viscous

    @property
    def dynamic(self) -> bool:
        return self.model.dynamic

    @property
    def n_elements(self) -> int:
        return getattr(self.model, "n_elements", 0)

    @property
    def damped(self) -> bool:
        """GMS: presliding damping time constant s = sigma1 / sum k (last of theta)."""
        return getattr(self.model, "damped", False)

    # ------------------------------------------------------------------ search-space transforms
    def to_search(self, theta: np.ndarray) -> np.ndarray:
        theta = np.asarray(theta, dtype=float)
        if self.unit is not None:
            theta = theta / self.unit
        return np.where(self.log, np.log10(np.maximum(theta, 1e-300)), theta)

    def from_search(self, x: np.ndarray) -> np.ndarray:
        x = np.asarray(x, dtype=float)
        theta = np.where(self.log, 10.0**x, x)
        return theta if self.unit is None else theta * self.unit

    def search_bounds(self) -> list[tuple[float, float]]:
        lo = self.to_search(self.lower)
        hi = self.to_search(self.upper)
        return list(zip(lo.tolist(), hi.tolist()))

    @property
    def load_names(self) -> list[str]:
        return [] if self.load is None else self.load.names

    @property
    def linear_all(self) -> list[str]:
        """Linear coefficients in design-column order: model, ``fv``, load terms, ``J`` (last)."""
        return [*self.linear, *(["fv"] if self.viscous else []), *self.load_names, "J"]

    @property
    def free(self) -> np.ndarray | None:
        """Mask of the linear coefficients that may take either sign (the load terms'), or None."""
        if not self.load_names:
            return None
        n_model = len(self.linear) + (1 if self.viscous else 0)
        return np.array([False] * n_model + list(self.load.free) + [False])

    def load_matrix(self, data, v: np.ndarray) -> np.ndarray | None:
        """The load-term columns of a record (``data``: JointData) for fit velocity ``v``."""
        if not self.load_names:
            return None
        return self.load.columns(data.position, v, data.transmitted)

    @property
    def n_params(self) -> int:
        return len(self.nonlinear) + len(self.linear_all)

    # ------------------------------------------------------------------ regressors
    def features(self, theta: np.ndarray, v: np.ndarray, dt: float) -> np.ndarray:
        """Model-specific regressor columns phi (n x len(linear)) for one theta."""
        v = np.ascontiguousarray(v, dtype=float)
        theta = np.ascontiguousarray(theta, dtype=float)
        if self.dynamic:
            v = self.state_velocity(v)
        return self.model.features(theta, v, dt, self.eps)

    def state_velocity(self, v: np.ndarray) -> np.ndarray:
        """The velocity that drives the internal states: the interval mean (see :func:`mid_velocity`)
        unless ``mid_velocity`` is off."""
        return mid_velocity(v) if self.mid_velocity else np.ascontiguousarray(v, dtype=float)

    def design(
        self, theta: np.ndarray, v: np.ndarray, a: np.ndarray, dt: float, load: np.ndarray | None = None
    ) -> np.ndarray:
        """Full design matrix [phi, (v), (load columns), a] for one theta (``load``: :meth:`load_matrix`)."""
        cols = [self.features(theta, v, dt)]
        if self.viscous:
            cols.append(np.asarray(v, dtype=float)[:, None])
        if load is not None:
            cols.append(load)
        elif self.load_names:
            raise ParameterError(
                f"{self.name}: the design needs the load columns ({', '.join(self.load_names)})"
            )
        cols.append(np.asarray(a, dtype=float)[:, None])
        return np.hstack(cols)

    def grams(
        self,
        P: np.ndarray,
        v: np.ndarray,
        a: np.ndarray,
        tau: np.ndarray,
        dt: float,
        sos: np.ndarray | None = None,
        load: np.ndarray | None = None,
    ) -> np.ndarray:
        """Gram matrices of L [phi, v, (load), a, tau] for every row of P (npop x m x m).

        ``sos``: second-order sections of a causal filter ``L`` applied to every column alike (the
        model is linear in beta, so ``L tau = sum beta_j L phi_j + fv L v + J L a`` holds exactly);
        None = no filter. The states are driven by the unfiltered ``v``.
        """
        P = np.ascontiguousarray(P, dtype=float)
        v = np.ascontiguousarray(v, dtype=float)
        a = np.ascontiguousarray(a, dtype=float)
        tau = np.ascontiguousarray(tau, dtype=float)
        sos = np.zeros((0, 6)) if sos is None else np.ascontiguousarray(sos, dtype=float)
        if load is None and self.load_names:
            raise ParameterError(
                f"{self.name}: the Gram needs the load columns ({', '.join(self.load_names)})"
            )
        # the columns that do not depend on theta, target last: [v, (load), a, tau]
        E = np.column_stack([v, *([] if load is None else [load]), a, tau])
        if sos.shape[0]:
            E = signal.sosfilt(sos, E, axis=0)
        E = np.ascontiguousarray(E)
        g = self.model.grams(P, self.state_velocity(v), E, dt, sos) if self.dynamic else None
        if g is None:
            out = []
            # with load terms, samples slower than their sign's linear zone are left out of a static
            # map's fit: the velocity estimate cannot tell their direction (a sign error of up to 2 fs
            # there biased gravity against the spring by 3 % on the realistic joint)
            keep = None
            if not self.dynamic and self.load is not None and not self.load.empty and not sos.shape[0]:
                keep = np.abs(v) >= self.load.eps
            for theta in P:
                phi = self.features(theta, v, dt)
                if sos.shape[0]:
                    phi = signal.sosfilt(sos, phi, axis=0)
                X = np.hstack([phi, E])
                if keep is not None:
                    X = X[keep]
                out.append(X.T @ X)
            g = np.array(out)
        if not self.viscous:  # drop the v row/column (index m_phi)
            i = len(self.linear)
            keep = [j for j in range(g.shape[1]) if j != i]
            g = g[:, keep][:, :, keep]
        return self._constrain(g)

    def _constrain(self, g: np.ndarray) -> np.ndarray:
        """Add each constraint ``c . beta = d`` as a pseudo-observation row ``sqrt(w) [c, d]``.

        ``w`` is CONSTRAINT_WEIGHT times the largest data weight of a constrained column
        (``(X'X)_ii / c_i^2``), so the data can move ``c . beta`` by about 1e-6 of what it would
        unconstrained; the non-negativity of the NNLS solve is kept (a null-space elimination would
        lose it for the GMS element weights)."""
        if not self.linear_constraints:
            return g
        g = g.copy()
        m = g.shape[1] - 1
        diag = np.einsum("pii->pi", g[:, :m, :m])
        for c, d in self.linear_constraints:
            on = c != 0
            w = CONSTRAINT_WEIGHT * np.max(diag[:, on] / c[on] ** 2, axis=1)
            row = np.append(c, d)
            g += w[:, None, None] * np.outer(row, row)[None]
        return g

    def fix_steady_state(self, static: dict) -> None:
        """Two-stage identification (anchors 3.3; AI friction chapter B.3): hold the whole steady-state curve
        at a static fit's ``fc, fs, vs, delta, fv`` (from constant-velocity plateaus, where the
        friction is measured directly) and leave only the presliding/dynamic coefficients and ``J``
        to the time-domain search.

        Nonlinear ``r = fc/fs, vs, delta``: bounds narrowed to +-0.1 % around the static values
        (not clipped to the free-fit bounds: a linear axis' vs can be far below 1e-3 m/s). Linear:
        ``fs`` (LuGre ``fs``; GMS the sum of the element weights) and ``fv`` by constraints. Left
        free, the time domain trades ``fc``/``fv`` against ``J`` and the filter lag: 2-9 % sliding
        map error on the presets against 0.1-0.2 % for the plateau fit."""
        fs = float(static.get("fs", static.get("fc", 0.0)))
        fc = float(static.get("fc", fs))
        values = {"r": fc / fs if fs > 0 else 1.0, "vs": static.get("vs"), "delta": static.get("delta")}
        for i, nme in enumerate(self.nonlinear):
            x = values.get(nme)
            if x is not None and np.isfinite(x) and x > 0:
                self.lower[i], self.upper[i] = float(x) * 0.999, float(x) * 1.001
        names = self.linear_all
        constraints = self.model.steady_state_constraints(names, fs) if fs > 0 else []
        if self.viscous and "fv" in static:
            constraints.append((np.array([1.0 if n == "fv" else 0.0 for n in names]), float(static["fv"])))
        self.linear_constraints = constraints

    # ------------------------------------------------------------------ physical coefficients
    def coefficients(self, theta: np.ndarray, beta: np.ndarray) -> dict:
        """Physical coefficients (SI) from the nonlinear theta and linear beta (incl. fv, J)."""
        theta = np.asarray(theta, dtype=float)
        beta = np.asarray(beta, dtype=float)
        lin = dict(zip(self.linear_all, beta.tolist()))
        J = lin.pop("J")
        fv = lin.pop("fv", 0.0)
        for n in self.load_names:
            lin.pop(n)
        c = self.model.coefficients(theta, lin, fv if self.viscous else None)
        return {**c, "J": J}

    def load_coefficients(self, beta: np.ndarray) -> dict:
        """The fitted load-term coefficients (keys = LoadTerms.names) from the linear beta."""
        lin = dict(zip(self.linear_all, np.asarray(beta, dtype=float).tolist()))
        return {n: lin[n] for n in self.load_names}

    def initial_theta(self, static: dict | None) -> np.ndarray:
        """A starting point for the local search from a static fit (fc, fs, vs, delta) if any."""
        mid = np.where(self.log, np.sqrt(self.lower * self.upper), 0.5 * (self.lower + self.upper))
        theta = mid.copy()
        if static:
            names = self.nonlinear
            fs = static.get("fs", static.get("fc", 1.0))
            fc = static.get("fc", fs)
            vals = {"r": fc / fs if fs > 0 else 0.8, "vs": static.get("vs"), "delta": static.get("delta")}
            for i, nme in enumerate(names):
                if nme in vals and vals[nme] is not None:
                    theta[i] = vals[nme]
        return np.clip(theta, self.lower, self.upper)


def spec_for(name: str, eps: float = DEFAULT_EPS, velocity_scale: float = 1.0) -> FitSpec:
    """The FitSpec of model ``name`` (any registered :class:`~.fit_model.FitModel`: ``gms<N>`` for a
    GMS with N elements (1..20), ``gms<N>d`` with presliding damping ...; bounds in
    :mod:`~friction_ros.core.identification.fit.fit_families`).

    ``velocity_scale`` (:mod:`~friction_ros.core.identification.data.data_scale`): each nonlinear
    coefficient's unit-scale bounds are multiplied by ``velocity_scale ** power`` (its
    :class:`~.fit_model.Coef` power: a velocity or position bound by the scale, an inverse position
    bound such as ``sigma_n``, ``sigma0_n`` divided by it), so the optimiser sees the same numbers for
    a log re-expressed in other units.
    """
    model = fit_model(name)
    coefs = model.nonlinear()
    spec = FitSpec(
        model,
        [c.name for c in coefs],
        np.array([c.lo for c in coefs], dtype=float),
        np.array([c.hi for c in coefs], dtype=float),
        np.array([c.log for c in coefs], dtype=bool),
        eps=eps,
    )
    if velocity_scale != 1.0:
        f = float(velocity_scale) ** np.array([c.power for c in coefs], dtype=float)
        spec.lower, spec.upper, spec.unit = spec.lower * f, spec.upper * f, f
    return spec


def check_model_names(models) -> list[str]:
    """Validate and normalise a list of model names (raises ParameterError naming the bad one)."""
    out = []
    for m in models:
        m = str(m).strip().lower()
        if m in LEARNED:
            out.append(m)
        else:
            out.append(fit_model(m).name)
    if not out:
        raise ParameterError(
            f"models = [] is empty: must name at least one of {model_help()}, {', '.join(LEARNED)}"
        )
    return list(dict.fromkeys(out))
