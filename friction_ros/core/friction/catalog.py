"""The friction model classes by name, without the asymmetric wrapper (which is built on them).

:mod:`.registry` adds :class:`~.asymmetric.Asymmetric` to this table; :mod:`.asymmetric` looks its
base models up here, so neither of the two has to import the other's importer.
"""

from __future__ import annotations

from .base import FrictionModel
from .dahl import Dahl
from .gms import GMS
from .lugre import LuGre
from .static import (
    Coulomb,
    CoulombViscous,
    GADupont,
    GAExponential,
    GANonLinear,
    GASevenParameter,
    GATustin,
    Gaussian,
    LoadDependent,
    Lorentzian,
    Polynomial,
    Stribeck,
    StribeckEps,
    Tustin,
    Viscous,
    ZeroFriction,
)
from .stiction import GKF, Karnopp

#: every model an asymmetric wrapper can be built on (all models but ``asymmetric`` itself)
BASE_MODEL_CLASSES: dict[str, type[FrictionModel]] = {
    cls.name: cls
    for cls in (
        ZeroFriction,
        Coulomb,
        Viscous,
        CoulombViscous,
        Stribeck,
        Tustin,
        Gaussian,
        Lorentzian,
        StribeckEps,
        GAExponential,
        GATustin,
        GANonLinear,
        GADupont,
        GASevenParameter,
        Polynomial,
        LoadDependent,
        Karnopp,
        GKF,
        Dahl,
        LuGre,
        GMS,
    )
}
