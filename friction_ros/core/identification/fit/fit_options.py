"""The options of one identification run (:func:`~friction_ros.core.identification.fit.pipeline.fit_records`).

:class:`FitOptions` holds every option with its default, unit and a one-line description; it is
validated once, when it is made (a bad value raises ParameterError naming the option and what is
allowed). ``FitOptions.from_kwargs(**kw)`` makes one from keyword arguments and refuses unknown names;
:meth:`FitOptions.resolve` merges an options object with keyword overrides (what ``fit_records``,
``fit_bag`` and ``cross_validate_runs`` accept). Units follow the joint: [vel] is rad/s on a revolute
joint, m/s on a prismatic one.
"""

from __future__ import annotations

import dataclasses
import math
import numbers
from dataclasses import dataclass, field
from typing import Any

from friction_ros.core.identification.data.decimation import DEFAULT_MAX_SAMPLES
from friction_ros.core.joint_type import JOINT_TYPES
from friction_ros.core.validation import (
    ParameterError,
    check_bool,
    check_choice,
    check_int,
    check_keys,
    check_real,
)

TRAIN_WINDOWS = ("content", "window", "first")
OPTIMIZERS = ("de", "ga", "none")
RESIDUALS = ("auto", "none", "mlp", "rff")


def _check_int(name: str, value: Any, lo: int) -> None:
    """An integer (numpy's too) >= ``lo``."""
    if not (isinstance(value, numbers.Integral) and not isinstance(value, bool)):
        check_int(name, value, lo)  # a float such as 5.0 passes, anything else is refused
    elif value < lo:
        raise ParameterError(f"{name} = {value} is out of range: must be an integer >= {lo}")


def _opt(default, unit: str, text: str):
    return field(default=default, metadata={"unit": unit, "text": text})


