"""The base class of the reference generators (:mod:`.references`): ``sample``/``arrays`` of
position, velocity and acceleration, offset and start time; and the piecewise-linear velocity profile
the trapezoidal generators share."""

from __future__ import annotations

from abc import ABC, abstractmethod
from typing import Any

import numpy as np

from friction_ros.core.validation import (
    check_real,
)


class Reference(ABC):
    """Base class: a reference trajectory theta_d(t) with its first two derivatives."""

    kind = "base"

    def __init__(self, offset: float = 0.0, start_time: float = 0.0):
        self.offset = check_real(f"reference.{self.kind}.offset", offset, unit="rad")
        self.start_time = check_real(f"reference.{self.kind}.start_time", start_time, 0.0, unit="s")

    @abstractmethod
    def _eval(self, tau: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Return (pos - offset, vel, acc) at times tau = t - start_time >= 0."""

    def arrays(self, t) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Vectorised reference at times ``t`` (array, s): ``(pos, vel, acc)`` arrays."""
        t = np.asarray(t, dtype=float)
        tau = np.maximum(t - self.start_time, 0.0)
        p, v, a = self._eval(np.atleast_1d(tau))
        before = np.atleast_1d(t) < self.start_time
        if np.any(before):
            p = np.where(before, self._initial(), p)
            v = np.where(before, 0.0, v)
            a = np.where(before, 0.0, a)
        p = p + self.offset
        if t.ndim == 0:
            return float(p[0]), float(v[0]), float(a[0])
        return p.reshape(t.shape), v.reshape(t.shape), a.reshape(t.shape)

    def _initial(self) -> float:
        """Value (relative to offset) held before ``start_time``."""
        return float(self._eval(np.zeros(1))[0][0])

    def sample(self, t: float) -> tuple[float, float, float]:
        """Reference at one time ``t`` (s): ``(pos, vel, acc)`` floats.

        Types with a scalar form (``_scalar``) skip numpy here (the controller calls this every
        period; ~1 us instead of ~10 us); the values equal :meth:`arrays` to rounding.
        """
        t = float(t)
        if t >= self.start_time:
            r = self._scalar(t - self.start_time)
            if r is not None:
                return r[0] + self.offset, r[1], r[2]
        p, v, a = self.arrays(t)
        return float(p), float(v), float(a)

    def _scalar(self, tau: float) -> tuple[float, float, float] | None:
        """(pos - offset, vel, acc) at one tau >= 0 without numpy, or None to use :meth:`_eval`."""
        return None

    __call__ = sample

    def config(self) -> dict[str, Any]:
        """Return the config dict that rebuilds this reference."""
        return {"type": self.kind, "offset": self.offset, "start_time": self.start_time, **self._config()}

    def _config(self) -> dict[str, Any]:
        return {}


def _pwl_velocity(tk: np.ndarray, vk: np.ndarray, tau: np.ndarray):
    """Integrate a piecewise-linear velocity (knots tk, vk) exactly: position, velocity, acceleration.

    Beyond the last knot the velocity is held constant at vk[-1].
    """
    dtk = np.diff(tk)
    slopes = np.where(dtk > 0, np.diff(vk) / np.where(dtk > 0, dtk, 1.0), 0.0)
    areas = 0.5 * (vk[:-1] + vk[1:]) * dtk
    cum = np.concatenate([[0.0], np.cumsum(areas)])
    idx = np.clip(np.searchsorted(tk, tau, side="right") - 1, 0, len(tk) - 1)
    last = idx >= len(tk) - 1
    seg = np.minimum(idx, len(tk) - 2)
    s = tau - tk[seg]
    a = np.where(last, 0.0, slopes[seg])
    v0 = vk[seg]
    pos = np.where(last, cum[-1] + vk[-1] * (tau - tk[-1]), cum[seg] + v0 * s + 0.5 * a * s * s)
    vel = np.where(last, vk[-1], v0 + a * s)
    return pos, vel, a
