"""Gearhead DC servo plant (pure core): mechanics, actuation, friction and realistic sensing.

Model (motor frame, SI; ``r`` = gear_ratio * (2*pi/lead_pitch for linear axes) = motor rad per joint
unit, ``eta`` = transmission efficiency applied to reflected load quantities as in seed 002
eqs. (2)-(4)):

* rigid transmission: ``J_eq w' = Kt i - Bm w - (Bl w/r + Kl q + m_g - T_load)/(r eta) - F_m(w)
  - F_l(w/r)/(r eta)``, ``J_eq = J_motor + J_transmission + J_load/(r^2 eta)`` (seed 002 eq. (1)-(4),
  seed 003 eq. (1));
* backlash / compliant transmission (``coupling_stiffness > 0``): two bodies coupled by a dead-zone
  spring-damper of total gap ``backlash`` (joint units);
* actuation: ``current`` (command = amplifier input, i_ref = amplifier_gain*cmd, current loop as a
  first-order lag with ``current_time_constant``, seed 002 eq. (9)), ``torque`` (command = joint
  torque, i_ref = cmd/(Kt r eta), same lag) or ``voltage`` (L di/dt = u - R i - Ke w; L = 0 gives
  seed 004's K/(s(tau s + 1)), see :func:`voltage_params_from_transfer_function`);
* friction: any model of :mod:`friction_ros.core.friction` at the motor and/or load side. Static
  models get exact stick logic (GKF rule of seed 004 eq. (4) at rest, zero-crossing detection,
  Karnopp band when the model is ``karnopp``); dynamic models use their exact/implicit updates;
* sensing: encoder quantisation (quadrature counts/rev, optional belt ratio), velocity from a
  filtered difference, current noise/offset, measurement and actuation delays, all seeded.

The inner loop (sub-steps inside one control period) runs in one compiled numba call.

Commands are plausibility-checked: a NaN/inf command or one with ``|command| >``
:data:`MAX_COMMAND` (1e9 A, V or N*m: no amplifier reaches it) raises ParameterError and leaves the
plant unchanged, so a finite but absurd command (1e308) cannot overflow the state to inf/NaN.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Mapping
from dataclasses import dataclass, field, fields
from typing import Any

import numpy as np

from friction_ros.core.config import Field, Schema
from friction_ros.core.friction import _kernels as K
from friction_ros.core.friction import model_from_config
from friction_ros.core.friction._kernels import jit
from friction_ros.core.validation import ParameterError, check_real

ACTUATION_MODES = ("current", "torque", "voltage")
_COMMAND_UNITS = {"current": "A", "torque": "N*m", "voltage": "V"}
#: Largest |command| the plant accepts (its own unit: A, N*m or V); see the module docstring.
MAX_COMMAND = 1.0e9
ENCODER_LOCATIONS = ("motor", "joint")

# seed 004 eq. (13): I_s = 7.8555 V_s - 19.6544
SEED004_SENSOR_GAIN = 7.8555
SEED004_SENSOR_OFFSET = -19.6544


def current_from_sensor_voltage(v, gain: float = SEED004_SENSOR_GAIN, offset: float = SEED004_SENSOR_OFFSET):
    """Current-sensor calibration of seed 004 eq. (13): I = gain * V + offset [A]."""
    return gain * np.asarray(v, dtype=float) + offset


def sensor_voltage_from_current(i, gain: float = SEED004_SENSOR_GAIN, offset: float = SEED004_SENSOR_OFFSET):
    """Inverse of :func:`current_from_sensor_voltage`: V = (I - offset) / gain [V]."""
    return (np.asarray(i, dtype=float) - offset) / gain


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
        for name, spec in PLANT_SCHEMA.fields():
            setattr(self, name, spec.check(getattr(self, name), f"plant.{name}"))
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
        PLANT_SCHEMA.check_given(plant)
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


# ---------------------------------------------------------------------------------------------------
# compiled inner loop
# ---------------------------------------------------------------------------------------------------
(
    P_JM,
    P_JL,
    P_R,
    P_ETA,
    P_BM,
    P_BL,
    P_KL,
    P_GRAV,
    P_TLOAD,
    P_BACKLASH,
    P_KC,
    P_CC,
    P_KT,
    P_MODE,
    P_TAUI,
    P_RES,
    P_IND,
    P_KE,
    P_IMAX,
    P_UMAX,
    P_BAND_M,
    P_BAND_L,
    P_STICK,
    P_COMPLIANT,
    P_SIZE,
) = range(25)
X_THM, X_WM, X_Q, X_WL, X_I, X_SIZE = range(6)


@jit
def _static_pair(km, pm, sm, kl, pl, sl, w, r, scale_l, load_m, load_l):
    """Static friction of both sides at motor velocity ``w`` (load side reflected by ``scale_l``)."""
    f = 0.0
    if km >= 0:
        f += K.friction_eval(km, pm, sm, w, 0.0, load_m)
    if kl >= 0:
        f += scale_l * K.friction_eval(kl, pl, sl, w / r, 0.0, load_l)
    return f


@jit
def _body_step(w, ta, J, h, km, pm, sm, kl, pl, sl, r, scale_l, load_m, load_l, band, stick):
    """Advance one body's velocity with static friction (GKF/Karnopp stick logic); returns (w, F)."""
    if km < 0 and kl < 0:
        return w + h * ta / J, 0.0
    if not stick:
        f = _static_pair(km, pm, sm, kl, pl, sl, w, r, scale_l, load_m, load_l)
        return w + h * (ta - f) / J, f
    if w == 0.0 or abs(w) < band:
        d = 1.0 if ta >= 0.0 else -1.0
        brk = abs(_static_pair(km, pm, sm, kl, pl, sl, d * 1e-12, r, scale_l, load_m, load_l))
        if abs(ta) <= brk:
            return 0.0, ta
        f = d * brk
        return w + h * (ta - f) / J, f
    f = _static_pair(km, pm, sm, kl, pl, sl, w, r, scale_l, load_m, load_l)
    wn = w + h * (ta - f) / J
    if wn * w < 0.0:
        wn = 0.0
    return wn, f


