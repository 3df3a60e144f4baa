"""Offline friction identification (pure core, no rclpy): bag arrays -> fitted models -> report.

Modules: ``data`` (loading, time alignment, differentiation, plateaus, breakaway, split),
``static_fit`` (robust LS on the plateau map), ``ga`` (seed 001's genetic algorithm),
``dynamic_fit`` (output error with DE/GA + Nelder-Mead, inertia jointly), ``learned`` (ANFIS,
nu-SVR per direction), ``identifiability`` (collinearity flags, confidence intervals), ``metrics``
(seed 003 eq. 4 NMSE, AIC/BIC, recommendation), ``report`` (Markdown, PNG, JSON, YAML),
``seed001`` (seed 001's unity-feedback position output error), ``synthetic`` (known-truth runs).

Entry points: :func:`fit_bag` and :func:`fit_records` (see ``pipeline``).
"""

from friction_ros.core.identification.pipeline import (
    DEFAULT_MODELS,
    FitResult,
    ModelResult,
    fit_bag,
    fit_records,
    load_bag,
)
from friction_ros.core.identification.records import ExcitationError, JointData, prepare

__all__ = [
    "DEFAULT_MODELS",
    "ExcitationError",
    "FitResult",
    "JointData",
    "ModelResult",
    "fit_bag",
    "fit_records",
    "load_bag",
    "prepare",
]
