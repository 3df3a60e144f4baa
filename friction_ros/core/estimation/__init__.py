"""Online friction estimation (pure core): torque balance, disturbance observer, RLS, LuGre observer."""

from friction_ros.core.estimation.estimator import (
    ESTIMATOR_MODELS,
    ESTIMATOR_SCHEMA,
    METHODS,
    FrictionEstimateData,
    OnlineFrictionEstimator,
    regressor,
)
from friction_ros.core.estimation.measurement import DisturbanceObserver, TorqueBalanceEstimator
from friction_ros.core.estimation.rls import RecursiveLeastSquares

__all__ = [
    "ESTIMATOR_SCHEMA",
    "ESTIMATOR_MODELS",
    "METHODS",
    "DisturbanceObserver",
    "FrictionEstimateData",
    "OnlineFrictionEstimator",
    "RecursiveLeastSquares",
    "TorqueBalanceEstimator",
    "regressor",
]