@jit
def _plant_run(P, x, km, pm, sm, dm, kl, pl, sl, dl, cmd, n_sub, h, out):
    """Run len(cmd) control periods of n_sub sub-steps each; out[k] = (thm, wm, q, wl, i, f_m, f_l)."""
    r = P[P_R]
    eta = P[P_ETA]
    refl = 1.0 / (r * eta)
    kt = P[P_KT]
    compliant = P[P_COMPLIANT] != 0.0
    stick = P[P_STICK] != 0.0
    jm = P[P_JM]
    jl = P[P_JL]
    jeq = jm + jl * refl / r
    decay_i = 0.0
    if P[P_MODE] == 0.0:
        if P[P_TAUI] > 0.0:
            decay_i = math.exp(-h / P[P_TAUI])
    elif P[P_IND] > 0.0:
        decay_i = math.exp(-P[P_RES] * h / P[P_IND])
    # static vs dynamic friction split
    skm = km if dm == 0 else -1
    skl = kl if dl == 0 else -1
    thm, wm, q, wl, cur = x[X_THM], x[X_WM], x[X_Q], x[X_WL], x[X_I]
    fm_last = 0.0
    fl_last = 0.0
    for k in range(cmd.shape[0]):
        c = cmd[k]
        for _ in range(n_sub):
            # --- current ---
            if P[P_MODE] == 0.0:
                iss = c
            else:
                u = c
                if P[P_UMAX] > 0.0:
                    u = min(max(u, -P[P_UMAX]), P[P_UMAX])
                iss = (u - P[P_KE] * wm) / P[P_RES]
            cur = iss + (cur - iss) * decay_i
            if P[P_IMAX] > 0.0:
                cur = min(max(cur, -P[P_IMAX]), P[P_IMAX])
            tm = kt * cur
            if not compliant:
                qd = wm / r
                # dynamic friction (advance states once per sub-step)
                fdyn = 0.0
                if dm != 0:
                    fm_last = K.friction_eval(km, pm, sm, wm, h, tm)
                    fdyn += fm_last
                if dl != 0:
                    fl_last = K.friction_eval(kl, pl, sl, qd, h, tm * r * eta)
                    fdyn += refl * fl_last
                ta = tm - P[P_BM] * wm - refl * (P[P_BL] * qd + P[P_KL] * q + P[P_GRAV] - P[P_TLOAD]) - fdyn
                wn, fs = _body_step(
                    wm,
                    ta,
                    jeq,
                    h,
                    skm,
                    pm,
                    sm,
                    skl,
                    pl,
                    sl,
                    r,
                    refl,
                    tm,
                    tm * r * eta,
                    max(P[P_BAND_M], P[P_BAND_L] * r),
                    stick,
                )
                if dm == 0:
                    fm_last = fs
                elif dl == 0:
                    fl_last = fs / refl
                wm = wn
                thm += h * wm
                q = thm / r
                wl = wm / r
            else:
                defl = thm / r - q
                gap = 0.5 * P[P_BACKLASH]
                if defl > gap:
                    dz = defl - gap
                elif defl < -gap:
                    dz = defl + gap
                else:
                    dz = 0.0
                tc = P[P_KC] * dz
                if dz != 0.0:
                    tc += P[P_CC] * (wm / r - wl)
                fdm = 0.0
                fdl = 0.0
                if dm != 0:
                    fdm = K.friction_eval(km, pm, sm, wm, h, tm)
                    fm_last = fdm
                if dl != 0:
                    fdl = K.friction_eval(kl, pl, sl, wl, h, tc)
                    fl_last = fdl
                tam = tm - P[P_BM] * wm - refl * tc - fdm
                tal = tc - P[P_BL] * wl - P[P_KL] * q - P[P_GRAV] + P[P_TLOAD] - fdl
                wmn, fsm = _body_step(
                    wm, tam, jm, h, skm, pm, sm, -1, pl, sl, r, 1.0, tm, 0.0, P[P_BAND_M], stick
                )
                wln, fsl = _body_step(
                    wl, tal, jl, h, skl, pl, sl, -1, pl, sl, 1.0, 1.0, tc, 0.0, P[P_BAND_L], stick
                )
                if dm == 0:
                    fm_last = fsm
                if dl == 0:
                    fl_last = fsl
                wm = wmn
                wl = wln
                thm += h * wm
                q += h * wl
        out[k, 0] = thm
        out[k, 1] = wm
        out[k, 2] = q
        out[k, 3] = wl
        out[k, 4] = cur
        out[k, 5] = fm_last
        out[k, 6] = fl_last
    x[X_THM] = thm
    x[X_WM] = wm
    x[X_Q] = q
    x[X_WL] = wl
    x[X_I] = cur


