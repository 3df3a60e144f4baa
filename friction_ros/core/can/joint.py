"""Motor side <-> joint side conversion (gear ratio, torque constant, direction, zero offset).

The drive reports motor-side quantities (already in SI after the codec); the rest of friction_ros
works with the joint: position [rad], velocity [rad/s], effort = joint torque [N*m]; on a
prismatic joint (``lead`` > 0, the travel per motor turn) position [m], velocity [m/s] and
effort = force [N], with ``ratio`` = 2 pi / lead motor rad per m in place of the gear ratio:

    q_joint   = direction * q_motor / ratio - zero_offset
    dq_joint  = direction * dq_motor / ratio
    tau_joint = direction * tau_motor * ratio = direction * k_t * i_q * ratio

(ideal gearbox: efficiency and gearbox friction are what the rest of the project identifies).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from friction_ros.core.validation import ParameterError, check_real


@dataclass(frozen=True)
class JointConversion:
    gear_ratio: float = 1.0  # motor revolutions per joint revolution
    torque_constant: float = 0.1  # motor N*m per A (q-axis)
    direction: int = 1  # +1 or -1: sign between motor and joint (REP-103 joint convention)
    zero_offset: float = 0.0  # joint position [rad or m] reported when the motor reads 0
    lead: float = 0.0  # prismatic joint: travel per motor turn [m/rev]; 0 = revolute joint

    def __post_init__(self):
        check_real("gear_ratio", self.gear_ratio, 0.0, lo_open=True, unit="motor rev / joint rev")
        check_real("torque_constant", self.torque_constant, 0.0, lo_open=True, unit="N*m/A")
        check_real("lead", self.lead, 0.0, unit="m/rev")
        check_real("zero_offset", self.zero_offset, unit="m" if self.lead > 0 else "rad")
        if self.direction not in (1, -1):
            raise ParameterError(f"direction = {self.direction!r} is not allowed: must be one of 1, -1")
        if self.lead > 0 and self.gear_ratio != 1.0:
            raise ParameterError(
                f"gear_ratio = {self.gear_ratio:g} with lead = {self.lead:g} [m/rev]: a prismatic axis takes "
                "the travel per motor turn (screw lead / gear ratio) as lead; leave gear_ratio at 1"
            )

    @property
    def ratio(self) -> float:
        """Motor rad per joint unit: ``gear_ratio`` (revolute) or 2 pi / ``lead`` (prismatic)."""
        return 2.0 * math.pi / self.lead if self.lead > 0 else self.gear_ratio

    # motor -> joint
    def joint_position(self, motor_position: float) -> float:
        return self.direction * motor_position / self.ratio - self.zero_offset

    def joint_velocity(self, motor_velocity: float) -> float:
        return self.direction * motor_velocity / self.ratio

    def joint_torque(self, motor_torque: float) -> float:
        return self.direction * motor_torque * self.ratio

    def joint_torque_from_current(self, current: float) -> float:
        return self.direction * current * self.torque_constant * self.ratio

    # joint -> motor
    def motor_position(self, joint_position: float) -> float:
        return self.direction * (joint_position + self.zero_offset) * self.ratio

    def motor_velocity(self, joint_velocity: float) -> float:
        return self.direction * joint_velocity * self.ratio

    def motor_torque(self, joint_torque: float) -> float:
        return self.direction * joint_torque / self.ratio

    def motor_current(self, joint_torque: float) -> float:
        return self.motor_torque(joint_torque) / self.torque_constant
