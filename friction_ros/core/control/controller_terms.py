"""The terms of one control period (the fields of friction_msgs/ControllerState)."""

from __future__ import annotations

from dataclasses import asdict, dataclass, fields
from operator import attrgetter
from typing import Any

from friction_ros.core.wire import CONTROLLER_STATE_FLOATS


@dataclass(slots=True)
class ControllerTerms:
    """All terms of one period (friction_msgs/ControllerState fields, SI units)."""

    time: float = 0.0
    mode: str = "pid"
    reference_position: float = 0.0
    reference_velocity: float = 0.0
    reference_acceleration: float = 0.0
    position: float = 0.0
    velocity: float = 0.0
    error: float = 0.0
    error_dot: float = 0.0
    p_term: float = 0.0
    i_term: float = 0.0
    d_term: float = 0.0
    velocity_feedforward: float = 0.0
    inertia_feedforward: float = 0.0
    friction_feedforward: float = 0.0
    friction_feedback: float = 0.0
    #: tau_L: identified load, gravity, load-dependent and position-dependent friction (section load)
    load_feedforward: float = 0.0
    #: learned residual model (section residual), bounded, 0 when it returned a non-finite value
    learned_feedforward: float = 0.0
    command_unlimited: float = 0.0
    command: float = 0.0
    saturated: bool = False
    #: friction compensation switched off (latched) by the run-time limit-cycle detector
    compensation_fallback: bool = False

    def as_dict(self) -> dict[str, Any]:
        return asdict(self)


#: the friction_msgs/ControllerState floats of one period's terms, in message order (one call)
state_floats = attrgetter(*CONTROLLER_STATE_FLOATS)
# every term but time, mode, saturated and compensation_fallback (diagnostics and the log carry it)
assert {f.name for f in fields(ControllerTerms)} - {
    "time",
    "mode",
    "saturated",
    "compensation_fallback",
} == set(CONTROLLER_STATE_FLOATS), "ControllerTerms and ControllerStateEncoder disagree"
