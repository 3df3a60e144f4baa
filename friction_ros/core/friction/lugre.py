"""LuGre model (Canudas de Wit, Olsson, Astrom, Lischinsky 1995, IEEE Trans. Automatic Control 40(3))."""

from __future__ import annotations

import numpy as np

from friction_ros.core.config import Field

from . import _kernels
from .base import DynamicModel, stribeck_np


class LuGre(DynamicModel):
    """LuGre (AI friction chapter eqs. (10)-(11); GA friction thesis 2002 eq. (14); Canudas de Wit et al. 1995):

    dz/dt = v - sigma0 |v| z / g(v),  g(v) = Fc + (Fs - Fc) exp(-|v/vs|^delta)
    F = sigma0 z + sigma1(v) dz/dt + fv v,  sigma1(v) = sigma1 exp(-(v/vd)^2) if vd > 0 else sigma1
    (velocity-dependent micro-damping, Canudas de Wit 1995). Steady sliding F = g(v) sgn(v) + fv v;
    presliding stiffness dF/dx -> sigma0 (+ sigma1 term) near zero displacement.

    Integration: for v held over a step the z equation is linear, so it is solved exactly
    (z -> z_ss + (z - z_ss) exp(-a dt), a = sigma0 |v| / g): stable for sigma0 = 1e5 N*m/rad at 1 ms.
    State: [z] (rad).
    """

    name = "lugre"
    KIND = _kernels.K_LUGRE
    STIFFNESS = "sigma0"
    STATE_NAMES = ("z",)
    COEFS = (
        Field(
            "sigma0",
            lo=0.0,
            lo_open=True,
            unit="N*m/rad",
            doc="bristle stiffness: sigma0 z in F and sigma0 |v| z / g(v) in dz/dt (AI friction chapter eqs. (10)-(11))",
        ),
        Field(
            "sigma1",
            0.0,
            lo=0.0,
            unit="N*m*s/rad",
            doc="bristle micro-damping: sigma1 dz/dt in F (AI friction chapter eq. (11))",
        ),
        Field(
            "fv",
            0.0,
            lo=0.0,
            unit="N*m*s/rad",
            doc="viscous coefficient (the papers' sigma2): fv v in F (AI friction chapter eq. (11))",
        ),
        Field(
            "fc",
            lo=0.0,
            lo_open=True,
            unit="N*m",
            doc="Coulomb level of g(v) = Fc + (Fs - Fc) exp(-|v/vs|^delta) (AI friction chapter eq. (10))",
        ),
        Field(
            "fs",
            lo=0.0,
            lo_open=True,
            unit="N*m",
            doc="static level of g(v), g(0) = Fs (AI friction chapter eq. (10))",
        ),
        Field(
            "vs",
            lo=0.0,
            lo_open=True,
            unit="rad/s",
            doc="Stribeck velocity of g(v) (AI friction chapter eq. (10))",
        ),
        Field(
            "delta",
            2.0,
            lo=0.0,
            lo_open=True,
            doc="Stribeck exponent of g(v) [-] (AI friction chapter eq. (10))",
        ),
        Field(
            "vd",
            0.0,
            lo=0.0,
            unit="rad/s",
            doc="micro-damping decay velocity: sigma1(v) = sigma1 exp(-(v/vd)^2), 0: constant sigma1 "
            "(Canudas de Wit et al. 1995)",
        ),
    )

    def _validate(self):
        self._require_fs_ge_fc()

    def _steady(self, v):
        c = self._c
        return stribeck_np(np.abs(v), c["fc"], c["fs"], c["vs"], c["delta"]) * np.sign(v) + c["fv"] * v

    def max_stiffness(self) -> float:
        return self._c["sigma0"]

    def _simulate_batch_numpy(self, pm, v, dt):
        s0, s1, fv, fc, fs, vs, de, vd = (pm[:, j][:, None] for j in range(8))
        vv = v[None, :]
        av = np.abs(vv)
        g = stribeck_np(av, fc, fs, vs, de)
        a = s0 * av / g
        ah = a * dt
        small = ah < 1e-9
        with np.errstate(divide="ignore", invalid="ignore"):
            e = np.where(small, 1.0 - ah, np.exp(-ah))
            b = np.where(small, vv * dt, (vv / np.where(small, 1.0, a)) * (1.0 - e))
        # z_{t+1} = e_t z_t + b_t (time-varying linear recurrence, vectorised over parameter sets)
        z = np.zeros(pm.shape[0])
        zs = np.empty_like(e)
        for t in range(v.size):
            z = e[:, t] * z + b[:, t]
            zs[:, t] = z
        s1v = np.where(vd > 0, s1 * np.exp(-((vv / np.where(vd > 0, vd, 1.0)) ** 2)), s1)
        zdot = vv - a * zs
        return s0 * zs + s1v * zdot + fv * vv
