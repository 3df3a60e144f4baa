"""Friction model library (pure core): static maps, stiction rules, Dahl, LuGre, GMS, asymmetric.

Contract (docs/architecture.md): ``make_model(name, **coefficients)`` / ``model_from_config(dict)``
return a :class:`FrictionModel`; ``model.to_config()`` round-trips; static models have vectorised
``torque(v)``; dynamic models have ``reset/state/step/simulate/simulate_batch``. Friction opposes
motion: ``steady_state(v) * v >= 0``; the plant applies ``-friction``.

The names below are loaded on first use (PEP 562): importing a light module of the package
(``joint_load``, ``learned_residual``: the controller's schemas) does not load the models and their
compiled kernels.
"""

from importlib import import_module

#: exported name -> the module that defines it
_EXPORTS = {
    "Asymmetric": "asymmetric",
    "DynamicModel": "base",
    "FrictionModel": "base",
    "StaticModel": "base",
    "Dahl": "dahl",
    "GMS": "gms",
    "LuGre": "lugre",
    "DYNAMIC_MODEL_NAMES": "registry",
    "MODEL_CLASSES": "registry",
    "MODEL_NAMES": "registry",
    "build_model": "registry",
    "STATIC_MODEL_NAMES": "registry",
    "make_model": "registry",
    "model_from_config": "registry",
    "register_model": "registry",
    "Coulomb": "static",
    "CoulombViscous": "static",
    "GADupont": "static",
    "GAExponential": "static",
    "GANonLinear": "static",
    "GASevenParameter": "static",
    "GATustin": "static",
    "Gaussian": "static",
    "LoadDependent": "static",
    "Lorentzian": "static",
    "Polynomial": "static",
    "Stribeck": "static",
    "StribeckEps": "static",
    "Tustin": "static",
    "Viscous": "static",
    "ZeroFriction": "static",
    "GKF": "stiction",
    "Karnopp": "stiction",
}

__all__ = sorted(_EXPORTS)


def __getattr__(name: str):
    module = _EXPORTS.get(name)
    if module is None:
        try:  # a submodule reached as an attribute (friction_ros.core.friction.static)
            return import_module(f"{__name__}.{name}")
        except ModuleNotFoundError as exc:
            if exc.name != f"{__name__}.{name}":
                raise  # a submodule that exists but cannot import: say so
            raise AttributeError(f"module {__name__!r} has no attribute {name!r}") from None
    value = getattr(import_module(f"{__name__}.{module}"), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_EXPORTS))