# ---------------------------------------------------------------------------------------------------
# plant
# ---------------------------------------------------------------------------------------------------
@dataclass(slots=True)
class Measurement:
    """What the sensors report after one control period (joint frame) plus the true values."""

    time: float
    position: float
    velocity: float
    effort: float
    motor_current: float
    true_position: float
    true_velocity: float
    true_effort: float
    true_motor_current: float
    motor_position: float
    motor_velocity: float
    friction_motor: float
    friction_load: float


_KIND_NONE = -1


class GearheadServoPlant:
    """Gearhead DC servo plant; ``step(command, dt) -> Measurement`` (see module docstring).

    ``command``: amplifier input (current mode, A per ``amplifier_gain``), joint torque [N*m or N]
    (torque mode) or armature voltage [V] (voltage mode). ``dt`` is the control period; the plant
    sub-steps internally at <= ``internal_dt`` (and finer if the friction stiffness needs it).
    """

    def __init__(self, params: PlantParams | Mapping[str, Any]) -> None:
        if isinstance(params, Mapping):
            cfg = dict(params)
            params = PlantParams.from_config(
                cfg.get("plant", cfg)
                if "plant" in cfg
                else {k: v for k, v in cfg.items() if not k.startswith("friction_")},
                cfg.get("friction_motor"),
                cfg.get("friction_load"),
            )
        if not isinstance(params, PlantParams):
            raise ParameterError(f"plant params = {params!r} must be PlantParams or a config mapping")
        self.params = params
        p = params
        P = np.zeros(P_SIZE)
        P[P_JM] = p.motor_inertia + p.transmission_inertia
        P[P_JL] = p.load_inertia
        P[P_R] = p.ratio
        P[P_ETA] = p.gear_efficiency
        P[P_BM] = p.motor_damping
        P[P_BL] = p.load_damping
        P[P_KL] = p.load_stiffness
        P[P_GRAV] = p.gravity_force
        P[P_TLOAD] = p.load_torque
        P[P_BACKLASH] = p.backlash
        P[P_KC] = p.coupling_stiffness
        P[P_CC] = p.coupling_damping
        P[P_KT] = p.torque_constant
        P[P_MODE] = 1.0 if p.actuation == "voltage" else 0.0
        P[P_TAUI] = p.current_time_constant
        P[P_RES] = p.resistance
        P[P_IND] = p.inductance
        P[P_KE] = p.back_emf_constant
        P[P_IMAX] = p.current_limit
        P[P_UMAX] = p.voltage_limit
        fm, fl = p.friction_motor, p.friction_load
        P[P_BAND_M] = fm.coefficients.get("dv", 0.0) if fm.name == "karnopp" else 0.0
        P[P_BAND_L] = fl.coefficients.get("dv", 0.0) if fl.name == "karnopp" else 0.0
        P[P_STICK] = 1.0 if p.stick_logic else 0.0
        P[P_COMPLIANT] = 1.0 if p.compliant else 0.0
        if p.compliant and p.load_inertia == 0:
            raise ParameterError(
                "plant.load_inertia = 0 with a compliant transmission: must be > 0 [kg*m^2 or kg]"
            )
        self._P = P
        self._km = _KIND_NONE if fm.name == "none" else fm.kernel_kind
        self._kl = _KIND_NONE if fl.name == "none" else fl.kernel_kind
        self._dm = 1 if fm.is_dynamic else 0
        self._dl = 1 if fl.is_dynamic else 0
        self._pm = fm.kernel_params.copy()
        self._pl = fl.kernel_params.copy()
        # stiffness-based sub-step limit: h * sqrt(k/J) <= 0.5 (semi-implicit Euler stable for < 2)
        k_motor = fm.max_stiffness() + fl.max_stiffness() / (p.ratio**2 * p.gear_efficiency)
        wn = math.sqrt(k_motor / p.reflected_inertia) if k_motor > 0 else 0.0
        if p.compliant:
            wn = max(
                wn,
                math.sqrt(p.coupling_stiffness / p.load_inertia),
                math.sqrt(p.coupling_stiffness / (p.ratio**2 * p.gear_efficiency * P[P_JM])),
            )
        self._h_max = min(p.internal_dt, 0.5 / wn if wn > 0 else p.internal_dt)
        self._out = np.zeros((1, 7))
        self._cmd = np.zeros(1)
        self.reset()

    # ------------------------------------------------------------------------------------------------
    def reset(self, position: float = 0.0, velocity: float = 0.0) -> None:
        """Reset to joint ``position``/``velocity``, relaxed friction, zero current; re-seed the noise."""
        p = self.params
        r = p.ratio
        self._x = np.zeros(X_SIZE)
        self._x[X_THM] = position * r
        self._x[X_WM] = velocity * r
        self._x[X_Q] = position
        self._x[X_WL] = velocity
        self._sm = p.friction_motor.initial_state().copy()
        self._sl = p.friction_load.initial_state().copy()
        self._t = 0.0
        self._rng = np.random.default_rng(p.seed)
        self._vfilt = velocity
        self._last_pos = None
        self._cmd_q: deque = deque()
        self._meas_q: deque = deque()
        self._dt = None
        self._last_dt = None

    @property
    def time(self) -> float:
        return self._t

    @property
    def state(self) -> dict:
        """True state: motor angle/velocity, joint position/velocity, current, friction states."""
        x = self._x
        return {
            "motor_position": x[X_THM],
            "motor_velocity": x[X_WM],
            "position": x[X_Q],
            "velocity": x[X_WL],
            "motor_current": x[X_I],
            "friction_motor_state": self._sm.copy(),
            "friction_load_state": self._sl.copy(),
            "time": self._t,
        }

    def substeps(self, dt: float) -> tuple[int, float]:
        """Number of internal sub-steps and their length for a control period ``dt``."""
        n = max(1, math.ceil(dt / self._h_max - 1e-9))
        return n, dt / n

    def _current_ref(self, command: float) -> float:
        p = self.params
        if p.actuation == "current":
            return p.amplifier_gain * command
        if p.actuation == "torque":
            return command / (p.torque_constant * p.ratio * p.gear_efficiency)
        return command

    def step(self, command: float, dt: float) -> Measurement:
        """Apply ``command`` for one control period ``dt`` and return the sensor readings at its end."""
        if dt != self._last_dt:
            check_real("plant.dt", dt, 0.0, lo_open=True, unit="s")
            self._n_sub, self._h = self.substeps(dt)
            self._last_dt = dt
            self._da = round(self.params.actuation_delay / dt)
            self._dmeas = round(self.params.measurement_delay / dt)
        command = float(command)
        if not abs(command) <= MAX_COMMAND:
            raise ParameterError(
                f"plant command = {command:g} is out of range: must be finite with |command| <= {MAX_COMMAND:g} "
                f"[{_COMMAND_UNITS[self.params.actuation]}]"
            )
        c = self._current_ref(command)
        if self._da:
            self._cmd_q.append(c)
            c = self._cmd_q.popleft() if len(self._cmd_q) > self._da else 0.0
        self._cmd[0] = c
        self._run(self._cmd, self._n_sub, self._h, self._out)
        self._t += dt
        m = self._measure(dt)
        if self._dmeas:
            self._meas_q.append(m)
            if len(self._meas_q) > self._dmeas:
                return self._meas_q.popleft()
            first = self._meas_q[0]
            return first
        return m

    def _measure(self, dt: float) -> Measurement:
        p = self.params
        o = self._out[0].tolist()
        thm, wm, q, wl, cur = o[0], o[1], o[2], o[3], o[4]
        r = p.ratio
        out_gain = p.torque_constant * r * p.gear_efficiency
        # encoder
        if p.encoder_cpr > 0:
            shaft = thm if p.encoder_location == "motor" else q
            cnt_per_rad = p.encoder_cpr * p.encoder_ratio / (2.0 * math.pi)
            x = shaft * cnt_per_rad
            shaft_q = (
                math.floor(x) / cnt_per_rad if math.isfinite(x) else shaft
            )  # no crash on a diverged state
            pos = shaft_q / r if p.encoder_location == "motor" else shaft_q
        else:
            pos = q
        if self._last_pos is None:
            vraw = wl
        else:
            vraw = (pos - self._last_pos) / dt
        self._last_pos = pos
        if p.velocity_filter_hz > 0:
            a = 1.0 - math.exp(-2.0 * math.pi * p.velocity_filter_hz * dt)
            self._vfilt += a * (vraw - self._vfilt)
            vel = self._vfilt
        else:
            vel = vraw
        im = cur + p.current_offset
        if p.current_noise_std > 0:
            im += p.current_noise_std * self._rng.standard_normal()
        return Measurement(
            self._t,
            pos,
            vel,
            out_gain * im,
            im,
            q,
            wl,
            out_gain * cur,
            cur,
            thm,
            wm,
            o[5],
            o[6],
        )

    def simulate(self, commands: Any, dt: float) -> dict[str, np.ndarray]:
        """Step through a command sequence; returns arrays keyed by the Measurement field names."""
        cmds = np.asarray(commands, dtype=float).ravel()
        names = Measurement.__slots__
        out = {n: np.empty(cmds.size) for n in names}
        for k, c in enumerate(cmds):
            m = self.step(c, dt)
            for n in names:
                out[n][k] = getattr(m, n)
        return out

    def _run(self, cmds: np.ndarray, n_sub: int, h: float, out: np.ndarray) -> None:
        """Advance the compiled loop over ``cmds`` (one control period each) writing ``out`` rows."""
        _plant_run(
            self._P, self._x, self._km, self._pm, self._sm, self._dm, self._kl, self._pl, self._sl, self._dl,
            cmds, n_sub, h, out,
        )  # fmt: skip

    def run_open_loop(self, commands: Any, dt: float) -> np.ndarray:
        """Fast path: run a whole command sequence in one compiled call (no sensing, no delays).

        Returns an (n, 7) array: motor angle, motor velocity, joint position, joint velocity, current,
        motor-side friction, load-side friction (true values at the end of each control period).
        """
        raw = np.asarray(commands, dtype=float).ravel()
        if raw.size and not np.max(np.abs(raw)) <= MAX_COMMAND:
            raise ParameterError(
                f"plant commands = {raw[~(np.abs(raw) <= MAX_COMMAND)][0]:g} is out of range: must be finite "
                f"with |command| <= {MAX_COMMAND:g} [{_COMMAND_UNITS[self.params.actuation]}]"
            )
        cmds = np.ascontiguousarray([self._current_ref(c) for c in raw])
        n_sub, h = self.substeps(dt)
        out = np.empty((cmds.size, 7))
        self._run(cmds, n_sub, h, out)
        self._t += dt * cmds.size
        return out
