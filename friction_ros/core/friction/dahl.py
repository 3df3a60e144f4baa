"""Dahl model (Dahl 1968) as written in AI friction chapter eq. (9)."""

from __future__ import annotations

import numpy as np

from friction_ros.core.config import Field

from . import _kernels
from .base import DynamicModel


class Dahl(DynamicModel):
    """Dahl: dF/dx = sigma |1 - F sgn(v)/Fc|^alpha sgn(1 - F sgn(v)/Fc) (AI friction chapter eq. (9)).

    Time form dF/dt = (dF/dx) v. The update integrates the closed-form solution over the displacement
    v*dt (exact for v held over the step, stable for any stiffness). With alpha = 1 the model is LuGre
    with Fs = Fc, sigma1 = 0, fv = 0 (Olsson et al. 1998). Steady sliding: F = Fc sgn(v). State: [F].
    """

    name = "dahl"
    KIND = _kernels.K_DAHL
    STIFFNESS = "sigma"
    STATE_NAMES = ("F",)
    COEFS = (
        Field(
            "sigma",
            lo=0.0,
            lo_open=True,
            unit="N*m/rad",
            doc="rest stiffness: dF/dx = sigma at F = 0 (AI friction chapter eq. (9))",
        ),
        Field(
            "fc",
            lo=0.0,
            lo_open=True,
            unit="N*m",
            doc="Coulomb level: F -> Fc sgn(v) (AI friction chapter eq. (9))",
        ),
        Field(
            "alpha",
            1.0,
            lo=0.0,
            lo_open=True,
            doc="shape exponent [-]: |1 - F sgn(v)/Fc|^alpha (AI friction chapter eq. (9))",
        ),
    )

    def _steady(self, v):
        return self._c["fc"] * np.sign(v)

    def max_stiffness(self) -> float:
        return self._c["sigma"]

    def _simulate_batch_numpy(self, pm, v, dt):
        sigma, fc, alpha = pm[:, 0], pm[:, 1], pm[:, 2]
        f = np.zeros(pm.shape[0])
        out = np.empty((pm.shape[0], v.size))
        one = alpha == 1.0
        lt = alpha < 1.0
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            for t, vt in enumerate(v):
                if vt != 0.0:
                    sv = np.sign(vt)
                    y = 1.0 - f * sv / fc
                    ay = np.abs(y)
                    d = sigma * abs(vt) * dt / fc
                    q = ay ** (1.0 - alpha) - (1.0 - alpha) * d
                    ay_lt = np.where(q > 0, np.abs(q) ** (1.0 / (1.0 - alpha)), 0.0)
                    ay_gt = (ay ** (1.0 - alpha) + (alpha - 1.0) * d) ** (-1.0 / (alpha - 1.0))
                    ayn = np.where(one, ay * np.exp(-d), np.where(lt, ay_lt, ay_gt))
                    ayn = np.where(ay == 0.0, 0.0, ayn)
                    f = fc * sv * (1.0 - np.where(y > 0, ayn, -ayn))
                out[:, t] = f
        return out
