"""The fit-model plugin: what one friction model family owns for identification, and the registry.

A :class:`FitModel` describes one fittable family (``coulomb``, ``stribeck``, ``lugre``, ``gms<N>``
... or a model defined outside the package, see docs/architecture.md "Adding a friction model").
Every family predicts the friction as (ABB M19-S paper A.3, eq. 1)

    F_hat(v trajectory) = sum_j beta_j phi_j(v; theta) + fv v

with a few nonlinear coefficients ``theta`` (declared as :class:`Coef`: unit-scale bounds, log
search, power of the data's velocity scale) searched globally, and linear ones ``beta`` (named in
``linear``; ``fv`` appended when ``viscous``) solved exactly per candidate. A family implements

* :meth:`FitModel.features` ``(theta, v, dt, eps) -> phi`` (n x len(linear)); optionally a fast
  :meth:`FitModel.grams` for a whole population (the generic Gram loop is used otherwise);
* :meth:`FitModel.coefficients` ``(theta, lin, fv) -> {name: value}`` (physical, SI);
* :meth:`FitModel.library_config` ``(c, eps, per_direction) -> config`` (the friction library's
  ``to_config()`` form: export, parameter file, controller);
* :meth:`FitModel.steady_state` ``(c, v, eps)`` (report and comparison curves);
* optionally :meth:`FitModel.steady_state_constraints` (two-stage fits), ``nested`` (the simpler
  model whose plateau fit seeds it), :meth:`FitModel.warm_start`, ``plateau_shape`` (fitted to
  constant-velocity plateaus by :mod:`static_fit` when the log has them).

Registry: :func:`register_fit_model` (a class), looked up by name with :func:`fit_model` (each
registered class's :meth:`FitModel.parse`). Classes named in the ``friction_ros.fit_models``
entry-point group of an installed distribution are registered on the first lookup that misses.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from friction_ros.core.validation import ParameterError


def mid_velocity(v: np.ndarray) -> np.ndarray:
    """Velocity averaged over each sample interval, (v[k-1] + v[k]) / 2.

    A dynamic model's state update from t[k-1] to t[k] holds the velocity constant; with a measured
    (continuous) velocity the interval mean is second-order accurate, whereas holding v[k] makes
    the state lead by dt/2 and biases the damping estimate by about sigma0 dt / 2. Used for every
    dynamic family (Dahl, LuGre, GMS): on the ABB M19-S plant the GMS-4 truth driven by v[k] misses
    the plant's friction by 0.031 N*m RMS, driven by the interval mean by 0.007 N*m.
    """
    v = np.ascontiguousarray(v, dtype=float)
    return np.concatenate([v[:1], 0.5 * (v[1:] + v[:-1])])


def sat_sign(v: np.ndarray, eps: float) -> np.ndarray:
    """sgn(v) with a linear zone of width eps (ABB M19-S paper A.2.1): clip(v / eps, -1, 1)."""
    return np.clip(np.asarray(v, dtype=float) / eps, -1.0, 1.0)


@dataclass(frozen=True)
class Coef:
    """One nonlinear coefficient: search bounds of a unit-scale joint, log10 search, and the power
    of the data's velocity scale in its unit (a velocity or a distance 1, an inverse distance -1):
    the bounds of a log in other units are ``[lo, hi] * velocity_scale**power``."""

    name: str
    lo: float
    hi: float
    log: bool = False
    power: int = 0


class FitModel:
    """One fittable friction family (see the module docstring). Instances are immutable per name
    (``gms4`` and ``gms4d`` are two instances of the GMS family)."""

    #: family name (several model names may share it: gms1 ... gms20)
    family: ClassVar[str] = ""
    #: how the model names are written in help texts ("gms<N>" ...)
    help: ClassVar[str] = ""
    dynamic: ClassVar[bool] = False
    #: fv v is a column of the design (the viscous coefficient ``fv`` is fitted)
    viscous: ClassVar[bool] = True
    #: the simpler model nested in this one whose plateau fit (the measured steady-state curve)
    #: starts the search and, with ``two_stage``, is held while the rest is fitted; None = none
    nested: ClassVar[str | None] = None
    two_stage: ClassVar[bool] = False
    #: a static shape :mod:`static_fit` fits to plateau means (coulomb, coulomb_viscous, stribeck)
    plateau_shape: ClassVar[str | None] = None
    #: drive the states with the narrow-window, low-passed signals (presliding ringing, GMS)
    narrow_signals: ClassVar[bool] = False

    def __init__(self, name: str | None = None) -> None:
        self.name = name or self.family

    # ------------------------------------------------------------------ naming
    @classmethod
    def parse(cls, name: str) -> FitModel | None:
        """The instance for model ``name`` or None when the name is not this family's."""
        return cls() if name == cls.family else None

    def nonlinear(self) -> list[Coef]:
        """The nonlinear coefficients theta, in order."""
        return []

    def linear(self) -> list[str]:
        """Names of the model's own linear coefficients (``fv`` and ``J`` are appended)."""
        raise NotImplementedError

    # ------------------------------------------------------------------ regressors
    def features(self, theta: np.ndarray, v: np.ndarray, dt: float, eps: float) -> np.ndarray:
        """Regressor columns phi (n x len(linear)) for one theta; ``v`` is already the state
        velocity of a dynamic model (interval means); ``eps``: the linear zone of sgn(v)."""
        raise NotImplementedError

    def grams(self, P, v, E, dt, sos) -> np.ndarray | None:
        """Gram matrices of L [phi, E] for every row of P (a compiled batch), or None to let
        :meth:`FitSpec.grams` loop over :meth:`features` (the default)."""
        return None

    # ------------------------------------------------------------------ results
    def coefficients(self, theta: np.ndarray, lin: dict, fv: float | None) -> dict:
        """Physical coefficients (SI, the library's names) from theta, the model's linear
        coefficients ``lin`` (name -> value) and ``fv`` (None when not fitted)."""
        raise NotImplementedError

    def library_config(self, c: dict, eps: float = 0.0, per_direction: dict | None = None) -> dict | None:
        """The friction library config (``{"model": name, ...}``) of fitted coefficients ``c``;
        ``per_direction``: plateau levels per direction (asymmetric joint); None: not exportable."""
        return None

    def steady_state(self, c: dict, v: np.ndarray, eps: float) -> np.ndarray:
        """Steady-sliding friction F(v) of fitted coefficients ``c`` (report curves)."""
        raise NotImplementedError

    def steady_state_constraints(self, linear_all: list[str], fs: float) -> list[tuple[np.ndarray, float]]:
        """Linear constraints ``c . beta = d`` that hold the static level at ``fs`` (two-stage
        identification, :meth:`FitSpec.fix_steady_state`); [] = none."""
        return []

    def warm_start(self, spec, fitted: list[tuple[str, np.ndarray]]) -> np.ndarray | None:
        """A starting theta from models fitted before (name, theta), or None."""
        return None


# ---------------------------------------------------------------------------------------- registry
_REGISTRY: dict[str, type[FitModel]] = {}
ENTRY_POINT_GROUP = "friction_ros.fit_models"


def register_fit_model(cls: type[FitModel], *, library_class=None) -> type[FitModel]:
    """Register a :class:`FitModel` class (usable as a decorator); ``library_class``: its friction
    library model (:func:`friction_ros.core.friction.register_model`), registered alongside."""
    if not (isinstance(cls, type) and issubclass(cls, FitModel)) or not cls.family:
        raise ParameterError(f"fit model {cls!r} must be a FitModel subclass with a family name")
    _REGISTRY[cls.family] = cls
    if library_class is not None:
        from friction_ros.core.friction import register_model

        register_model(library_class)
    return cls
