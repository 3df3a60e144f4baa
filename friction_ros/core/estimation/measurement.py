"""Friction "measurements" from motor torque and motion: torque balance and disturbance observer.

Torque balance (ABB M19-S paper eq. (1) ``tau_m = J theta_ddot + tau_f (+ tau_0)``):

    tau_f_hat = Q(s) tau_m - J s Q(s) theta_dot

``Q(s) = w^2 / (s + w)^2`` (critically damped 2nd-order low-pass, w = 1 / filter_time_constant) is
applied to both the torque and the velocity so the filtered acceleration ``s Q(s) theta_dot`` and
the torque stay aligned in phase. The filtered velocity ``Q(s) theta_dot`` is returned as well so a
regression uses the same delay. Discretised exactly (zero-order hold, matrix exponential).

Disturbance observer (Ohnishi; J dv/dt = tau - d, d = friction (+ load)):

    d_hat_dot = L (d - d_hat)  <=>  z_dot = L (tau - d_hat),  d_hat = z - L J v

i.e. a first-order low-pass of bandwidth L [rad/s] on the true disturbance, without differentiating
the velocity. Discretised with the exact ZOH of the z equation (stable for any L dt).
"""

from __future__ import annotations

import math

import numpy as np

from friction_ros.core.config import Names, prefixed
from friction_ros.core.validation import check_real

#: the names of the estimator's keys in messages by default (``estimator.inertia``)
NAMES: Names = prefixed("estimator")


class _CriticalLowPass:
    """Q(s) = w^2/(s+w)^2 in state form x = [y, y_dot]; exact ZOH discretisation cached per dt.

    Scalar arithmetic (two states): numpy's per-call overhead would dominate at 1 kHz.
    """

    def __init__(self, w: float):
        self.w = w
        self._dt = None
        self._x: tuple[float, float] | None = None

    @property
    def x(self) -> np.ndarray | None:
        return None if self._x is None else np.array(self._x)

    def _matrices(self, dt: float):
        """Exact ZOH matrices in closed form (A = [[0, 1], [-w^2, -2w]] has a double pole at -w):
        e^{Ah} = e^{-wh} [[1 + wh, h], [-w^2 h, 1 - wh]], Bd = [1 - e^{-wh}(1 + wh), w^2 h e^{-wh}]
        (the step response of w^2/(s+w)^2 and its derivative). Cached per dt."""
        if self._dt != dt:
            w, h = self.w, dt
            e = math.exp(-w * h)
            self._Ad = ((e * (1.0 + w * h), e * h), (-e * w * w * h, e * (1.0 - w * h)))
            self._Bd = (1.0 - e * (1.0 + w * h), w * w * h * e)
            self._dt = dt
        return self._Ad, self._Bd

    def reset(self, value: float | None = None) -> None:
        self._x = None if value is None else (float(value), 0.0)

    def update(self, u: float, dt: float) -> tuple[float, float]:
        if self._x is None:
            self._x = (u, 0.0)
            return u, 0.0
        ((a00, a01), (a10, a11)), (b0, b1) = self._matrices(dt)
        x0, x1 = self._x
        self._x = (a00 * x0 + a01 * x1 + b0 * u, a10 * x0 + a11 * x1 + b1 * u)
        return self._x


class TorqueBalanceEstimator:
    """tau_f_hat = Q tau_m - J d/dt(Q theta_dot); see the module docstring."""

    def __init__(self, inertia: float, filter_time_constant: float = 0.005, names: Names = NAMES):
        self.inertia = check_real(names("inertia"), inertia, 0.0, unit="kg*m^2")
        self.filter_time_constant = check_real(
            names("filter_time_constant"), filter_time_constant, 0.0, 1.0, lo_open=True, unit="s"
        )
        w = 1.0 / self.filter_time_constant
        self._qt = _CriticalLowPass(w)
        self._qv = _CriticalLowPass(w)

    def reset(self) -> None:
        self._qt.reset()
        self._qv.reset()

    def update(self, torque: float, velocity: float, dt: float) -> tuple[float, float, float]:
        """Return (friction estimate, filtered velocity, filtered acceleration)."""
        tq, _ = self._qt.update(float(torque), dt)
        vf, af = self._qv.update(float(velocity), dt)
        return tq - self.inertia * af, vf, af


class DisturbanceObserver:
    """Disturbance observer d_hat = z - L J v, z_dot = L (tau - d_hat); see the module docstring."""

    def __init__(self, inertia: float, bandwidth: float = 200.0, names: Names = NAMES):
        self.inertia = check_real(names("inertia"), inertia, 0.0, lo_open=True, unit="kg*m^2")
        self.bandwidth = check_real(names("observer_bandwidth"), bandwidth, 0.0, lo_open=True, unit="rad/s")
        self.reset()

    def reset(self) -> None:
        self.z = None
        self.d_hat = 0.0
        self._vf = None

    def update(self, torque: float, velocity: float, dt: float) -> tuple[float, float, float]:
        """Return (disturbance estimate, velocity filtered at the observer bandwidth, 0)."""
        L, J = self.bandwidth, self.inertia
        v = float(velocity)
        if self.z is None:
            self.z = L * J * v
            self._vf = v
            self._vprev = v
        # z_dot = L (tau - z + L J v): tau held, v taken at the mid-point of the period (the
        # velocity ramps over the period; holding the end value would bias d_hat by L J a dt / 2)
        target = float(torque) + L * J * 0.5 * (v + self._vprev)
        self._vprev = v
        e = math.exp(-L * dt)
        self.z = target + (self.z - target) * e
        self.d_hat = self.z - L * J * v
        # first-order filtered velocity with the same bandwidth (aligned with d_hat's lag)
        self._vf = v + (self._vf - v) * e
        return self.d_hat, self._vf, 0.0
