"""``CompensatingController``: one façade over every controller mode, built from a config dict.

Per period (ABB M19-S paper A.4.1 Fig. 6 structure, generalised)::

    e      = theta_d - theta,   e_dot = theta_dot_d - theta_dot_hat      (derivative on measurement)
    u      = feedback(mode) + feedforward_gain theta_dot_d + J_hat theta_ddot_d
             + tau_f_ff(theta_dot_d) + tau_f_fb(theta_dot_hat) + load_feedforward
             + tau_L(theta, theta_dot_d, theta_dot_hat, theta_ddot_d) + tau_r(theta, theta_dot_hat, u_{k-1})
    command = clamp(u, u_clamp, rate limit)

``tau_L`` (section ``load``, :mod:`.load_compensation`): the identified joint load
``tau_load(theta) = gravity sin(theta + gravity_phase) + offset + spring theta`` at the measured
position (gravity compensation) plus ``g_c s(v) (k_L |tau_load + J_hat theta_ddot_d| + R(theta))``,
the load-dependent and position-dependent friction with the velocity (and weights) of
``friction.source``; 0 with the default (all-zero) section. ``tau_r`` (section ``residual``): the
learned residual map's ``g_c r`` from the measured motion and the previous command, bounded, 0
for a non-finite output (counted: ``residual_nonfinite``, ``residual_note``); 0 for kind none.

Limits (:mod:`.command_safety`): the command is clamped to ``+-effort_limit`` (the joint's torque or
force limit) and to ``u_clamp_min/max`` when tighter; the compensating_controller node refuses to start
without one of them. Without any (the pure core, e.g. a simulation script) the command stays within
+-1e6 N*m (:data:`friction_ros.core.input_gate.PLAUSIBLE_EFFORT`). Whatever the gains and inputs, the
command is finite: a reference that is not finite or lies beyond ``position_min/max``,
``velocity_limit`` or ``acceleration_limit`` is replaced by the last good reference position at rest;
a non-finite friction or load term is dropped (its states reset); a feedback law that overflows is
reset and the last command held. Each such event is recorded in ``guard`` (a
:class:`.command_safety.TermGuard`) for the node's log and diagnostics.
In ``pid`` mode the PID integrator is kept
inside the same clamp and, by default, only integrates while the output is not saturated
(``pid.antiwindup_strategy`` = conditional_integration), so a saturated transient does not wind up.

``theta_dot_hat`` is the measured velocity (``velocity_source = measured``) or the filtered
backward difference of the measured position (``differentiated``, GA friction thesis 2002 section 6.1, with the
lost-bit hold filter ``position_jump_limit``: a sample that jumps more than the limit is replaced
by the previous one).

Modes (``mode``):

``pid``             PID (control_toolbox names, section ``pid``); ABB M19-S paper's PD (p = 200,
                    d = 0.15), AI friction chapter's PD + model compensation, GA friction thesis 2002's saturated unity
                    feedback (p = 1, friction feedback gain 0.95, u_clamp).
``cascade``         ABB M19-S paper classical cascade (section ``cascade``).
``dnpf``            ABB M19-S paper DNPF (section ``dnpf``).
``gain_scheduling`` ABB M19-S paper gain scheduling (section ``gain_scheduling``).
``sliding_mode``    Chatterjee et al. 2017 sliding mode / relay (section ``sliding_mode``).
``compensation_only`` an add-on to an existing arm controller (a trajectory, impedance or vendor
                    controller): ``u = compensation_scale (tau_f_ff + tau_f_fb + load_feedforward
                    + tau_L + tau_r)``, no feedback of its own. The feedback-path stability bound
                    uses ``pid.p`` / ``pid.d`` as the arm controller's stiffness and damping (set
                    them to its gains; the default 0 limits every presliding feedback term).

``compensation_enabled`` (run-time switch, the node's ``~/set_feedforward_control`` service): when
False every compensation term (friction, load, learned residual, the constant load feedforward in
compensation_only) is 0; the friction and residual states keep running, so switching on again
is bumpless.

Friction compensation (section ``friction``, :mod:`.compensation`) is added in every mode.
Safety (feedback paths only, i.e. sources feedback / blended / observer):

* stability bound (:meth:`.compensation.FrictionCompensator.bound_feedback`, ``friction.feedback_bound``
  f = 0.5): the presliding stiffness and damping fed back satisfy ``g w_fb k_hat <= f K_p`` and
  ``g w_fb sigma1 <= f K_d`` with (K_p, K_d) from :func:`loop_gains`; ``feedback_bound_note`` says
  what was limited ('' when nothing);
* run-time compensation watch (:mod:`.compensation_watch`: limit cycles, over-compensation, an
  unstable plain loop; ``limit_cycle_*`` keys): friction compensation switched off and latched
  (``compensation_fallback``, ``fallback_reason``); the friction part of ``tau_L`` and ``tau_r`` go with
  it, ``tau_load(theta)`` (a load, not friction) stays.

The ROS node is a thin adapter: ``update(t, reference, measured, dt) -> command`` and ``terms``
(a :class:`ControllerTerms`, the fields of friction_msgs/ControllerState).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

from friction_ros.core.config import Names, TypedConfig
from friction_ros.core.control.command_safety import JointLimits, TermGuard, check_reference_sample
from friction_ros.core.control.compensation import FrictionCompensator, model_of
from friction_ros.core.control.compensation_watch import CompensationWatch
from friction_ros.core.control.controller_config import (
    core_config,
    core_controller_config,
    merge_config,
    ros_controller_config,
)
from friction_ros.core.control.controller_terms import ControllerTerms
from friction_ros.core.control.load_compensation import LearnedFeedforward, LoadFeedforward
from friction_ros.core.control.pid import Pid
from friction_ros.core.control.schemes import DNPF, Cascade, GainScheduling, SlidingMode, loop_gains
from friction_ros.core.control.velocity_estimate import VelocityEstimator
from friction_ros.core.friction.joint_load import JointLoad
from friction_ros.core.friction.learned_residual import LearnedResidual
from friction_ros.core.input_gate import PLAUSIBLE_EFFORT
from friction_ros.core.validation import ParameterError


def controller_from_ros_parameters(
    values: Mapping[str, Any], names: Names | None = None
) -> tuple[CompensatingController, dict[str, Any]]:
    """compensating_controller ROS parameters (nested or dotted) -> (controller, reference config).

    The values become the controller's typed config (:func:`.controller_config.ros_controller_config`)
    once; every refused parameter is named as the user wrote it in the ROS layout
    (``compensation.gain``, ``friction.fc``; ``names`` maps the dotted keys, e.g. to per-joint names).
    """
    joint_type = values.get("joint_type", "revolute")
    controller = CompensatingController.from_config(ros_controller_config(values, names, joint_type))
    reference = values.get("reference")
    if reference is None:  # dotted names
        reference = {str(k)[10:]: v for k, v in values.items() if str(k).startswith("reference.")}
    return controller, dict(reference or {"type": "constant"})


class CompensatingController:
    """Controller façade; see the module docstring and :data:`.controller_config.CONTROLLER_DEFAULTS`."""

    _dt_checked: float | None = None  # the last period length compute() validated

    def __init__(self, config: Mapping[str, Any] | None = None):
        """From a config dict in the core layout (nested or dotted), typed once
        (:func:`.controller_config.core_controller_config`)."""
        self._build(core_controller_config(config))

    @classmethod
    def from_config(cls, config: TypedConfig) -> CompensatingController:
        """From the typed config (:func:`.controller_config.ros_controller_config`), as it is: each
        part takes its section; messages name its parameters (``config.path``)."""
        self = cls.__new__(cls)
        self._build(config)
        return self

    @classmethod
    def from_parameters(cls, params: Mapping[str, Any]) -> CompensatingController:
        """Build from flat ROS parameters with dotted names (``pid.p``, ``friction.source`` ...)."""
        return cls(params)

    def _build(self, c: TypedConfig) -> None:
        """The parts from their typed sections; only the rules across sections are checked here."""
        at = c.path  # dotted key -> the name messages give it
        mode, inertia = c.mode, c.inertia
        umax, umin = c.u_clamp_max, c.u_clamp_min
        if umin >= umax:
            raise ParameterError(
                f"{at('u_clamp_min')} = {umin:g} is out of range: must be "
                + (f"<= {umax:g} [N*m]" if umin > umax else "< u_clamp_max")
            )
        try:
            limits = JointLimits(
                c.effort_limit, c.position_min, c.position_max, c.velocity_limit, c.acceleration_limit
            )
        except ParameterError as exc:  # JointLimits names its keys without the section
            raise ParameterError(f"{at('')}.{exc}" if at("") else str(exc)) from None
        umin, umax = limits.command_bounds(umin, umax)
        if umax <= 0.0 or umin >= 0.0:
            raise ParameterError(
                f"{at('u_clamp_min')}/u_clamp_max = {umin:g}/{umax:g} must hold zero torque "
                "inside (u_clamp_min < 0 < u_clamp_max)"
            )
        # a running node needs a finite limit (see limits_given); the pure core keeps a plausibility bound
        limits_given = math.isfinite(umin) and math.isfinite(umax)
        umin, umax = max(umin, -PLAUSIBLE_EFFORT), min(umax, PLAUSIBLE_EFFORT)
        lc_w, lc_h = c.limit_cycle_window, c.limit_cycle_hold
        if lc_w + lc_h > 0.1:
            raise ParameterError(
                f"{at('limit_cycle_window')} + limit_cycle_hold = {lc_w + lc_h:g} is out of range: "
                "must be <= 0.1 [s] (the fallback must come within 0.1 s of an established limit cycle)"
            )
        pid = Pid.from_config(c.pid)
        model = model_of(c.friction)
        scheme = None
        if mode == "dnpf":
            scheme = DNPF(c.dnpf)
        elif mode == "gain_scheduling":
            scheme = GainScheduling(c.gain_scheduling, model)
        elif mode == "cascade":
            scheme = Cascade(c.cascade)
        elif mode == "sliding_mode":
            scheme = SlidingMode(c.sliding_mode)
        # stability bound of the feedback path against the loop's linear gains (loop_gains)
        kp, kd = loop_gains(mode, pid, scheme)
        friction = FrictionCompensator.from_config(c.compensation, model, at("friction"), (kp, kd))
        load = JointLoad.from_section(c.load)
        residual = LearnedResidual.from_section(c.residual)
        # everything validated: commit
        self._config = c
        self.mode = mode
        self.feedforward_gain = c.feedforward_gain
        self.inertia = inertia
        self.load_feedforward = c.load_feedforward
        self.compensation_scale = c.compensation_scale
        self.u_clamp_max, self.u_clamp_min = umax, umin
        self.limits, self.limits_given = limits, limits_given
        self.guard = TermGuard()  # non-finite terms dropped (see command_safety)
        self._hold_ref: float | None = None  # the last reference position that passed the check
        self.rate_limit = c.rate_limit
        self.velocity = VelocityEstimator(
            c.velocity_source, c.velocity_filter_time_constant, c.position_jump_limit
        )
        self.pid = pid
        self.friction = friction
        self.scheme = scheme
        wff, wfb = friction.weights
        self.load = LoadFeedforward(load, (friction.gain * wff, friction.gain * wfb), inertia)
        self._load_on = self.load.active
        # the residual is friction: off with source none (and after a fallback, see compute)
        self.residual = (
            LearnedFeedforward(residual, friction.gain)
            if residual is not None and friction.source != "none" and friction.gain > 0.0
            else None
        )
        self._prev_cmd: float | None = None
        self._addon = mode == "compensation_only"
        if not hasattr(self, "compensation_enabled"):
            self.compensation_enabled = True  # kept across a rebuild (a parameter change)
        self.terms = ControllerTerms(mode=mode)
        self.loop_stiffness, self.loop_damping = kp, kd
        self.feedback_bound_note = friction.bound_note
        # only a feedback path puts the compensation inside the loop: a feedforward term is a function
        # of the reference and cannot make the loop oscillate by itself (so it is not watched for limit
        # cycles); the load's friction part fed back from the measured velocity and the learned residual,
        # a function of the measured motion, are such paths too. Over-compensation is watched whenever
        # friction is compensated and the controller has a feedback law of its own.
        feedback_path = (
            (friction.model is not None or self.load.has_friction) and self.load.w_fb > 0.0
        ) or self.residual is not None
        self.watch = CompensationWatch(
            enabled=c.limit_cycle_detection,
            limit_cycle={
                "min_frequency": c.limit_cycle_min_frequency,
                "min_amplitude": c.limit_cycle_min_amplitude,
                "window": lc_w,
                "hold": lc_h,
            },
            feedback_path=feedback_path,
            overcompensation=friction.model is not None and mode != "compensation_only",
            command_range=umax - umin,
        )

    # the watch's latched state (see compensation_watch)
    @property
    def limit_cycle(self):
        return self.watch.limit_cycle

    @property
    def compensation_fallback(self) -> bool:
        return self.watch.fallback

    @compensation_fallback.setter
    def compensation_fallback(self, value: bool) -> None:
        self.watch.fallback = bool(value)

    @property
    def loop_unstable(self) -> bool:
        return self.watch.loop_unstable

    @property
    def fallback_reason(self) -> str:
        return self.watch.reason

    @property
    def residual_nonfinite(self) -> int:
        """Periods whose learned residual was not finite (its term was set to 0)."""
        return 0 if self.residual is None else self.residual.nonfinite

    @property
    def residual_note(self) -> str:
        """What the first non-finite learned residual was ('' when none)."""
        return "" if self.residual is None else self.residual.note

    def config(self) -> dict[str, Any]:
        """The effective configuration in the core layout (nested dict; round-trips through the
        constructor)."""
        cfg = core_config(self._config)
        cfg["pid"] = self.pid.config()
        cfg["friction"] = self.friction.config()
        cfg["load"] = self.load.load.to_config()
        return cfg

    def set_pid_gains(self, **gains: Any) -> None:
        """Change PID parameters at run time (control_toolbox names), validated; the integrator,
        filters and model states are kept (bumpless for gain changes)."""
        self.pid.set_gains(**gains)
        if self.scheme is None:  # the feedback-path bound follows the loop gains
            self.loop_stiffness, self.loop_damping = loop_gains(self.mode, self.pid, None)
            self.feedback_bound_note = self.friction.bound_feedback(self.loop_stiffness, self.loop_damping)

    def reconfigure(self, changes: Mapping[str, Any]) -> None:
        """Apply parameter changes (nested or dotted keys, core layout); all-or-nothing, resets the
        states."""
        self._build(core_controller_config(merge_config(self.config(), changes)))

    def set_coefficients(self, coefficients: Mapping[str, Any]) -> None:
        """Hot-swap the friction model without a restart.

        ``coefficients`` is either a full model config (``{"model": "lugre", "sigma0": ...}``,
        replaces the model) or some coefficients of the current model (``{"fc": 0.3}``).
        Validated first: on error a ParameterError is raised and nothing changes.
        """
        if not isinstance(coefficients, Mapping):
            raise ParameterError(f"coefficients = {coefficients!r} must be a mapping")
        if "model" in coefficients:
            self.friction.set_model(dict(coefficients))
        else:
            self.friction.set_coefficients(**coefficients)
        self.feedback_bound_note = self.friction.bound_note

    def reset(self) -> None:
        """Clear integrators, filters, observer and dynamic-model states."""
        self.pid.reset()
        self.friction.reset()
        self.velocity.reset()
        if self.scheme is not None:
            self.scheme.reset()
        if self.residual is not None:
            self.residual.reset()
        self._prev_cmd = None
        self._dt_checked = None

    # -- the control law ---------------------------------------------------------------------------
    def compute(self, t: float, reference, measured, dt: float) -> ControllerTerms:
        """One control period; returns all terms (also kept in ``self.terms``)."""
        if dt != self._dt_checked:  # checked once per period length, not every period
            if not (isinstance(dt, (int, float)) and dt > 0.0 and math.isfinite(dt)):
                raise ParameterError(f"controller: dt = {dt!r} is out of range: must be > 0 [s]")
            self._dt_checked = dt
        r_pos, r_vel, r_acc = reference
        r_pos, r_vel, r_acc = float(r_pos), float(r_vel), float(r_acc)
        m_pos = float(measured[0])
        m_vel = None if len(measured) < 2 or measured[1] is None else float(measured[1])
        pos, vel = self.velocity.update(m_pos, m_vel, dt)
        guard = self.guard
        why = check_reference_sample(self.limits, r_pos, r_vel, r_acc)
        if why:  # hold the last good reference position (or where the joint is), at rest
            guard.record("reference", why, t)
            r_pos = self._hold_ref if self._hold_ref is not None else pos
            r_vel = r_acc = 0.0
        else:
            self._hold_ref = r_pos
        e = r_pos - pos
        edot = r_vel - vel
        addon, on = self._addon, self.compensation_enabled
        ff_inertia = 0.0 if addon else self.inertia * r_acc
        ff_vel = (0.0 if addon else self.feedforward_gain * r_vel) + (self.load_feedforward if on else 0.0)
        if self.compensation_fallback:
            f_ff = f_fb = 0.0
        else:
            f_ff, f_fb = self.friction.update(r_vel, vel, dt, error=e)
            if not (math.isfinite(f_ff) and math.isfinite(f_fb)):  # dropped, its states restart
                guard.record("friction compensation", f"friction compensation was {f_ff!r}/{f_fb!r}", t)
                self.friction.reset()
                f_ff = f_fb = 0.0
            if not on:
                f_ff = f_fb = 0.0
        tau_l = tau_r = 0.0
        if self._load_on and on:
            tau_l = self.load.torque(pos, r_vel, vel, r_acc, not self.compensation_fallback)
            if not math.isfinite(tau_l):
                guard.record("load feedforward", f"load feedforward was {tau_l!r}", t)
                tau_l = 0.0
        learned = self.residual is not None and not self.compensation_fallback
        if learned:
            prev = 0.0 if self._prev_cmd is None else self._prev_cmd
            tau_r = self.residual.torque(pos, vel, prev, t, dt)
            if not on:
                tau_r = 0.0
        lower, upper = -math.inf, math.inf
        if self._prev_cmd is not None and math.isfinite(self.rate_limit):
            lower = self._prev_cmd - self.rate_limit * dt
            upper = self._prev_cmd + self.rate_limit * dt
        lo = max(self.u_clamp_min, lower)
        hi = min(self.u_clamp_max, upper)
        if addon:
            k = self.compensation_scale
            f_ff, f_fb, tau_l, tau_r, ff_vel = k * f_ff, k * f_fb, k * tau_l, k * tau_r, k * ff_vel
            p_t = i_t = d_t = s_vff = s_fb = 0.0
            unlimited = ff_vel + f_ff + f_fb + tau_l + tau_r
            if lo > hi:
                lo = hi = min(max(0.5 * (lower + upper), self.u_clamp_min), self.u_clamp_max)
            cmd = min(max(unlimited, lo), hi)
            sat = cmd != unlimited
        elif self.scheme is None:
            offset = ff_inertia + ff_vel + f_ff + f_fb
            if self._load_on:
                offset += tau_l
            if learned:
                offset += tau_r
            out = self.pid.update(
                e,
                dt,
                error_dot=edot,
                offset=offset,
                lower=lo,
                upper=hi,
                integral_lower=self.u_clamp_min,
                integral_upper=self.u_clamp_max,
            )
            p_t, i_t, d_t, s_vff, s_fb = out.p_term, out.i_term, out.d_term, 0.0, 0.0
            unlimited, cmd, sat = out.unlimited, out.command, out.saturated
        else:
            s = self.scheme.compute(e, edot, (r_pos, r_vel, r_acc), (pos, vel), dt)
            p_t, i_t, d_t, s_vff, s_fb = (
                s.p_term,
                s.i_term,
                s.d_term,
                s.velocity_feedforward,
                s.friction_feedback,
            )
            unlimited = (
                s.p_term
                + s.i_term
                + s.d_term
                + s.velocity_feedforward
                + ff_vel
                + ff_inertia
                + f_ff
                + f_fb
                + s.friction_feedback
            )
            if self._load_on:
                unlimited += tau_l
            if learned:
                unlimited += tau_r
            if lo > hi:
                lo = hi = min(max(0.5 * (lower + upper), self.u_clamp_min), self.u_clamp_max)
            cmd = min(max(unlimited, lo), hi)
            sat = cmd != unlimited
        if not math.isfinite(cmd):  # the feedback law overflowed: restart it, hold the last command
            guard.record("feedback", f"feedback command was {unlimited!r}", t)
            self.pid.reset()
            if self.scheme is not None:
                self.scheme.reset()
            prev = 0.0 if self._prev_cmd is None else self._prev_cmd
            cmd, sat = min(max(prev, self.u_clamp_min), self.u_clamp_max), True
        self._prev_cmd = cmd
        if self.watch.loop_unstable:  # the loop oscillates without compensation: damp the joint to rest
            hold = tau_l + (self.load_feedforward if on else 0.0) - self.loop_damping * vel
            cmd, sat = min(max(hold, self.u_clamp_min), self.u_clamp_max), True
            self.pid.reset()
        else:
            self.watch.update(t, e, cmd, r_vel, pos, dt, r_pos, f_ff + f_fb + s_fb, p_t + i_t + d_t)
        self.terms = ControllerTerms(
            time=float(t),
            mode=self.mode,
            reference_position=r_pos,
            reference_velocity=r_vel,
            reference_acceleration=r_acc,
            position=pos,
            velocity=vel,
            error=e,
            error_dot=edot,
            p_term=p_t,
            i_term=i_t,
            d_term=d_t,
            velocity_feedforward=ff_vel + s_vff,
            inertia_feedforward=ff_inertia,
            friction_feedforward=f_ff,
            friction_feedback=f_fb + s_fb,
            load_feedforward=tau_l,
            learned_feedforward=tau_r,
            command_unlimited=unlimited,
            command=cmd,
            saturated=bool(sat),
            compensation_fallback=self.compensation_fallback,
        )
        return self.terms

    def update(self, t: float, reference, measured, dt: float) -> float:
        """One control period: ``reference = (pos, vel, acc)``, ``measured = (pos, vel|None)``.

        Returns the command (N*m, or A when the plant is current-driven and gains are in A);
        all terms are in ``self.terms``.
        """
        return self.compute(t, reference, measured, dt).command
