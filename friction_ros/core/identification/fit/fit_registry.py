"""Lookup of the fit models by name: the built-in families (:mod:`.fit_families`, registered on
import), the classes of the ``friction_ros.fit_models`` entry points and the learned models."""

from __future__ import annotations

from importlib.metadata import entry_points

from friction_ros.core.identification.fit import fit_families  # noqa: F401 (registers the built-ins)
from friction_ros.core.identification.fit.fit_model import (
    _REGISTRY,
    ENTRY_POINT_GROUP,
    FitModel,
    register_fit_model,
)
from friction_ros.core.validation import ParameterError

#: learned (non-parametric) models, fitted by :mod:`.learned`, not by a FitModel
LEARNED = ("anfis", "nusvr")
_PLUGINS_LOADED = False


def _load_plugins() -> None:
    """Register the classes named in the ``friction_ros.fit_models`` entry-point group (once)."""
    global _PLUGINS_LOADED
    if _PLUGINS_LOADED:
        return
    _PLUGINS_LOADED = True
    for ep in entry_points(group=ENTRY_POINT_GROUP):
        obj = ep.load()
        if isinstance(obj, type) and issubclass(obj, FitModel) and obj.family not in _REGISTRY:
            register_fit_model(obj)


def model_help() -> str:
    """Every registered model name form, for messages."""
    return ", ".join(c.help or c.family for c in _REGISTRY.values())


def fit_model(name: str) -> FitModel:
    """The FitModel instance for model ``name`` (ParameterError naming the allowed ones)."""
    for attempt in range(2):
        for cls in list(_REGISTRY.values()):
            m = cls.parse(name)
            if m is not None:
                return m
        if attempt == 0:
            _load_plugins()
    raise ParameterError(
        f"model = {name!r} is not allowed: must be one of {model_help()}, {', '.join(LEARNED)}"
    )


def library_config(
    name: str, coefs: dict, *, eps: float = 0.0, per_direction: dict | None = None
) -> dict | None:
    """The library ``to_config()`` dict for a fitted model (None for learned models): the model's
    :meth:`~.fit_model.FitModel.library_config`."""
    if name in LEARNED:
        return None
    return fit_model(name).library_config(coefs, eps=eps, per_direction=per_direction)
