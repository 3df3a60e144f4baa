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
``sqrt(diag(P) * sigma2)`` with ``sigma2`` an exponentially weighted residual variance.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

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
    ):
        self.names = list(names)
        n = len(self.names)
        if n == 0:
            raise ParameterError("rls: needs at least one coefficient")
        self.forgetting_factor = check_real(
            "estimator.forgetting_factor", forgetting_factor, 0.5, 1.0, lo_open=True
        )
        self.initial_covariance = check_real(
            "estimator.initial_covariance", initial_covariance, 0.0, lo_open=True
        )
        self.max_covariance = check_real("estimator.max_covariance", max_covariance, 0.0, lo_open=True)
        init = np.zeros(n) if initial is None else np.asarray(initial, dtype=float)
        if init.shape != (n,) or not np.all(np.isfinite(init)):
            raise ParameterError(
                f"rls: initial = {list(init)!r} must be {n} finite numbers ({', '.join(names)})"
            )
        self._theta0 = init.copy()
        self.reset()

    def reset(self) -> None:
        n = len(self.names)
        self.theta = self._theta0.copy()
        self.P = np.eye(n) * self.initial_covariance
        self.sigma2 = 0.0
        self.samples = 0
        self.updates = 0

    def predict(self, phi: np.ndarray) -> float:
        return float(np.dot(phi, self.theta))

    def update(self, phi: Sequence[float], y: float, excited: bool = True) -> float:
        """Process one sample; returns the a-priori residual. ``excited`` False: skip the update."""
        phi = np.asarray(phi, dtype=float)
        r = float(y) - float(phi @ self.theta)
        self.samples += 1
        if not excited or not math.isfinite(r) or not np.any(phi):
            return r
        lam = self.forgetting_factor
        Pphi = self.P @ phi
        denom = lam + float(phi @ Pphi)
        K = Pphi / denom
        self.theta = self.theta + K * r
        P = self.P - np.outer(K, Pphi)
        if lam < 1.0:
            d = (phi != 0.0).astype(float)
            P = P + (1.0 / lam - 1.0) * (d[:, None] * P * d[None, :])
        P = 0.5 * (P + P.T)
        dmax = np.max(np.diag(P))
        if dmax > self.max_covariance:
            P *= self.max_covariance / dmax
        self.P = P
        # residual variance (EW, same memory as the forgetting factor, at least 100 samples)
        a = max(1.0 - lam, 0.01)
        self.sigma2 = r * r if self.updates == 0 else (1.0 - a) * self.sigma2 + a * r * r
        self.updates += 1
        return r

    @property
    def std(self) -> np.ndarray:
        return np.sqrt(np.maximum(np.diag(self.P), 0.0) * self.sigma2)
