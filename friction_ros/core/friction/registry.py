"""Model registry: ``make_model``, ``model_from_config``, ``MODEL_NAMES``."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

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


def make_model(name: str, **coefficients: Any) -> FrictionModel:
    """Build a validated friction model by name (see ``MODEL_NAMES``)."""
    check_choice("friction.model", name, MODEL_NAMES)
    return MODEL_CLASSES[name](**coefficients)


def model_from_config(config: Mapping[str, Any] | FrictionModel | None) -> FrictionModel:
    """Build a model from ``{"model": name, <coefficient>: value, ...}`` (inverse of ``to_config``).

    ``None`` or an empty mapping gives the ``none`` model; a model instance is returned unchanged.
    """
    if isinstance(config, FrictionModel):
        return config
    if config is None or (isinstance(config, Mapping) and not config):
        return ZeroFriction()
    if not isinstance(config, Mapping):
        raise ParameterError(f"friction config = {config!r} must be a mapping with a 'model' key")
    if "model" not in config:
        raise ParameterError(f"friction config is missing 'model': must be one of {', '.join(MODEL_NAMES)}")
    cfg = dict(config)
    name = cfg.pop("model")
    return make_model(name, **cfg)
