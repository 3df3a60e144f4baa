"""The friction model classes by name, without the asymmetric wrapper (which is built on them).

:mod:`.registry` adds :class:`~.asymmetric.Asymmetric` to this table; :mod:`.asymmetric` looks its
base models up here, so neither of the two has to import the other's importer.
"""

from __future__ import annotations

from . import dahl, gms, lugre, static, stiction
from .base import FrictionModel

#: every model an asymmetric wrapper can be built on (all models but ``asymmetric`` itself)
BASE_MODEL_CLASSES: dict[str, type[FrictionModel]] = {
    cls.name: cls
    for cls in (
        static.ZeroFriction,
        static.Coulomb,
        static.Viscous,
        static.CoulombViscous,
        static.Stribeck,
        static.Tustin,
        static.Gaussian,
        static.Lorentzian,
        static.StribeckEps,
        static.GAExponential,
        static.GATustin,
        static.GANonLinear,
        static.GADupont,
        static.GASevenParameter,
        static.Polynomial,
        static.LoadDependent,
        stiction.Karnopp,
        stiction.GKF,
        dahl.Dahl,
        lugre.LuGre,
        gms.GMS,
    )
}