@dataclass(frozen=True)
class FitOptions:
    """Every option of a fit (each field: default, unit, one-line description; :meth:`table`).

    ``train_window``: ``content`` trains on chunks stratified by content
    (:func:`~friction_ros.core.identification.data.training_split.training_segments`, about
    ``train_seconds`` in all) and validates on the rest; ``window`` on the single most exciting
    ``train_seconds`` (:func:`~friction_ros.core.identification.data.training_split.training_window`);
    ``first`` on the first ``train_seconds`` (ABB M19-S paper A.3).
    ``load``: the load, gravity and position terms identified jointly with every model
    (:mod:`~friction_ros.core.identification.fit.load_terms`): ``auto`` (chosen by validation when the
    records have no constant-velocity plateaus; with plateaus, the load offset measured on them),
    ``none``, a term list such as ``gravity,offset,ripple=4`` or a ``LoadTerms``. ``ripple_period``
    [rad]: the period of the position-dependent friction (2 pi / N for the motor angle of an N:1
    gear); ``load_eps``: the linear zone of sgn(v) in those terms (default: ``eps``, at least three
    times the velocity noise).
    ``residual``: a learned residual on the best physics model
    (:mod:`~friction_ros.core.identification.fit.residual_learning`; ``none`` here, friction-fit's
    default is ``auto``: for records without plateaus, mlp or rff by validation); the combined model
    ``<physics>+residual`` competes in the recommendation like any other.
    ``joint_type``: a prismatic joint has no angle-dependent load terms (gravity is constant along
    the axis: the offset takes it). ``max_samples``: a longer log is cut down by content
    (:mod:`~friction_ros.core.identification.data.decimation`; a warning says what was used).
    """

    train_seconds: float = _opt(10.0, "s", "training data per record (friction-characterization paper: 10 s)")
    train_window: str = _opt("content", "", "training data: content (chunks by content), window or first")
    optimizer: str = _opt("de", "", "global search of the dynamic models: de, ga or none (local only)")
    maxiter: int | dict | None = _opt(
        None, "", "global-search generations, or {model: generations}; None: 40 + 15 x dimension"
    )
    popsize: int = _opt(12, "", "differential-evolution population per search dimension")
    seed: int = _opt(3, "", "random seed of the global search and the learned residual")
    eps: float | None = _opt(
        None, "vel", "linear zone of sgn(v) of the static models; None: 1e-3 x speed scale"
    )
    high_threshold: float | None = _opt(
        None, "vel", "high/low velocity split of the metrics; None: automatic"
    )
    identifiability_check: bool = _opt(
        True, "", "standard errors and correlations of the fitted coefficients"
    )
    two_stage: bool = _opt(True, "", "keep the plateau steady state, search only the dynamic coefficients")
    label: str = _opt("data", "", "name of the data in messages")
    load: Any = _opt(
        "auto", "", "load terms: auto, none, a list such as gravity,offset,ripple=4, or LoadTerms"
    )
    ripple_period: float = _opt(2.0 * math.pi, "rad", "period of the position-dependent friction")
    load_eps: float | None = _opt(
        None, "vel", "linear zone of sgn(v) in the load terms; None: from the noise"
    )
    residual: str = _opt("none", "", "learned residual on the best physics model: auto, none, mlp or rff")
    joint_type: str = _opt("revolute", "", "revolute (rad, N*m) or prismatic (m, N)")
    max_samples: int | None = _opt(
        DEFAULT_MAX_SAMPLES,
        "samples",
        "a longer log is cut down to this many, chosen by content; None or 0: all",
    )

    def __post_init__(self) -> None:
        check_real("train_seconds", self.train_seconds, 0.0, lo_open=True, unit="s")
        check_choice("train_window", self.train_window, TRAIN_WINDOWS)
        check_choice("optimizer", self.optimizer, OPTIMIZERS)
        if isinstance(self.maxiter, dict):
            for name, n in self.maxiter.items():
                if n is not None:
                    _check_int(f"maxiter[{name!r}]", n, 1)
        elif self.maxiter is not None:
            _check_int("maxiter", self.maxiter, 1)
        _check_int("popsize", self.popsize, 1)
        _check_int("seed", self.seed, 0)
        for name in ("eps", "high_threshold", "load_eps"):
            if getattr(self, name) is not None:
                check_real(name, getattr(self, name), 0.0, lo_open=True, unit="rad/s or m/s")
        check_bool("identifiability_check", self.identifiability_check)
        check_bool("two_stage", self.two_stage)
        if not isinstance(self.label, str):
            raise ParameterError(f"label = {self.label!r} must be a string")
        check_real("ripple_period", self.ripple_period, 0.0, lo_open=True, unit="rad")
        check_choice("residual", self.residual, RESIDUALS)
        check_choice("joint_type", self.joint_type, JOINT_TYPES)
        if self.max_samples is not None:
            _check_int("max_samples", self.max_samples, 0)
        from friction_ros.core.identification.fit.load_terms import LoadTerms, parse_terms

        if isinstance(self.load, str):
            parse_terms(self.load, ripple_period=self.ripple_period)  # a bad term name is refused here
        elif not isinstance(self.load, LoadTerms):
            raise ParameterError(
                f"load = {self.load!r} is not allowed: must be auto, none, a term list or LoadTerms"
            )

    @classmethod
    def names(cls) -> list[str]:
        return [f.name for f in dataclasses.fields(cls)]

    @classmethod
    def from_kwargs(cls, **kw) -> FitOptions:
        """Options from keyword arguments; an unknown name is refused in one line listing the allowed."""
        check_keys("fit options", kw, cls.names())
        return cls(**kw)

    @classmethod
    def resolve(cls, options: FitOptions | None, kw: dict) -> FitOptions:
        """``options`` (default: all defaults) with the keyword overrides ``kw`` (validated)."""
        if options is None:
            return cls.from_kwargs(**kw)
        if not isinstance(options, FitOptions):
            raise ParameterError(f"options = {options!r} must be a FitOptions (or give keyword arguments)")
        if not kw:
            return options
        check_keys("fit options", kw, cls.names())
        return dataclasses.replace(options, **kw)

    def replace(self, **kw) -> FitOptions:
        """A copy with ``kw`` changed (validated)."""
        return FitOptions.resolve(self, kw)

    def maxiter_for(self, model: str) -> int | None:
        """The generations of ``model``'s global search (``maxiter`` may be a per-model dict)."""
        return self.maxiter.get(model) if isinstance(self.maxiter, dict) else self.maxiter

    @classmethod
    def table(cls) -> list[tuple[str, Any, str, str]]:
        """(name, default, unit, description) of every option."""
        return [(f.name, f.default, f.metadata["unit"], f.metadata["text"]) for f in dataclasses.fields(cls)]
