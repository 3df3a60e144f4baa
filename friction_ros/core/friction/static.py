"""Static (memoryless) friction maps, vectorised over velocity arrays.

Every map is odd in v unless stated (sgn(0) = 0, AI friction chapter eq. (6)) and returns the torque that
opposes motion (``F * v >= 0``).
"""

from __future__ import annotations

import numpy as np

from friction_ros.core.config import Field
from friction_ros.core.validation import ParameterError

from . import _kernels
from .base import StaticModel, sign, stribeck_np

# The coefficients the static maps share; each model's docstring gives the equation it uses them in.
_FC = Field(
    "fc",
    lo=0.0,
    unit="N*m",
    doc="Coulomb (kinetic) friction level Fc: F = Fc sgn(v) (AI friction chapter eq. (1)), the high-speed "
    "level of the Stribeck curve s(v) = Fc + (Fs - Fc) exp(-|v/vs|^delta) (AI friction chapter eq. (5))",
)
_FS = Field(
    "fs",
    lo=0.0,
    unit="N*m",
    doc="static friction (stiction) level Fs: s(0) = Fs in the Stribeck curve (AI friction chapter eq. (5))",
)
_VS = Field(
    "vs",
    lo=0.0,
    lo_open=True,
    unit="rad/s",
    doc="Stribeck velocity vs: exp(-|v/vs|^delta) in the Stribeck curve (AI friction chapter eq. (5))",
)
_DELTA = Field(
    "delta",
    2.0,
    lo=0.0,
    lo_open=True,
    doc="Stribeck shape exponent delta [-]: exp(-|v/vs|^delta) (AI friction chapter eq. (5); 1 Tustin, 2 Gaussian)",
)
_FV = Field(
    "fv",
    0.0,
    lo=0.0,
    unit="N*m*s/rad",
    doc="viscous coefficient Fv: the term Fv v (AI friction chapter eqs. (2), (3), (5))",
)


class ZeroFriction(StaticModel):
    """No friction: F = 0."""

    name = "none"
    KIND = _kernels.K_NONE

    def _steady(self, v):
        return np.zeros_like(v)


class Coulomb(StaticModel):
    """Coulomb friction F = Fc sgn(v) (AI friction chapter eq. (1); Tilakaratna et al. 2004 eq. (3); GA friction thesis 2002 eq. (2))."""

    name = "coulomb"
    KIND = _kernels.K_COULOMB
    COEFS = (_FC,)

    def _steady(self, v):
        return self._c["fc"] * sign(v)


class Viscous(StaticModel):
    """Viscous friction F = Fv v (AI friction chapter eq. (2); GA friction thesis 2002 eq. (3))."""

    name = "viscous"
    KIND = _kernels.K_VISCOUS
    COEFS = (
        Field(
            "fv",
            lo=0.0,
            unit="N*m*s/rad",
            doc="viscous coefficient Fv: F = Fv v (AI friction chapter eq. (2))",
        ),
    )

    def _steady(self, v):
        return self._c["fv"] * v


class CoulombViscous(StaticModel):
    """Coulomb + viscous F = Fc sgn(v) + Fv v (AI friction chapter eq. (3); Tilakaratna et al. 2004 eq. (1) with C_r)."""

    name = "coulomb_viscous"
    KIND = _kernels.K_COULOMB_VISCOUS
    COEFS = (
        _FC,
        Field(
            "fv",
            lo=0.0,
            unit="N*m*s/rad",
            doc="viscous coefficient Fv: F = Fc sgn(v) + Fv v (AI friction chapter eq. (3))",
        ),
    )

    def _steady(self, v):
        return self._c["fc"] * sign(v) + self._c["fv"] * v


class Stribeck(StaticModel):
    """Exponential Stribeck family F = [Fc + (Fs - Fc) exp(-|v/vs|^delta)] sgn(v) + Fv v.

    AI friction chapter eq. (5) (delta = 1: Tustin, delta = 2: Gaussian); the standard form reviewed by Olsson et al. 1998.
    Requires Fs >= Fc.
    """

    name = "stribeck"
    KIND = _kernels.K_STRIBECK
    COEFS = (_FC, _FS, _VS, _DELTA, _FV)

    def _validate(self):
        self._require_fs_ge_fc()

    def _steady(self, v):
        c = self._c
        return stribeck_np(abs(v), c["fc"], c["fs"], c["vs"], c["delta"]) * sign(v) + c["fv"] * v


