"""What a fit returns: one :class:`ModelResult` per model and the :class:`FitResult` of a record set."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from friction_ros.core.identification.data.breakaway_detection import Breakaway
from friction_ros.core.identification.data.data_scale import effort_limit_of_log
from friction_ros.core.identification.data.excitation_checks import (
    Excitation,
)
from friction_ros.core.identification.data.plateau_detection import (
    Plateau,
)
from friction_ros.core.identification.data.records import JointData


@dataclass
class ModelResult:
    """One fitted model with everything the report needs."""

    name: str
    method: str  # "plateaus", "time-domain (de)", "learned"
    coefficients: dict
    config: dict | None
    metrics: dict
    identifiability: dict
    seconds: float
    steady_state: Callable[[np.ndarray], np.ndarray]
    predict: Callable[[JointData], np.ndarray]
    notes: list[str] = field(default_factory=list)
    extra: dict = field(default_factory=dict)
    #: "fitted", "not fitted" (the fit failed) or "diverged" (its prediction ran away on validation);
    #: only fitted models have figures, a config and a chance of being recommended
    status: str = "fitted"
    reason: str = ""

    @property
    def fitted(self) -> bool:
        return self.status == "fitted"


@dataclass
class FitResult:
    """Everything one fit produced; ``files`` lists what :func:`fit_bag` wrote."""

    models: dict[str, ModelResult]
    recommended: str | None
    train: list[JointData]
    validation: list[JointData]
    plateaus: list[Plateau]
    breakaways: list[Breakaway]
    excitation: Excitation
    high_threshold: float
    options: dict
    files: dict[str, str] = field(default_factory=dict)
    warnings: list[str] = field(default_factory=list)
    seconds: float = 0.0
    recommendation: dict = field(default_factory=dict)
    gate: dict = field(default_factory=dict)

    @property
    def inertia(self) -> float:
        m = self.models.get(self.recommended) if self.recommended else None
        return float(m.coefficients.get("J", 0.0)) if m else 0.0

    @property
    def effort_limit(self) -> float:
        """The joint's torque (force) limit for the parameter file: the plant preset's when one is
        given, else from the log's peak effort (:func:`~friction_ros.core.identification.data.data_scale.effort_limit_of_log`)."""
        preset = self.options.get("plant_preset")
        if preset:
            from friction_ros.core.experiment.joint_scale import JointScale
            from friction_ros.core.presets import load_preset

            return float(JointScale.from_preset(load_preset(preset)).torque_limit)
        return effort_limit_of_log([*self.train, *self.validation])
