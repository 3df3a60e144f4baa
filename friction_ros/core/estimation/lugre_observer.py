"""LuGre friction observer (Canudas de Wit et al. 1995, IEEE TAC 40(3), eq. (12)).

``dz_hat/dt = v - sigma0 |v| z_hat / g(v) + L e``, ``F_hat = sigma0 z_hat + sigma1 dz_hat/dt + fv v``
with ``g(v) = fc + (fs - fc) exp(-|v / vs|^delta)``, the tracking error ``e = theta_d - theta`` and
the observer gain ``L >= 0`` (the correction raises the friction estimate while the joint lags the
reference). The online estimator tracks the bristle state with it (gain 0); the compensating
controller's ``observer`` source feeds its estimate back (gain ``observer_gain``).
"""

from __future__ import annotations

import math

import numpy as np

from friction_ros.core.validation import ParameterError, check_real


class LuGreObserver:
    """LuGre friction observer after Canudas de Wit et al. (1995), see the module docstring.

    The z equation is integrated exactly over a step with v and e held (it is linear in z),
    so it stays stable for stiff bristles (sigma0 ~ 1e5 N*m/rad) at 1 ms.
    """

    NEEDS = ("sigma0", "fc", "fs", "vs")

    @classmethod
    def observes(cls, model) -> bool:
        """Whether the observer can follow ``model``: one with a LuGre bristle (its coefficients)."""
        return all(k in model.coefficients for k in cls.NEEDS)

    def __init__(self, model, gain: float = 0.0):
        c = model.coefficients
        for k in self.NEEDS:
            if k not in c:
                raise ParameterError(f"LuGre observer needs a LuGre model: coefficient {k!r} missing")
        self.model = model
        self.gain = check_real("friction.observer_gain", gain, 0.0)
        self.z = 0.0
        self.zdot = 0.0

    def reset(self, z: float = 0.0) -> None:
        self.z = float(z)
        self.zdot = 0.0

    def g(self, v: float) -> float:
        c = self.model.coefficients
        return c["fc"] + (c["fs"] - c["fc"]) * math.exp(-(abs(v / c["vs"]) ** c.get("delta", 2.0)))

    def step(self, v: float, dt: float, error: float = 0.0) -> float:
        """Advance z_hat by dt with velocity v and tracking error e; return F_hat."""
        c = self.model.coefficients
        s0 = c["sigma0"]
        a = s0 * abs(v) / self.g(v)
        b = v + self.gain * error
        z0 = self.z
        if a * dt > 1e-9:
            zs = b / a
            self.z = zs + (z0 - zs) * math.exp(-a * dt)
        else:
            self.z = z0 + b * dt
        self.zdot = (self.z - z0) / dt
        s1 = c.get("sigma1", 0.0)
        vd = c.get("vd", 0.0)
        if vd > 0.0:
            s1 *= math.exp(-((v / vd) ** 2))
        return s0 * self.z + s1 * self.zdot + c.get("fv", 0.0) * v

    @property
    def state(self) -> np.ndarray:
        return np.array([self.z])
