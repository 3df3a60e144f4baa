"""Drive units <-> joint SI units for CiA 402 (position counts, velocity counts/s, torque per mille).

With ``cpr`` encoder counts per motor revolution (0x608F), rated torque ``T_r`` [motor N*m] (0x6076
is in mN*m), rated current ``I_r`` [A] (0x6075 in mA) and the motor-to-joint conversion ``c`` (a
:class:`~friction_ros.core.can.joint.JointConversion`: gear ratio or lead, direction, zero offset):

    q_joint   = c.joint_position(2 pi * counts / cpr)        [rad or m]
    dq_joint  = c.joint_velocity(2 pi * counts_per_s / cpr)  [rad/s or m/s]
    tau_joint = c.joint_torque(T_r * permille / 1000)        [N*m or N]
    i         = I_r * permille / 1000                        [A]

(CiA 402-2 6.9.5, 6.9.8: 0x6071/0x6077 in per mille of 0x6076; 0x6078 in per mille of 0x6075.)
The factors are folded into four constants once, so the per-period conversion is one multiply each.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from friction_ros.core.can.joint import JointConversion
from friction_ros.core.validation import check_int, check_real

from .frames import I16_MAX, I16_MIN


@dataclass(frozen=True)
class Cia402Scaling:
    counts_per_rev: int = 131072  # encoder counts per motor revolution
    rated_torque: float = 1.0  # motor N*m (0x6076 / 1000)
    rated_current: float = 10.0  # A (0x6075 / 1000)
    conversion: JointConversion = field(default_factory=JointConversion)

    def __post_init__(self):
        check_int("counts_per_rev", self.counts_per_rev, 1, 2**31 - 1)
        check_real("rated_torque", self.rated_torque, 0.0, lo_open=True, unit="N*m")
        check_real("rated_current", self.rated_current, 0.0, lo_open=True, unit="A")
        c = self.conversion
        rad_per_count = 2.0 * math.pi / self.counts_per_rev
        object.__setattr__(self, "_k_pos", c.joint_velocity(rad_per_count))  # direction / ratio folded in
        object.__setattr__(self, "_k_tau", c.joint_torque(self.rated_torque / 1000.0))
        object.__setattr__(self, "_k_cur", self.rated_current / 1000.0)

    def factors(self) -> tuple[float, float, float, float]:
        """(k_pos, zero_offset, k_tau, k_cur): q = k_pos * counts - zero_offset, dq = k_pos *
        counts_per_s, tau = k_tau * permille, i = k_cur * permille (the cyclic PDO path inlines them)."""
        return self._k_pos, self.conversion.zero_offset, self._k_tau, self._k_cur

    # drive -> joint
    def joint_position(self, counts: int) -> float:
        return self._k_pos * counts - self.conversion.zero_offset

    def joint_velocity(self, counts_per_s: int) -> float:
        return self._k_pos * counts_per_s

    def joint_torque(self, permille: int) -> float:
        return self._k_tau * permille

    def current(self, permille: int) -> float:
        return self._k_cur * permille

    # joint -> drive
    def torque_permille(self, joint_torque: float) -> int:
        """Target torque 0x6071 for a joint torque, rounded and saturated to int16."""
        x = round(joint_torque / self._k_tau)
        return I16_MIN if x < I16_MIN else I16_MAX if x > I16_MAX else x

    # motor SI -> drive (emulator side)
    def counts(self, motor_rad: float) -> int:
        return round(motor_rad * self.counts_per_rev / (2.0 * math.pi))

    def motor_permille(self, motor_torque: float) -> int:
        x = round(1000.0 * motor_torque / self.rated_torque)
        return I16_MIN if x < I16_MIN else I16_MAX if x > I16_MAX else x
