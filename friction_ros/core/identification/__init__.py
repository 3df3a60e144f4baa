"""Offline friction identification (pure core, no rclpy): bag arrays -> fitted models -> report.

Modules: ``records`` (time alignment, differentiation: the uniform record), ``bag_loading`` (a
joint of a bag as a record), ``velocity_regimes``, ``plateau_detection``, ``breakaway_detection``,
``plateau_map`` (the static map printed after an experiment), ``training_split``,
``excitation_checks`` (what a record excites), ``static_fit`` (robust LS on the plateau map), ``ga`` (GA friction thesis 2002's genetic algorithm),
``dynamic_fit`` (output error with DE/GA + Nelder-Mead, inertia jointly), ``learned`` (ANFIS,
nu-SVR per direction), ``identifiability`` (collinearity flags, confidence intervals), ``metrics``
(ABB M19-S paper eq. 4 NMSE, AIC/BIC, recommendation), ``report`` (Markdown, PNG, JSON, YAML),
``seed001`` (GA friction thesis 2002's unity-feedback position output error), ``synthetic`` (known-truth runs),
``load_terms`` (gravity, offset, spring, load- and position-dependent friction regressors, chosen by
validation), ``diagnosis`` (what a poor fit's residual follows), ``residual_learning`` (learned
residual on a physics backbone), ``csv_loading``/``log_loading`` (CSV logs, any bag),
``realistic_joint`` (a realistic synthetic robot joint with known truth), ``fit_model`` (the
plugin base every fittable family implements, and its registry) with ``fit_families`` (the
built-in families).

Entry points: :func:`fit_bag` (``fit_logs``: logs in, files out) and :func:`fit_records` (``pipeline``, which compares the models;
its options: :class:`FitOptions`;
``model_fits`` turns each family's fit into a ``ModelResult`` of ``fit_results``).
"""

from friction_ros.core.identification.bag_loading import load_bag
from friction_ros.core.identification.fit_logs import cross_validate_runs, fit_bag
from friction_ros.core.identification.fit_model import Coef, FitModel, register_fit_model
from friction_ros.core.identification.fit_options import FitOptions
from friction_ros.core.identification.fit_results import FitResult, ModelResult
from friction_ros.core.identification.pipeline import DEFAULT_MODELS, fit_records
from friction_ros.core.identification.records import ExcitationError, JointData, prepare

__all__ = [
    "Coef",
    "DEFAULT_MODELS",
    "ExcitationError",
    "FitModel",
    "FitOptions",
    "FitResult",
    "JointData",
    "ModelResult",
    "cross_validate_runs",
    "fit_bag",
    "fit_records",
    "load_bag",
    "prepare",
    "register_fit_model",
]
