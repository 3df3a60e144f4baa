"""Generalized Maxwell-Slip model (Al-Bender, Lampaert, Swevers 2005; ABB M19-S paper)."""

from __future__ import annotations

import math

import numpy as np

from friction_ros.core.config import Field
from friction_ros.core.validation import ParameterError

from . import _kernels
from .base import DynamicModel, stribeck_np

ALPHA_SUM_TOL = 1e-6


class GMS(DynamicModel):
    """GMS with N Maxwell-slip elements (ABB M19-S paper eqs. (2)-(3), sign fixed per ABB M19-S paper A.2.4):

    stick:  dF_i/dt = k_i v
    slip:   dF_i/dt = sgn(v) C (alpha_i - F_i / s(v)) = C (alpha_i sgn(v) - F_i / |s(v)|), C = attraction
    s(v) = Fc + (Fs - Fc) exp(-|v/vs|^delta);  F = sum_i F_i + fv v + F_damp;  sum_i alpha_i = 1.
    Optional presliding micro-damping (Lampaert et al.: F = sum_i (k_i z_i + sigma_i
    dz_i/dt) + sigma_2 v) with one coefficient ``sigma1`` shared in proportion to the element
    stiffness, sigma_i = sigma1 k_i / sum_j k_j (Rayleigh stiffness-proportional damping), i.e.
    F_damp = (sigma1 / sum_j k_j) sum_i dF_i/dt, which is sigma1 v while every element sticks and
    fades as elements slip. ``sigma1 = 0`` (default) is the undamped model of the ABB M19-S paper.
    An element slips when |F_i| reaches alpha_i s(v) and sticks again on reversal or at v = 0.
    Virgin curve y(x) = sum_i min(k_i x, alpha_i Fs); Masing rule and wiping-out follow (ABB M19-S paper E.1.7).

    Integration: sticking is exact (F_i += k_i v dt) with break-away clipped inside the step; slipping
    uses the exact exponential solution with rate C/s: stable for k_i = 1e5 at dt = 1 ms.
    Config: ``k`` and ``alpha`` are flat float lists of equal length N (ROS parameters hold no lists
    of lists). State: [F_1..F_N, stuck_1..stuck_N].
    """

    name = "gms"
    KIND = _kernels.K_GMS
    STIFFNESS = "k"
    COEFS = (
        Field(
            "fc",
            lo=0.0,
            lo_open=True,
            unit="N*m",
            doc="Coulomb level of s(v) = Fc + (Fs - Fc) exp(-|v/vs|^delta) (ABB M19-S paper eq. (3), A.2.4)",
        ),
        Field(
            "fs",
            lo=0.0,
            lo_open=True,
            unit="N*m",
            doc="static level of s(v), s(0) = Fs (ABB M19-S paper eq. (3))",
        ),
        Field(
            "vs",
            lo=0.0,
            lo_open=True,
            unit="rad/s",
            doc="Stribeck velocity of s(v) (ABB M19-S paper eq. (3))",
        ),
        Field(
            "delta", 2.0, lo=0.0, lo_open=True, doc="Stribeck exponent of s(v) [-] (ABB M19-S paper eq. (3))"
        ),
        Field(
            "attraction",
            lo=0.0,
            lo_open=True,
            unit="N*m/s",
            doc="attraction parameter C: slip dF_i/dt = C (alpha_i sgn(v) - F_i / |s(v)|) (ABB M19-S paper eq. (3))",
        ),
        Field(
            "fv",
            0.0,
            lo=0.0,
            unit="N*m*s/rad",
            doc="viscous coefficient: F = sum_i F_i + fv v (ABB M19-S paper eq. (2))",
        ),
        Field(
            "k",
            lo=0.0,
            lo_open=True,
            unit="N*m/rad",
            is_list=True,
            doc="element stiffnesses k_i: stick dF_i/dt = k_i v (ABB M19-S paper eq. (2))",
        ),
        Field(
            "alpha",
            lo=0.0,
            lo_open=True,
            hi=1.0,
            is_list=True,
            doc="element weights alpha_i [-] (sum 1): element i slips at |F_i| = alpha_i s(v) (ABB M19-S paper eq. (3))",
        ),
        # appended last so positional users of param_names / param_vector() keep their indices
        Field(
            "sigma1",
            0.0,
            lo=0.0,
            unit="N*m*s/rad",
            doc="presliding micro-damping, shared as sigma_i = sigma1 k_i / sum_j k_j (0 = none; "
            "Lampaert et al.)",
        ),
    )

    def _validate(self):
        self._require_fs_ge_fc()
        k, a = self._c["k"], self._c["alpha"]
        if len(k) != len(a):
            raise ParameterError(
                f"{self.key('alpha')} has {len(a)} elements but {self.key('k')} has {len(k)}: "
                "must have the same element count"
            )
        if abs(sum(a) - 1.0) > ALPHA_SUM_TOL:
            raise ParameterError(
                f"{self.key('alpha')} sums to {sum(a):.9g}: the element weights must sum to 1 "
                f"(+-{ALPHA_SUM_TOL:g})"
            )

    @property
    def n_elements(self) -> int:
        return len(self._c["k"])

    def _kernel_params(self):
        c = self._c
        return (
            [float(self.n_elements), c["fc"], c["fs"], c["vs"], c["delta"], c["attraction"], c["fv"]]
            + c["k"]
            + c["alpha"]
            + [c["sigma1"]]
        )

    def initial_state(self) -> np.ndarray:
        st = np.zeros(2 * len(self._c["k"]))
        st[len(self._c["k"]) :] = 1.0  # relaxed and sticking
        return st

    @property
    def element_forces(self) -> np.ndarray:
        return self._state[: self.n_elements].copy()

    def _steady(self, v):
        c = self._c
        return stribeck_np(np.abs(v), c["fc"], c["fs"], c["vs"], c["delta"]) * np.sign(v) + c["fv"] * v

    def virgin_curve(self, x):
        """Quasi-static first-loading curve y(x) = sum_i min(k_i |x|, alpha_i Fs) sgn(x) (ABB M19-S paper A.2.4)."""
        x = np.asarray(x, dtype=float)
        k = np.asarray(self._c["k"])
        a = np.asarray(self._c["alpha"]) * self._c["fs"]
        y = np.minimum(np.abs(x)[..., None] * k, a).sum(axis=-1)
        return y * np.sign(x)

    def max_stiffness(self) -> float:
        return float(sum(self._c["k"]))

    def batch_kernel_params(self, param_matrix):
        pm = np.asarray(param_matrix, dtype=float)
        n = self.n_elements
        asum = pm[:, 6 + n : 6 + 2 * n].sum(axis=1)
        bad = np.abs(asum - 1.0) > ALPHA_SUM_TOL
        if bad.any():
            r = int(np.argmax(bad))
            raise ParameterError(
                f"gms.alpha (row {r}) sums to {asum[r]:.9g}: the element weights must sum to 1"
            )
        return np.ascontiguousarray(np.hstack([np.full((pm.shape[0], 1), float(n)), pm]))

    def _simulate_batch_numpy(self, pm, v, dt):
        self.batch_kernel_params(pm)
        n = self.n_elements
        fc, fs, vs, de, attraction, fv = (pm[:, j] for j in range(6))
        k = pm[:, 6 : 6 + n]
        al = pm[:, 6 + n : 6 + 2 * n]
        sig = pm[:, 6 + 2 * n] if pm.shape[1] > 6 + 2 * n else np.zeros(pm.shape[0])
        damp = sig / k.sum(axis=1)
        f = np.zeros_like(k)
        stuck = np.ones_like(k, dtype=bool)
        out = np.empty((pm.shape[0], v.size))
        for t, vt in enumerate(v):
            s = stribeck_np(abs(vt), fc, fs, vs, de)[:, None]
            f_old = f
            if vt == 0.0:
                stuck[:] = True
            else:
                sv = math.copysign(1.0, vt)
                stuck |= f * vt < 0.0
                lim = al * s
                fst = f + k * vt * dt
                brk = stuck & (fst * sv >= lim)
                tgt = lim * sv
                fsl = tgt + (f - tgt) * np.exp(-attraction[:, None] * dt / s)
                f = np.where(stuck, np.where(brk, tgt, fst), fsl)
                stuck = stuck & ~brk
            out[:, t] = f.sum(axis=1) + fv * vt + damp * (f - f_old).sum(axis=1) / dt
        return out