class Tustin(Stribeck):
    """Tustin model: the Stribeck family with delta = 1 (AI friction chapter eq. (5))."""

    name = "tustin"
    COEFS = (_FC, _FS, _VS, _FV)

    def _kernel_params(self):
        c = self._c
        return [c["fc"], c["fs"], c["vs"], 1.0, c["fv"]]

    def _steady(self, v):
        c = self._c
        return stribeck_np(abs(v), c["fc"], c["fs"], c["vs"], 1.0) * sign(v) + c["fv"] * v


class Gaussian(Tustin):
    """Gaussian Stribeck model: the Stribeck family with delta = 2 (AI friction chapter eq. (5))."""

    name = "gaussian"

    def _kernel_params(self):
        c = self._c
        return [c["fc"], c["fs"], c["vs"], 2.0, c["fv"]]

    def _steady(self, v):
        c = self._c
        return stribeck_np(abs(v), c["fc"], c["fs"], c["vs"], 2.0) * sign(v) + c["fv"] * v


class Lorentzian(StaticModel):
    """Lorentzian (Hess & Soom) F = [Fc + (Fs - Fc) / (1 + (v/vs)^2)] sgn(v) + Fv v (AI friction chapter eq. (7))."""

    name = "lorentzian"
    KIND = _kernels.K_LORENTZIAN
    COEFS = (_FC, _FS, _VS, _FV)

    def _validate(self):
        self._require_fs_ge_fc()

    def _steady(self, v):
        c = self._c
        return (c["fc"] + (c["fs"] - c["fc"]) / (1.0 + (v / c["vs"]) ** 2)) * sign(v) + c["fv"] * v


class StribeckEps(StaticModel):
    """ABB M19-S paper Stribeck with a linear zone of width eps (ABB M19-S paper A.2.2, corrected reading).

    s(v) = Fc + (Fs - Fc) exp(-|v/vs|^delta);
    F = s(v) sgn(v) + Fv v for |v| > eps, F = (v/eps) s(v) + Fv v for |v| <= eps
    (continuous at |v| = eps, F(0) = 0, odd).
    """

    name = "stribeck_eps"
    KIND = _kernels.K_STRIBECK_EPS
    COEFS = (
        *Stribeck.COEFS,
        Field(
            "eps",
            lo=0.0,
            lo_open=True,
            unit="rad/s",
            doc="linear-zone half width: F = (v/eps) s(v) + Fv v for |v| <= eps (ABB M19-S paper A.2.2)",
        ),
    )

    def _validate(self):
        self._require_fs_ge_fc()

    def _steady(self, v):
        c = self._c
        av = np.abs(v)
        s = stribeck_np(av, c["fc"], c["fs"], c["vs"], c["delta"])
        return np.where(av > c["eps"], s * np.sign(v), v / c["eps"] * s) + c["fv"] * v


class GAExponential(StaticModel):
    """GA friction thesis 2002 modified Exponential model, eq. (21) (the model the GA selected):

    F = (Fc + (Fs - Fc) exp(-(gamma |v|)^delta) + sigma |v|) sgn(v); Fs = F_ST, Fc = F_kmin (Table 5.2).
    """

    name = "ga_exponential"
    KIND = _kernels.K_GA_EXPONENTIAL
    COEFS = (
        Field(
            "fs", lo=0.0, unit="N*m", doc="static level F_ST (GA friction thesis 2002 eq. (21), Table 5.2)"
        ),
        Field(
            "gamma",
            lo=0.0,
            lo_open=True,
            unit="s/rad",
            doc="inverse Stribeck velocity: exp(-(gamma |v|)^delta) (GA friction thesis 2002 eq. (21))",
        ),
        Field(
            "delta",
            lo=0.0,
            lo_open=True,
            doc="shape exponent [-]: exp(-(gamma |v|)^delta) (GA friction thesis 2002 eq. (21))",
        ),
        Field(
            "fc",
            lo=0.0,
            unit="N*m",
            doc="minimum kinetic level F_kmin (GA friction thesis 2002 eq. (21), Table 5.2)",
        ),
        Field(
            "sigma",
            lo=0.0,
            unit="N*m*s/rad",
            doc="viscous coefficient: sigma |v| (GA friction thesis 2002 eq. (21))",
        ),
    )

    def _steady(self, v):
        c = self._c
        av = np.abs(v)
        return (
            c["fc"] + (c["fs"] - c["fc"]) * np.exp(-((c["gamma"] * av) ** c["delta"])) + c["sigma"] * av
        ) * np.sign(v)


