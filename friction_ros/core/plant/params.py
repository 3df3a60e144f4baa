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

from friction_ros.core.config import Field, Names, Schema, prefixed, within
from friction_ros.core.friction import model_from_config
from friction_ros.core.validation import (
    ParameterError,
    check_keys,
    check_real,
)

ACTUATION_MODES = ("current", "torque", "voltage")
ENCODER_LOCATIONS = ("motor", "joint")


def voltage_params_from_transfer_function(k: float, tau: float, resistance: float = 1.0) -> dict:
    """Voltage-mode motor constants reproducing theta/u = K / (s (tau s + 1)) (AI friction chapter eq. (12)).

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
PLANT_SCHEMA = Schema(
    "plant",
    [
        Field(
            "motor_inertia",
            None,
            "rotor (+ motor-side) inertia",
            lo=0.0,
            lo_open=True,
            unit="kg*m^2",
            kind=float,
        ),
        Field(
            "transmission_inertia", 0.0, "gear / lead screw inertia on the motor side", lo=0.0, unit="kg*m^2"
        ),
        Field(
            "load_inertia",
            0.0,
            "load inertia (mass for linear axes) at the joint",
            lo=0.0,
            unit="kg*m^2 or kg",
        ),
        Field("gear_ratio", 1.0, "motor revolutions per output revolution", lo=0.0, lo_open=True),
        Field("gear_efficiency", 1.0, "transmission efficiency (0, 1]", lo=0.0, lo_open=True, hi=1.0),
        Field("lead_pitch", 0.0, "lead-screw pitch; 0 = rotary joint", lo=0.0, unit="m/rev"),
        Field("motor_damping", 0.0, "viscous damping at the motor", lo=0.0, unit="N*m*s/rad"),
        Field("load_damping", 0.0, "viscous damping at the joint", lo=0.0, unit="N*m*s/rad or N*s/m"),
        Field("load_stiffness", 0.0, "stiffness of the joint to ground", lo=0.0, unit="N*m/rad or N/m"),
        Field("gravity_force", 0.0, "constant gravity load acting towards -q", unit="N*m or N"),
        Field(
            "gravity",
            0.0,
            "pendulum gravity load m g l: the joint feels -gravity sin(q + gravity_phase) (0 = off)",
            unit="N*m",
        ),
        Field("gravity_phase", 0.0, "phase q0 of the pendulum gravity load (q = -q0: hanging)", unit="rad"),
        Field("load_torque", 0.0, "constant external load along +q", unit="N*m or N"),
        Field("backlash", 0.0, "total backlash gap at the joint", lo=0.0, unit="rad or m"),
        Field("coupling_stiffness", 0.0, "transmission stiffness (0 = rigid)", lo=0.0, unit="N*m/rad or N/m"),
        Field("coupling_damping", 0.0, "transmission damping", lo=0.0, unit="N*m*s/rad or N*s/m"),
        Field(
            "torque_constant",
            None,
            "motor torque constant Kt",
            lo=0.0,
            lo_open=True,
            unit="N*m/A",
            kind=float,
        ),
        Field(
            "current_time_constant",
            0.0,
            "current-loop first-order lag (current/torque modes)",
            lo=0.0,
            unit="s",
        ),
        Field(
            "amplifier_gain", 1.0, "current per unit command (current mode)", lo=0.0, lo_open=True, unit="A/V"
        ),
        Field("current_limit", 0.0, "|i| limit (0 = none)", lo=0.0, unit="A"),
        Field("resistance", 1.0, "armature resistance (voltage mode)", lo=0.0, lo_open=True, unit="Ohm"),
        Field("inductance", 0.0, "armature inductance (voltage mode; 0 = algebraic)", lo=0.0, unit="H"),
        Field("back_emf_constant", 0.0, "back-EMF constant Ke (voltage mode)", lo=0.0, unit="V*s/rad"),
        Field("voltage_limit", 0.0, "|u| limit (0 = none)", lo=0.0, unit="V"),
        Field("internal_dt", 1e-4, "maximum internal integration step", lo=0.0, lo_open=True, unit="s"),
        Field(
            "encoder_cpr", 0, "quadrature counts per encoder revolution (0 = ideal)", lo=0, unit="counts/rev"
        ),
        Field(
            "encoder_ratio",
            1.0,
            "encoder revolutions per revolution of its shaft (belt)",
            lo=0.0,
            lo_open=True,
        ),
        Field(
            "velocity_filter_hz", 0.0, "first-order low-pass on the differenced velocity", lo=0.0, unit="Hz"
        ),
        Field("current_noise_std", 0.0, "white current-sensor noise", lo=0.0, unit="A"),
        Field("current_offset", 0.0, "current-sensor offset", unit="A"),
        Field("measurement_delay", 0.0, "sensor delay (rounded to control periods)", lo=0.0, unit="s"),
        Field("actuation_delay", 0.0, "command delay (rounded to control periods)", lo=0.0, unit="s"),
        Field("seed", 0, "random seed of the sensor noise", lo=0),
        Field(
            "actuation",
            "current",
            "what the command sets: current [A], torque [N*m] or voltage [V]",
            choices=ACTUATION_MODES,
        ),
        Field("stick_logic", True, "exact sticking at rest (GKF / Karnopp rule)"),
        Field("encoder_location", "motor", "shaft the encoder reads", choices=ENCODER_LOCATIONS),
    ],
    doc="gearhead servo plant (SI; joint units are rad or m)",
)
"""Parameters of :class:`PlantParams` (the ``plant`` section of a preset / plant_simulator)."""


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
    gravity: float = 0.0
    gravity_phase: float = 0.0
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
        _check_plant(self.__dict__, _PLANT_NAMES)
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
        """J_total at the motor = J_motor + J_transmission + J_load / (r^2 eta) (Tilakaratna et al. 2004 eq. (2))."""
        return (
            self.motor_inertia
            + self.transmission_inertia
            + self.load_inertia / (self.ratio**2 * self.gear_efficiency)
        )

    def reflect(self, joint_torque: float) -> float:
        """Joint-side torque/force reflected to the motor: T / (r eta) (Tilakaratna et al. 2004 eqs. (3)-(4))."""
        return joint_torque / (self.ratio * self.gear_efficiency)

    @classmethod
    def from_config(
        cls,
        plant: Mapping[str, Any],
        friction_motor: Any = None,
        friction_load: Any = None,
        names: Names | None = None,
    ) -> PlantParams:
        """From a ``plant`` section and the friction models' configs; messages name
        ``names("plant.<key>")``, ``names("friction_motor.<coefficient>")`` ... (default: those names)."""
        plant = dict(plant or {})
        if names is None:
            PLANT_SCHEMA.check_given(plant)
            return cls(**plant, friction_motor=friction_motor, friction_load=friction_load)
        check_keys(names("plant"), plant, PLANT_SCHEMA.items)
        full = {name: plant.get(name, spec.default) for name, spec in PLANT_SCHEMA.fields()}
        _check_plant(full, within(names, "plant"))
        fm = model_from_config(friction_motor, within(names, "friction_motor"))
        fl = model_from_config(friction_load, within(names, "friction_load"))
        return cls(**plant, friction_motor=fm, friction_load=fl)

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

    def replace(self, names: Names | None = None, **changes: Any) -> PlantParams:
        """These parameters with ``changes`` (plant keys, whole friction models); ``names`` as in
        :meth:`from_config`."""
        cfg = self.to_config()
        fm = changes.pop("friction_motor", cfg["friction_motor"])
        fl = changes.pop("friction_load", cfg["friction_load"])
        cfg["plant"].update(changes)
        return PlantParams.from_config(cfg["plant"], fm, fl, names)


_PLANT_NAMES = prefixed("plant")


def _check_plant(values: dict, names: Names) -> None:
    """Check and normalise the plant keys of ``values`` in place (messages: ``names(key)``)."""
    for name, spec in PLANT_SCHEMA.fields():
        values[name] = spec.check(values[name], names(name))
    if values["backlash"] > 0 and values["coupling_stiffness"] == 0:
        raise ParameterError(
            f"{names('coupling_stiffness')} = 0 with {names('backlash')} = {values['backlash']:g}: must "
            "be > 0 when backlash is modelled (the gap closes on a compliant contact)"
        )
