"""Plant parameters (pure core): :class:`PlantParams`, validated once, built from the ``plant``
section of a preset or parameter file plus its ``friction_motor`` / ``friction_load`` models.

The model the parameters describe is in :mod:`friction_ros.core.plant.servo`; presets
(:mod:`friction_ros.core.presets`) are the one way from a YAML file to a plant.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field, fields
from typing import Any

from friction_ros.core.friction import model_from_config
from friction_ros.core.validation import (
    ParameterError,
    check_bool,
    check_choice,
    check_int,
    check_keys,
    check_real,
)

ACTUATION_MODES = ("current", "torque", "voltage")
ENCODER_LOCATIONS = ("motor", "joint")


def voltage_params_from_transfer_function(k: float, tau: float, resistance: float = 1.0) -> dict:
    """Voltage-mode motor constants reproducing theta/u = K / (s (tau s + 1)) (seed 004 eq. (12)).

    With L = 0 and no viscous term: Ke = Kt = 1/K, J = Kt tau / (R K) gives
    theta'' = -theta'/tau + (K/tau) u. ``resistance`` is free (the paper does not give it).
    """
    k = check_real("k", k, 0.0, lo_open=True)
    tau = check_real("tau", tau, 0.0, lo_open=True, unit="s")
    r = check_real("resistance", resistance, 0.0, lo_open=True, unit="Ohm")
    ke = 1.0 / k
    return {
        "actuation": "voltage",
        "torque_constant": ke,
        "back_emf_constant": ke,
        "resistance": r,
        "inductance": 0.0,
        "motor_inertia": ke * tau / (r * k),
    }


# ---------------------------------------------------------------------------------------------------
# parameters
# ---------------------------------------------------------------------------------------------------
_SPECS: dict[str, tuple] = {
    # name: (default, lo, lo_open, unit, doc)
    "motor_inertia": (None, 0.0, True, "kg*m^2", "rotor (+ motor-side) inertia"),
    "transmission_inertia": (0.0, 0.0, False, "kg*m^2", "gear / lead screw inertia on the motor side"),
    "load_inertia": (0.0, 0.0, False, "kg*m^2 or kg", "load inertia (mass for linear axes) at the joint"),
    "gear_ratio": (1.0, 0.0, True, "", "motor revolutions per output revolution"),
    "gear_efficiency": (1.0, 0.0, True, "", "transmission efficiency (0, 1]"),
    "lead_pitch": (0.0, 0.0, False, "m/rev", "lead-screw pitch; 0 = rotary joint"),
    "motor_damping": (0.0, 0.0, False, "N*m*s/rad", "viscous damping at the motor"),
    "load_damping": (0.0, 0.0, False, "N*m*s/rad or N*s/m", "viscous damping at the joint"),
    "load_stiffness": (0.0, 0.0, False, "N*m/rad or N/m", "stiffness of the joint to ground"),
    "gravity_force": (0.0, None, False, "N*m or N", "constant gravity load acting towards -q"),
    "load_torque": (0.0, None, False, "N*m or N", "constant external load along +q"),
    "backlash": (0.0, 0.0, False, "rad or m", "total backlash gap at the joint"),
    "coupling_stiffness": (0.0, 0.0, False, "N*m/rad or N/m", "transmission stiffness (0 = rigid)"),
    "coupling_damping": (0.0, 0.0, False, "N*m*s/rad or N*s/m", "transmission damping"),
    "torque_constant": (None, 0.0, True, "N*m/A", "motor torque constant Kt"),
    "current_time_constant": (0.0, 0.0, False, "s", "current-loop first-order lag (current/torque modes)"),
    "amplifier_gain": (1.0, 0.0, True, "A/V", "current per unit command (current mode)"),
    "current_limit": (0.0, 0.0, False, "A", "|i| limit (0 = none)"),
    "resistance": (1.0, 0.0, True, "Ohm", "armature resistance (voltage mode)"),
    "inductance": (0.0, 0.0, False, "H", "armature inductance (voltage mode; 0 = algebraic)"),
    "back_emf_constant": (0.0, 0.0, False, "V*s/rad", "back-EMF constant Ke (voltage mode)"),
    "voltage_limit": (0.0, 0.0, False, "V", "|u| limit (0 = none)"),
    "internal_dt": (1e-4, 0.0, True, "s", "maximum internal integration step"),
    "encoder_cpr": (0, 0, False, "counts/rev", "quadrature counts per encoder revolution (0 = ideal)"),
    "encoder_ratio": (1.0, 0.0, True, "", "encoder revolutions per revolution of its shaft (belt)"),
    "velocity_filter_hz": (0.0, 0.0, False, "Hz", "first-order low-pass on the differenced velocity"),
    "current_noise_std": (0.0, 0.0, False, "A", "white current-sensor noise"),
    "current_offset": (0.0, None, False, "A", "current-sensor offset"),
    "measurement_delay": (0.0, 0.0, False, "s", "sensor delay (rounded to control periods)"),
    "actuation_delay": (0.0, 0.0, False, "s", "command delay (rounded to control periods)"),
    "seed": (0, 0, False, "", "random seed of the sensor noise"),
}
_CHOICES = {"actuation": ("current", ACTUATION_MODES), "encoder_location": ("motor", ENCODER_LOCATIONS)}
_INTS = ("encoder_cpr", "seed")


@dataclass
class PlantParams:
    """Validated plant parameters (SI; joint units are rad or m). See module docstring.

    Build from a ROS-parameter style section with :meth:`from_config`; :meth:`to_config` round-trips.
    """

    motor_inertia: float = 1e-4
    torque_constant: float = 0.1
    transmission_inertia: float = 0.0
    load_inertia: float = 0.0
    gear_ratio: float = 1.0
    gear_efficiency: float = 1.0
    lead_pitch: float = 0.0
    motor_damping: float = 0.0
    load_damping: float = 0.0
    load_stiffness: float = 0.0
    gravity_force: float = 0.0
    load_torque: float = 0.0
    backlash: float = 0.0
    coupling_stiffness: float = 0.0
    coupling_damping: float = 0.0
    actuation: str = "current"
    current_time_constant: float = 0.0
    amplifier_gain: float = 1.0
    current_limit: float = 0.0
    resistance: float = 1.0
    inductance: float = 0.0
    back_emf_constant: float = 0.0
    voltage_limit: float = 0.0
    internal_dt: float = 1e-4
    stick_logic: bool = True
    encoder_cpr: int = 0
    encoder_location: str = "motor"
    encoder_ratio: float = 1.0
    velocity_filter_hz: float = 0.0
    current_noise_std: float = 0.0
    current_offset: float = 0.0
    measurement_delay: float = 0.0
    actuation_delay: float = 0.0
    seed: int = 0
    friction_motor: Any = None
    friction_load: Any = None
    extra: dict = field(default_factory=dict, repr=False)

    def __post_init__(self) -> None:
        for name, (_d, lo, lo_open, unit, _doc) in _SPECS.items():
            val = getattr(self, name)
            if name in _INTS:
                setattr(self, name, check_int(f"plant.{name}", val, lo))
            else:
                setattr(self, name, check_real(f"plant.{name}", val, lo, lo_open=lo_open, unit=unit))
        if self.gear_efficiency > 1.0:
            raise ParameterError(
                f"plant.gear_efficiency = {self.gear_efficiency:g} is out of range: must be > 0 and <= 1"
            )
        for name, (_d, choices) in _CHOICES.items():
            check_choice(f"plant.{name}", getattr(self, name), choices)
        self.stick_logic = check_bool("plant.stick_logic", self.stick_logic)
        if self.backlash > 0 and self.coupling_stiffness == 0:
            raise ParameterError(
                f"plant.coupling_stiffness = 0 with plant.backlash = {self.backlash:g}: must be > 0 when "
                "backlash is modelled (the gap closes on a compliant contact)"
            )
        self.friction_motor = model_from_config(self.friction_motor)
        self.friction_load = model_from_config(self.friction_load)

    @property
    def ratio(self) -> float:
        """Motor radians per joint unit (rad or m)."""
        r = self.gear_ratio
        if self.lead_pitch > 0:
            r *= 2.0 * math.pi / self.lead_pitch
        return r

    @property
    def compliant(self) -> bool:
        return self.coupling_stiffness > 0

    @property
    def reflected_inertia(self) -> float:
        """J_total at the motor = J_motor + J_transmission + J_load / (r^2 eta) (seed 002 eq. (2))."""
        return (
            self.motor_inertia
            + self.transmission_inertia
            + self.load_inertia / (self.ratio**2 * self.gear_efficiency)
        )

    def reflect(self, joint_torque: float) -> float:
        """Joint-side torque/force reflected to the motor: T / (r eta) (seed 002 eqs. (3)-(4))."""
        return joint_torque / (self.ratio * self.gear_efficiency)

    @classmethod
    def from_config(
        cls, plant: Mapping[str, Any], friction_motor: Any = None, friction_load: Any = None
    ) -> PlantParams:
        plant = dict(plant or {})
        allowed = [f.name for f in fields(cls) if f.name not in ("extra", "friction_motor", "friction_load")]
        check_keys("plant", plant, allowed)
        for req in ("motor_inertia", "torque_constant"):
            if req not in plant:
                raise ParameterError(
                    f"plant.{req} is missing: required ({_SPECS[req][4]}, > 0 {_SPECS[req][3]})"
                )
        return cls(**plant, friction_motor=friction_motor, friction_load=friction_load)

    def to_config(self) -> dict:
        """``{"plant": {...}, "friction_motor": {...}, "friction_load": {...}}`` (ROS parameter section)."""
        plant = {
            f.name: getattr(self, f.name)
            for f in fields(self)
            if f.name not in ("extra", "friction_motor", "friction_load")
        }
        return {
            "plant": plant,
            "friction_motor": self.friction_motor.to_config(),
            "friction_load": self.friction_load.to_config(),
        }

    def replace(self, **changes: Any) -> PlantParams:
        cfg = self.to_config()
        fm = changes.pop("friction_motor", cfg["friction_motor"])
        fl = changes.pop("friction_load", cfg["friction_load"])
        cfg["plant"].update(changes)
        return PlantParams.from_config(cfg["plant"], fm, fl)
