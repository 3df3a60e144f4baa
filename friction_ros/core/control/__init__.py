"""Compensating controllers (pure core): PID, friction compensation, the seeds' schemes, façade."""

from friction_ros.core.control.compensation import FrictionCompensator
from friction_ros.core.control.controller import CompensatingController, ControllerTerms
from friction_ros.core.control.controller_config import CONTROLLER_DEFAULTS, CONTROLLER_MODES, default_config
from friction_ros.core.control.pid import ANTIWINDUP_STRATEGIES, PID_DEFAULTS, Pid, PidOutput
from friction_ros.core.control.schemes import (
    DNPF,
    Cascade,
    GainScheduling,
    SlidingMode,
    describing_damping,
    describing_stiffness,
    maxwell_virgin_curve,
    sliding_mode_relay,
)

__all__ = [
    "ANTIWINDUP_STRATEGIES",
    "CONTROLLER_DEFAULTS",
    "CONTROLLER_MODES",
    "PID_DEFAULTS",
    "DNPF",
    "Cascade",
    "CompensatingController",
    "ControllerTerms",
    "FrictionCompensator",
    "GainScheduling",
    "Pid",
    "PidOutput",
    "SlidingMode",
    "default_config",
    "describing_damping",
    "describing_stiffness",
    "maxwell_virgin_curve",
    "sliding_mode_relay",
]
