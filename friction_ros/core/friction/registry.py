"""Model registry: ``make_model``, ``model_from_config``, ``MODEL_NAMES``, ``register_model``."""

from __future__ import annotations

import copy
from collections.abc import Mapping
from typing import Any

from friction_ros.core.config import Names, names_of
from friction_ros.core.validation import ParameterError, check_choice

from .asymmetric import Asymmetric
from .base import FrictionModel
from .catalog import BASE_MODEL_CLASSES
from .static import ZeroFriction

MODEL_CLASSES: dict[str, type[FrictionModel]] = {**BASE_MODEL_CLASSES, Asymmetric.name: Asymmetric}

#: every model name accepted by :func:`make_model`
MODEL_NAMES: tuple[str, ...] = tuple(MODEL_CLASSES)
STATIC_MODEL_NAMES = tuple(n for n, c in MODEL_CLASSES.items() if not c.is_dynamic and n != "asymmetric")
DYNAMIC_MODEL_NAMES = tuple(n for n, c in MODEL_CLASSES.items() if c.is_dynamic)


def register_model(cls: type[FrictionModel]) -> type[FrictionModel]:
    """Add a model class defined outside the package (a :class:`~.base.StaticModel` or
    :class:`~.base.DynamicModel` subclass with ``name`` and ``COEFS``) to the registry:
    :func:`make_model`, :func:`model_from_config`, the ``asymmetric`` wrapper, the controller and
    the plant find it by name (usable as a decorator). ``MODEL_NAMES`` stays the built-in list."""
    if not (isinstance(cls, type) and issubclass(cls, FrictionModel)) or cls.name in ("", "base"):
        raise ParameterError(f"friction model {cls!r} must be a FrictionModel subclass with a name")
    if cls.is_dynamic and cls.KIND == FrictionModel.KIND:
        raise ParameterError(f"friction model {cls.name!r} is dynamic without a compiled kernel (KIND)")
    MODEL_CLASSES[cls.name] = BASE_MODEL_CLASSES[cls.name] = cls
    return cls


def make_model(name: str, _path: str | Names = "", **coefficients: Any) -> FrictionModel:
    """Build a validated friction model by name (see ``MODEL_NAMES`` and :func:`register_model`);
    messages name its coefficients ``<_path>.<coefficient>`` (default: the model's name), or
    ``_path(<coefficient>)`` for a :data:`~friction_ros.core.config.Names`."""
    check_choice(names_of(_path or "friction")("model"), name, list(MODEL_CLASSES))
    return MODEL_CLASSES[name](**coefficients, **({"_path": _path} if _path else {}))


def model_from_config(
    config: Mapping[str, Any] | FrictionModel | None, path: str | Names = ""
) -> FrictionModel:
    """Build a model from ``{"model": name, <coefficient>: value, ...}`` (inverse of ``to_config``).

    ``None`` or an empty mapping gives the ``none`` model; a model instance is returned unchanged.
    ``path``: the parameter name of the model's section in messages (default: the model's name), or
    the :data:`~friction_ros.core.config.Names` of its keys.
    """
    if isinstance(config, FrictionModel):
        return config
    if config is None or (isinstance(config, Mapping) and not config):
        return ZeroFriction()
    if not isinstance(config, Mapping):
        raise ParameterError(f"friction config = {config!r} must be a mapping with a 'model' key")
    if "model" not in config:
        raise ParameterError(f"friction config is missing 'model': must be one of {', '.join(MODEL_CLASSES)}")
    cfg = dict(config)
    name = cfg.pop("model")
    return make_model(name, path, **cfg)


def build_model(model: Any, name: str = "friction.model", path: str = ""):
    """Return a fresh library model from a model config dict or a model instance (None -> None);
    ``path`` as in :func:`model_from_config`."""
    if model is None:
        return None
    if isinstance(model, FrictionModel):  # validated already: a copy from its initial state
        fresh = copy.deepcopy(model)
        fresh._state = fresh.initial_state()
        return fresh
    if hasattr(model, "to_config"):
        return model_from_config(model.to_config())
    if not isinstance(model, Mapping):
        raise ParameterError(f"{name} = {model!r} must be a model config dict with a 'model' key")
    if not model or model.get("model") in (None, "", "none"):
        return None
    return model_from_config(dict(model), path)


def model_from_section(section: Any) -> FrictionModel | None:
    """The model of a typed ``friction`` section (``model`` + its coefficients, typed against the
    model's fields: :func:`~friction_ros.core.control.controller_config.friction_schema`); None for
    ``none``."""
    name = section.model
    return None if name in ("", "none") else MODEL_CLASSES[name].from_section(section)
