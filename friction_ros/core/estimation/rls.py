"""Recursive least squares with forgetting, gated by excitation, for linear-in-parameter friction.

Model ``y = phi(v)^T theta + noise`` (Ljung, *System Identification*, 11.2)::

    K     = P phi / (lambda + phi^T P phi)
    theta = theta + K (y - phi^T theta)
    P     = (P - K phi^T P) + (1/lambda - 1) D (P - K phi^T P) D      (selective forgetting)

``D = diag(phi_i != 0)``: forgetting only acts on the parameters the sample excites, so a direction
that is not excited (e.g. the negative Coulomb level while the joint only moves forward) keeps its
covariance (no covariance wind-up). Samples are skipped altogether when the excitation check
fails (|v| below ``min_velocity``: at rest or in presliding the static maps do not apply), so the
estimate cannot drift while the joint rests. The coefficient standard deviation is
``sqrt(diag(P) * residual_variance)``, ``residual_variance`` being the exponentially weighted residual variance.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from friction_ros.core.config import Names
from friction_ros.core.estimation.measurement import NAMES
from friction_ros.core.validation import ParameterError, check_real


class RecursiveLeastSquares:
    """RLS with forgetting and excitation gating; see the module docstring."""

    def __init__(
        self,
        names: Sequence[str],
        initial: Sequence[float] | None = None,
        forgetting_factor: float = 0.999,
        initial_covariance: float = 10.0,
        max_covariance: float = 1e6,
        param_names: Names = NAMES,
    ):
        self.names = list(names)
        n = len(self.names)
        if n == 0:
            raise ParameterError("rls: needs at least one coefficient")
        self.forgetting_factor = check_real(
            param_names("forgetting_factor"), forgetting_factor, 0.5, 1.0, lo_open=True
        )
        self.initial_covariance = check_real(
            param_names("initial_covariance"), initial_covariance, 0.0, lo_open=True
        )
        self.max_covariance = check_real(param_names("max_covariance"), max_covariance, 0.0, lo_open=True)
        init = np.zeros(n) if initial is None else np.asarray(initial, dtype=float)
        if init.shape != (n,) or not np.all(np.isfinite(init)):
            raise ParameterError(
                f"rls: initial = {list(init)!r} must be {n} finite numbers ({', '.join(names)})"
            )
        self._theta0 = init.copy()
        self.reset()

    # The state is kept in plain Python lists: with 1-6 coefficients every numpy call costs more
    # than the arithmetic (the estimator node runs this at 1 kHz; ~4x faster than the numpy form).
    def reset(self) -> None:
        n = len(self.names)
        self._th = [float(x) for x in self._theta0]
        self._P = [[self.initial_covariance if i == j else 0.0 for j in range(n)] for i in range(n)]
        self.residual_variance = 0.0
        self.samples = 0
        self.updates = 0

    @property
    def theta(self) -> np.ndarray:
        """Current coefficient estimate (copy)."""
        return np.array(self._th)

    def theta_list(self) -> list[float]:
        """Current coefficient estimate as a list of floats (no numpy)."""
        return list(self._th)

    @theta.setter
    def theta(self, value) -> None:
        self._th = [float(x) for x in value]

    @property
    def P(self) -> np.ndarray:
        """Covariance matrix (copy)."""
        return np.array(self._P)

    @P.setter
    def P(self, value) -> None:
        self._P = [[float(x) for x in row] for row in np.asarray(value, dtype=float)]

    def predict(self, phi: Sequence[float]) -> float:
        return _dot([float(x) for x in phi], self._th)

    def update(self, phi: Sequence[float], y: float, excited: bool = True) -> float:
        """Process one sample; returns the a-priori residual. ``excited`` False: skip the update."""
        phi = [float(x) for x in phi]
        th = self._th
        r = float(y) - _dot(phi, th)
        self.samples += 1
        if not excited or not math.isfinite(r) or not any(phi):
            return r
        lam = self.forgetting_factor
        P = self._P
        n = len(phi)
        rng = range(n)
        Pphi = [_dot(P[i], phi) for i in rng]
        denom = lam + _dot(phi, Pphi)
        K = [x / denom for x in Pphi]
        self._th = [th[i] + K[i] * r for i in rng]
        # P <- sym(F(P - K Pphi^T)), F: forgetting on the excited directions (d), sym: 0.5 (A + A^T);
        # one pass over the upper triangle with the same operations in the same order per element
        f = 1.0 / lam - 1.0 if lam < 1.0 else 0.0
        d = [1.0 if x != 0.0 else 0.0 for x in phi]
        new = [[0.0] * n for _ in rng]
        for i in rng:
            Pi, Ki, Pphii, di, row = P[i], K[i], Pphi[i], d[i], new[i]
            for j in range(i, n):
                pij = Pi[j] - Ki * Pphi[j]
                pji = P[j][i] - K[j] * Pphii
                if f:
                    pij = pij + f * (di * pij * d[j])
                    pji = pji + f * (d[j] * pji * di)
                row[j] = new[j][i] = 0.5 * (pij + pji)
        P = new
        dmax = max(P[i][i] for i in rng)
        if dmax > self.max_covariance:
            c = self.max_covariance / dmax
            P = [[x * c for x in row] for row in P]
        self._P = P
        # residual variance (EW, same memory as the forgetting factor, at least 100 samples)
        a = max(1.0 - lam, 0.01)
        self.residual_variance = (
            r * r if self.updates == 0 else (1.0 - a) * self.residual_variance + a * r * r
        )
        self.updates += 1
        return r

    def std_list(self) -> list[float]:
        """One-sigma standard deviation of each coefficient (list of floats)."""
        s2 = self.residual_variance
        return [math.sqrt(max(self._P[i][i], 0.0) * s2) for i in range(len(self._th))]

    @property
    def std(self) -> np.ndarray:
        return np.array(self.std_list())


def _dot(a: Sequence[float], b: Sequence[float]) -> float:
    """Sum of products, left to right."""
    total = 0.0
    for x, y in zip(a, b):
        total += x * y
    return total
