"""Offline friction identification (pure core, no rclpy): logs -> fitted models -> report and files.

Three layers, each importing only the ones before it:

* :mod:`~friction_ros.core.identification.data`: logs in (bags, CSV), the uniform record, its
  scales, segments (plateaus, breakaways, velocity regimes), train/validation split and the
  selection of a long log's samples;
* :mod:`~friction_ros.core.identification.fit`: the fit models and their registry, the search
  space, static and dynamic fits, learned models, metrics, the baseline, the recommendation and
  :func:`fit_records`, the pipeline that runs them with its :class:`FitOptions`;
* :mod:`~friction_ros.core.identification.report`: ``report.md``, plots, ``summary.json``, the
  parameter file, and :func:`fit_bag` (logs in, files out), one joint or every joint of a bag.

The simulated joints with a known truth that tests and benchmarks fit are in
:mod:`friction_ros.core.synthetic`; the fitter never imports them.
"""

from friction_ros.core.identification.data.bag_loading import load_bag
from friction_ros.core.identification.data.records import ExcitationError, JointData, prepare
from friction_ros.core.identification.fit.fit_model import Coef, FitModel, register_fit_model
from friction_ros.core.identification.fit.fit_options import FitOptions
from friction_ros.core.identification.fit.fit_results import FitResult, ModelResult
from friction_ros.core.identification.fit.pipeline import DEFAULT_MODELS, fit_records
from friction_ros.core.identification.report.fit_logs import cross_validate_runs, fit_bag

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