class GATustin(StaticModel):
    """GA friction thesis 2002 modified Tustin model, eq. (22): F = (Ff0 - Ffc [1 - exp(-(|v|/Vc)^x)] + sigma |v|) sgn(v)."""

    name = "ga_tustin"
    KIND = _kernels.K_GA_TUSTIN
    COEFS = (
        Field(
            "ff0", lo=0.0, unit="N*m", doc="static friction constant Ff0 (GA friction thesis 2002 eq. (22))"
        ),
        Field(
            "ffc",
            lo=0.0,
            unit="N*m",
            doc="static minus dynamic friction Ffc (GA friction thesis 2002 eq. (22))",
        ),
        Field(
            "vc",
            lo=0.0,
            lo_open=True,
            unit="rad/s",
            doc="threshold velocity Vc: 1 - exp(-(|v|/Vc)^x) (GA friction thesis 2002 eq. (22))",
        ),
        Field(
            "x",
            lo=0.0,
            lo_open=True,
            doc="Armstrong exponent [-]: (|v|/Vc)^x (GA friction thesis 2002 eq. (22))",
        ),
        Field(
            "sigma",
            lo=0.0,
            unit="N*m*s/rad",
            doc="viscous coefficient: sigma |v| (GA friction thesis 2002 eq. (22))",
        ),
    )

    def _steady(self, v):
        c = self._c
        av = np.abs(v)
        return (
            c["ff0"] - c["ffc"] * (1.0 - np.exp(-((av / c["vc"]) ** c["x"]))) + c["sigma"] * av
        ) * np.sign(v)


class GANonLinear(StaticModel):
    """GA friction thesis 2002 Non-Linear model (Canudas de Wit), eq. (23):

    F = (alpha0 + alpha1 exp(-beta1 |v|) + alpha2 (1 - exp(-beta2 |v|))) sgn(v).
    """

    name = "ga_nonlinear"
    KIND = _kernels.K_GA_NONLINEAR
    COEFS = (
        Field("alpha0", lo=0.0, unit="N*m", doc="constant level alpha0 (GA friction thesis 2002 eq. (23))"),
        Field(
            "alpha1",
            lo=0.0,
            unit="N*m",
            doc="decaying level: alpha1 exp(-beta1 |v|) (GA friction thesis 2002 eq. (23))",
        ),
        Field(
            "alpha2",
            lo=0.0,
            unit="N*m",
            doc="rising level: alpha2 (1 - exp(-beta2 |v|)) (GA friction thesis 2002 eq. (23))",
        ),
        Field(
            "beta1",
            lo=0.0,
            unit="s/rad",
            doc="decay rate of the alpha1 term (GA friction thesis 2002 eq. (23))",
        ),
        Field(
            "beta2",
            lo=0.0,
            unit="s/rad",
            doc="rise rate of the alpha2 term (GA friction thesis 2002 eq. (23))",
        ),
    )

    def _steady(self, v):
        c = self._c
        av = np.abs(v)
        return (
            c["alpha0"]
            + c["alpha1"] * np.exp(-c["beta1"] * av)
            + c["alpha2"] * (1.0 - np.exp(-c["beta2"] * av))
        ) * np.sign(v)


class GADupont(StaticModel):
    """GA friction thesis 2002 Dupont model, eq. (24): F = (c0 + c1 |v| + c2 exp(-(|v|/c3)^c4)) sgn(v)."""

    name = "ga_dupont"
    KIND = _kernels.K_GA_DUPONT
    COEFS = (
        Field("c0", lo=0.0, unit="N*m", doc="constant level c0 (GA friction thesis 2002 eq. (24))"),
        Field("c1", lo=0.0, unit="N*m*s/rad", doc="viscous term c1 |v| (GA friction thesis 2002 eq. (24))"),
        Field(
            "c2",
            lo=0.0,
            unit="N*m",
            doc="Stribeck level: c2 exp(-(|v|/c3)^c4) (GA friction thesis 2002 eq. (24))",
        ),
        Field(
            "c3",
            lo=0.0,
            lo_open=True,
            unit="rad/s",
            doc="Stribeck velocity c3 (GA friction thesis 2002 eq. (24))",
        ),
        Field("c4", lo=0.0, lo_open=True, doc="Stribeck exponent c4 [-] (GA friction thesis 2002 eq. (24))"),
    )

    def _steady(self, v):
        c = self._c
        av = np.abs(v)
        return (c["c0"] + c["c1"] * av + c["c2"] * np.exp(-((av / c["c3"]) ** c["c4"]))) * np.sign(v)


