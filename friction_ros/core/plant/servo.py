"""Gearhead DC servo plant (pure core): mechanics, actuation, friction and realistic sensing.

Model (motor frame, SI; ``r`` = gear_ratio * (2*pi/lead_pitch for linear axes) = motor rad per joint
unit, ``eta`` = transmission efficiency applied to reflected load quantities as in Tilakaratna et al. 2004
eqs. (2)-(4)):

* rigid transmission: ``J_eq w' = Kt i - Bm w - (Bl w/r + Kl q + m_g - T_load)/(r eta) - F_m(w)
  - F_l(w/r)/(r eta)``, ``J_eq = J_motor + J_transmission + J_load/(r^2 eta)`` (Tilakaratna et al. 2004 eq. (1)-(4),
  ABB M19-S paper eq. (1));
* gravity: ``m_g = gravity_force + gravity sin(q + gravity_phase)``: a constant load towards -q
  (a vertical linear axis) plus a pendulum load ``m g l sin(q + q0)`` [N*m] (a robot joint that
  lifts a link; ``gravity`` = m g l, ``gravity_phase`` = q0: the link hangs at q = -q0, is upright
  at q = pi - q0, and a joint held with zero torque sags towards the hanging position). Both act
  on the joint side (the load body of a compliant transmission); ``gravity`` = 0 (default) leaves
  the term out entirely, so plants without it are bit-identical to before it existed;
* backlash / compliant transmission (``coupling_stiffness > 0``): two bodies coupled by a dead-zone
  spring-damper of total gap ``backlash`` (joint units);
* actuation: ``current`` (command = amplifier input, i_ref = amplifier_gain*cmd, current loop as a
  first-order lag with ``current_time_constant``, Tilakaratna et al. 2004 eq. (9)), ``torque`` (command = joint
  torque, i_ref = cmd/(Kt r eta), same lag) or ``voltage`` (L di/dt = u - R i - Ke w; L = 0 gives
  AI friction chapter's K/(s(tau s + 1)), see :func:`~friction_ros.core.plant.params.voltage_params_from_transfer_function`);
* friction: any model of :mod:`friction_ros.core.friction` at the motor and/or load side. Static
  models get exact stick logic (GKF rule of AI friction chapter eq. (4) at rest, zero-crossing detection,
  Karnopp band when the model is ``karnopp``); dynamic models use their exact/implicit updates;
* sensing (:mod:`friction_ros.core.plant.sensing`): encoder quantisation (quadrature counts/rev,
  optional belt ratio), velocity from a filtered difference, current noise/offset, measurement and
  actuation delays, all seeded.

The inner loop (sub-steps inside one control period) runs in one compiled numba call
(:mod:`friction_ros.core.plant.kernels`).

:attr:`GearheadServoPlant.command_scale` converts a joint torque into the plant's command: current
mode 1 / (amplifier_gain Kt r eta), torque mode 1, voltage mode R / (Kt r eta) (quasi-static, the
back-EMF is part of the plant's linear dynamics, AI friction chapter eq. (12)).

Commands are plausibility-checked: a NaN/inf command or one with ``|command| >``
:data:`MAX_COMMAND` (1e9 A, V or N*m: no amplifier reaches it) raises ParameterError and leaves the
plant unchanged, so a finite but absurd command (1e308) cannot overflow the state to inf/NaN.

A plant is built from a preset (:meth:`friction_ros.core.presets.Preset.make_plant`), the one way
from a preset or a parameter file to a plant.
"""

from __future__ import annotations

import math
from collections import deque
from typing import Any

import numpy as np

from friction_ros.core.plant.kernels import (
    P_JM,
    X_I,
    X_Q,
    X_SIZE,
    X_THM,
    X_WL,
    X_WM,
    pack_params,
    run_control_periods,
)
from friction_ros.core.plant.params import PlantParams
from friction_ros.core.plant.sensing import Measurement, Sensors
from friction_ros.core.validation import ParameterError, check_real

_COMMAND_UNITS = {"current": "A", "torque": "N*m", "voltage": "V"}
#: Largest |command| the plant accepts (its own unit: A, N*m or V); see the module docstring.
MAX_COMMAND = 1.0e9

_KIND_NONE = -1


class GearheadServoPlant:
    """Gearhead DC servo plant; ``step(command, dt) -> Measurement`` (see module docstring).

    ``command``: amplifier input (current mode, A per ``amplifier_gain``), joint torque [N*m or N]
    (torque mode) or armature voltage [V] (voltage mode). ``dt`` is the control period; the plant
    sub-steps internally at <= ``internal_dt`` (and finer if the friction stiffness needs it).
    """

    def __init__(self, params: PlantParams) -> None:
        if not isinstance(params, PlantParams):
            raise ParameterError(
                f"plant params = {params!r} must be PlantParams (a preset or a parameter file builds "
                "one: friction_ros.core.presets.resolve_preset)"
            )
        self.params = p = params
        if p.compliant and p.load_inertia == 0:
            raise ParameterError(
                "plant.load_inertia = 0 with a compliant transmission: must be > 0 [kg*m^2 or kg]"
            )
        self._P = P = pack_params(p)
        fm, fl = p.friction_motor, p.friction_load
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
        self._sensors = Sensors(p)
        self.reset()

    @property
    def command_scale(self) -> float:
        """Joint torque -> plant command factor (see the module docstring)."""
        p = self.params
        gain = p.torque_constant * p.ratio * p.gear_efficiency
        if p.actuation == "current":
            return 1.0 / (p.amplifier_gain * gain)
        if p.actuation == "voltage":
            return p.resistance / gain
        return 1.0

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
        self._sensors.reset(velocity)
        self._cmd_q: deque = deque()
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
            self._sensors.set_period(dt)
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
        return self._sensors.read(self._t, self._out[0].tolist(), dt)

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
        run_control_periods(
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
