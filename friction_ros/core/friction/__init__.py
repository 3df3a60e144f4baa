"""Friction model library (pure core): static maps, stiction rules, Dahl, LuGre, GMS, asymmetric.

Contract (docs/architecture.md): ``make_model(name, **coefficients)`` / ``model_from_config(dict)``
return a :class:`FrictionModel`; ``model.to_config()`` round-trips; static models have vectorised
``torque(v)``; dynamic models have ``reset/state/step/simulate/simulate_batch``. Friction opposes
motion: ``steady_state(v) * v >= 0``; the plant applies ``-friction``.
"""

from .asymmetric import Asymmetric
from .base import DynamicModel, FrictionModel, StaticModel
from .dahl import Dahl
from .gms import GMS
from .lugre import LuGre
from .registry import (
    DYNAMIC_MODEL_NAMES,
    MODEL_CLASSES,
    MODEL_NAMES,
    STATIC_MODEL_NAMES,
    make_model,
    model_from_config,
)
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

__all__ = [
    "Asymmetric",
    "Coulomb",
    "CoulombViscous",
    "Dahl",
    "DynamicModel",
    "DYNAMIC_MODEL_NAMES",
    "FrictionModel",
    "GADupont",
    "GAExponential",
    "GANonLinear",
    "GASevenParameter",
    "GATustin",
    "Gaussian",
    "GKF",
    "GMS",
    "Karnopp",
    "LoadDependent",
    "Lorentzian",
    "LuGre",
    "MODEL_CLASSES",
    "MODEL_NAMES",
    "Polynomial",
    "STATIC_MODEL_NAMES",
    "StaticModel",
    "Stribeck",
    "StribeckEps",
    "Tustin",
    "Viscous",
    "ZeroFriction",
    "make_model",
    "model_from_config",
]
