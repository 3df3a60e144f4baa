"""Asymmetric friction: separate parameter sets for positive and negative motion (AI friction chapter B.3)."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from friction_ros.core.config import Names, names_of
from friction_ros.core.validation import ParameterError, check_keys

from . import _kernels
from .base import DynamicModel, FrictionModel
from .catalog import BASE_MODEL_CLASSES


class Asymmetric(FrictionModel):
    """Direction-dependent wrapper around any base model (AI friction chapter: stiction 0.2279 A positive vs
    0.2120 A negative, AI friction chapter B.3, "justifies the asymmetric nature of friction").

    F(v) = F_pos(v) for v >= 0 and F_neg(v) for v < 0, where F_pos / F_neg are the base model with the
    ``positive`` / ``negative`` coefficient sets. For a dynamic base the state is shared and the set is
    chosen by the sign of the current velocity. Config:
    ``{model: asymmetric, base: <name>, positive: {...}, negative: {...}}``.
    """

    name = "asymmetric"
    KIND = _kernels.K_ASYMMETRIC

    @classmethod
    def from_section(cls, section: Any) -> Asymmetric:
        """From a typed ``friction`` section (open: ``base``, ``positive``, ``negative`` are checked
        here, the base model's coefficients by the base model)."""
        values = {k: v for k, v in section.as_dict().items() if k != "model"}
        return cls(**values, _path=section.path())

    def __init__(
        self,
        base: str = "",
        positive: Mapping[str, Any] | None = None,
        negative: Mapping[str, Any] | None = None,
        _path: str | Names = "",
    ) -> None:
        _path = names_of(_path)("")  # nested sections: named by their path
        self.path = p = _path or self.name
        if base not in BASE_MODEL_CLASSES:
            allowed = ", ".join(BASE_MODEL_CLASSES)
            raise ParameterError(f"{p}.base = {base!r} is not allowed: must be one of {allowed}")
        for key, val in (("positive", positive), ("negative", negative)):
            if not isinstance(val, Mapping):
                raise ParameterError(f"{p}.{key} = {val!r} must be a mapping of {base} coefficients")
            check_keys(
                f"{p}.{key}",
                {k: v for k, v in val.items() if k != "model"},
                [c.name for c in BASE_MODEL_CLASSES[base].COEFS],
            )
        self.base = base
        cls = BASE_MODEL_CLASSES[base]
        self.positive = cls(
            **{k: v for k, v in positive.items() if k != "model"}, _path=_path and f"{p}.positive"
        )
        self.negative = cls(
            **{k: v for k, v in negative.items() if k != "model"}, _path=_path and f"{p}.negative"
        )
        if len(self.positive.kernel_params) != len(self.negative.kernel_params):
            raise ParameterError(
                f"{p}.negative has a different element count from {p}.positive: "
                "list coefficients must have the same length in both directions"
            )
        self.is_dynamic = self.positive.is_dynamic  # type: ignore[misc]
        self.load_dependent = self.positive.load_dependent  # type: ignore[misc]
        self._c = {}
        m = len(self.positive.kernel_params)
        self._p = np.ascontiguousarray(
            np.concatenate(
                [
                    [float(self.positive.KIND), float(m)],
                    self.positive.kernel_params,
                    self.negative.kernel_params,
                ]
            )
        )
        self._state = self.initial_state()

    @property
    def coefficients(self):
        return {
            "base": self.base,
            "positive": dict(self.positive.coefficients),
            "negative": dict(self.negative.coefficients),
        }

    def to_config(self) -> dict:
        return {"model": self.name, **self.coefficients}

    @property
    def param_names(self) -> list[str]:
        return [f"positive.{n}" for n in self.positive.param_names] + [
            f"negative.{n}" for n in self.negative.param_names
        ]

    def param_vector(self) -> np.ndarray:
        return np.concatenate([self.positive.param_vector(), self.negative.param_vector()])

    def from_param_vector(self, vec):
        vec = np.asarray(vec, dtype=float)
        n = len(self.positive.param_names)
        if vec.size != 2 * n:
            raise ParameterError(f"asymmetric parameter vector has {vec.size} entries: must have {2 * n}")
        pos = self.positive.from_param_vector(vec[:n])
        neg = self.negative.from_param_vector(vec[n:])
        return Asymmetric(self.base, dict(pos.coefficients), dict(neg.coefficients))

    def with_coefficients(self, **changes):
        cfg = self.coefficients
        cfg.update(changes)
        return Asymmetric(**cfg)

    def initial_state(self) -> np.ndarray:
        return self.positive.initial_state()

    def _steady(self, v):
        return np.where(v >= 0, self.positive.steady_state(v), self.negative.steady_state(v))

    def torque(self, v, load=0.0):
        if self.is_dynamic:
            raise TypeError("asymmetric dynamic model: use step()/simulate()")
        v = np.asarray(v, dtype=float)
        out = np.where(v >= 0, self.positive.torque(v, load), self.negative.torque(v, load))
        return float(out) if out.ndim == 0 else out

    def breakaway(self, direction: float = 1.0) -> float:
        return (self.positive if direction >= 0 else self.negative).breakaway(direction)

    def max_stiffness(self) -> float:
        return max(self.positive.max_stiffness(), self.negative.max_stiffness())

    # dynamic interface (valid when the base is dynamic)
    reset = DynamicModel.reset
    state = DynamicModel.state
    step = DynamicModel.step
    simulate = DynamicModel.simulate

    def simulate_batch(self, param_matrix, v_traj, dt, **_):
        """Batch simulation; rows are ``param_vector()`` layouts (positive set then negative set)."""
        pm = np.atleast_2d(np.asarray(param_matrix, dtype=float))
        v = np.ascontiguousarray(v_traj, dtype=float).ravel()
        out = np.empty((pm.shape[0], v.size))
        for r in range(pm.shape[0]):
            mdl = self.from_param_vector(pm[r])
            out[r] = mdl.simulate(v, dt) if mdl.is_dynamic else mdl.steady_state(v)
        return out