class GASevenParameter(StaticModel):
    """GA friction thesis 2002 reduced seven-parameter model, eq. (25), steady-sliding part with sgn(v) restored:

    F = (Fc + Fv |v| + Fs / (1 + (v/vs)^2)) sgn(v). The dwell-time rise F_SF(gamma, t2) and the
    frictional-lag delay tau_L are not modelled: Fs is F_SF after a long dwell (F_s,inf).
    """

    name = "ga_seven_parameter"
    KIND = _kernels.K_GA_SEVEN
    COEFS = (
        Field("fc", lo=0.0, unit="N*m", doc="Coulomb level Fc (GA friction thesis 2002 eq. (25))"),
        Field(
            "fv",
            lo=0.0,
            unit="N*m*s/rad",
            doc="viscous coefficient: Fv |v| (GA friction thesis 2002 eq. (25))",
        ),
        Field(
            "fs",
            lo=0.0,
            unit="N*m",
            doc="Stribeck magnitude F_s,inf, added to fc at rest: Fs / (1 + (v/vs)^2) (GA friction thesis 2002 eq. (25))",
        ),
        Field(
            "vs",
            lo=0.0,
            lo_open=True,
            unit="rad/s",
            doc="Stribeck velocity: (v/vs)^2 (GA friction thesis 2002 eq. (25))",
        ),
    )

    def _steady(self, v):
        c = self._c
        return (c["fc"] + c["fv"] * np.abs(v) + c["fs"] / (1.0 + (v / c["vs"]) ** 2)) * np.sign(v)


class Polynomial(StaticModel):
    """Per-direction polynomial (AI friction chapter eq. (8), fitted separately for each direction):

    F = sum_j pos[j] v^j for v > 0; F = -sum_j neg[j] |v|^j for v < 0; F(0) = 0.
    ``pos``/``neg`` are flat lists c0..cn (same length); AI friction chapter uses c1 = 0 and degree 8.
    """

    name = "polynomial"
    KIND = _kernels.K_POLYNOMIAL
    COEFS = (
        Field(
            "pos",
            lo=None,
            unit="N*m",
            is_list=True,
            doc="coefficients c0..cn of F = sum_j c_j v^j for v > 0 (c_j in N*m*(s/rad)^j; AI friction chapter eq. (8))",
        ),
        Field(
            "neg",
            lo=None,
            unit="N*m",
            is_list=True,
            doc="coefficients c0..cn of |F| = sum_j c_j |v|^j for v < 0 (as pos; AI friction chapter eq. (8))",
        ),
    )

    def _validate(self):
        if len(self._c["pos"]) != len(self._c["neg"]):
            raise ParameterError(
                f"{self.key('neg')} has {len(self._c['neg'])} elements but {self.key('pos')} has "
                f"{len(self._c['pos'])}: must have the same element count"
            )

    def _kernel_params(self):
        return [float(len(self._c["pos"]))] + self._c["pos"] + self._c["neg"]

    def _steady(self, v):
        av = np.abs(v)
        pp = np.polynomial.polynomial.polyval(av, self._c["pos"])
        pn = np.polynomial.polynomial.polyval(av, self._c["neg"])
        return np.where(v > 0, pp, np.where(v < 0, -pn, 0.0))


class LoadDependent(StaticModel):
    """Load-dependent gearbox friction: F = v/(veps + |v|) (fc + fl |tau_load|) + fv v.

    Friction budget grows with the transmitted torque (anchors: TMotorCANControl a3 + a4 |i| and BAM
    M3-M6). ``veps`` = 0 gives a hard sgn(v). ``load`` is the transmitted torque [N*m].
    """

    name = "load_dependent"
    KIND = _kernels.K_LOAD_DEPENDENT
    load_dependent = True
    COEFS = (
        _FC,
        Field(
            "fl",
            0.0,
            lo=0.0,
            doc="friction per unit transmitted torque [-]: (fc + fl |tau_load|) (anchors 3.1, BAM M3-M6)",
        ),
        _FV,
        Field(
            "veps",
            0.0,
            lo=0.0,
            unit="rad/s",
            doc="smoothing velocity of the sign: v / (veps + |v|) (anchors 3.1)",
        ),
    )

    def _steady(self, v, load=0.0):
        c = self._c
        mag = c["fc"] + c["fl"] * np.abs(load)
        sg = np.sign(v) if c["veps"] == 0.0 else v / (c["veps"] + np.abs(v))
        return sg * mag + c["fv"] * v

    def torque(self, v, load=0.0):
        arr = np.asarray(v, dtype=float)
        out = self._steady(np.atleast_1d(arr), np.asarray(load, dtype=float))
        return float(np.ravel(out)[0]) if arr.ndim == 0 and np.ndim(load) == 0 else out
