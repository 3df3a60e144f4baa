"""Feedforward of the identified joint load (:mod:`friction_ros.core.friction.joint_load`) and of
the learned residual (:mod:`friction_ros.core.friction.learned_residual`).

Per period, with ``q`` the measured position, ``a_d`` the reference acceleration and ``J_hat`` the
controller's ``inertia`` (REP-103 signs, SI)::

    tau_L = tau_load(q) + g_c s(v) (k_L |tau_load(q) + J_hat a_d| + R(q))
    tau_load(q) = gravity sin(q + gravity_phase) + offset + spring q
    s(v) = w_ff sgn_eps(theta_dot_d) + w_fb sgn_eps(theta_dot_hat),  sgn_eps(v) = clip(v / eps, -1, 1)

* ``tau_load(q)`` at the measured position is gravity compensation (PD + gravity compensation,
  Takegaki & Arimoto 1981, J. Dyn. Sys. Meas. Control 103(2): the equilibrium at the reference is
  kept without an integrator). It is a load, not friction: it stays on when friction compensation
  is switched off.
* The load-dependent friction ``k_L |tau_tr|`` and the position ripple ``R(q)`` are friction: they
  take the gain ``g_c`` and the weights ``(w_ff, w_fb)`` of ``compensation.source``
  (:attr:`~.compensation.FrictionCompensator.weights`: feedforward at the reference velocity,
  feedback / observer at the measured one, blended both), and are off for source ``none`` and
  after a limit-cycle fallback. With ``g_c = 1`` and source feedforward ``tau_L`` equals
  :meth:`JointLoad.torque_scalar(q, theta_dot_d, a_d, J_hat) <friction_ros.core.friction.joint_load.JointLoad.torque_scalar>`.

Math only per period (one ``sin``, plus a ``cos``/``sin`` pair per ripple harmonic): ~1 us.

The learned residual (section ``residual``, :class:`LearnedFeedforward`) adds
``tau_r = g_c r(theta, theta_dot_hat, u_{k-1})``: the map's ``step`` with the measured position and
velocity and the previous command (causal), bounded by the map's own clip to its training residual
range. It is friction: gain ``g_c``, off for source ``none`` and after a fallback. A non-finite
output gives 0 (never NaN on the command) and is counted (``nonfinite``); the first one leaves a
``note`` for the node to log once.
"""

from __future__ import annotations

from friction_ros.core.friction.joint_load import JointLoad
from friction_ros.core.friction.learned_residual import LearnedResidual


class LoadFeedforward:
    """``tau_L`` of the module docstring for one joint; ``weights = (g_c w_ff, g_c w_fb)``."""

    def __init__(self, load: JointLoad, weights: tuple[float, float], inertia: float):
        self.load = load
        self.active = load.active
        self.eps = float(load.eps)
        self.has_friction = bool(load.load_friction or any(load.ripple_cos) or any(load.ripple_sin))
        self.w_ff, self.w_fb = (float(x) for x in weights)
        self.inertia = float(inertia)

    def torque(self, q: float, v_ref: float, v_meas: float, a_ref: float, friction_on: bool) -> float:
        """``tau_L`` [N*m]; ``friction_on`` False drops the friction part (fallback)."""
        tl, level = self.load.scalar_parts(q, a_ref, self.inertia)
        if not (friction_on and self.has_friction):
            return tl
        eps = self.eps
        s = 0.0
        if self.w_ff:
            s += self.w_ff * min(max(v_ref / eps, -1.0), 1.0)
        if self.w_fb:
            s += self.w_fb * min(max(v_meas / eps, -1.0), 1.0)
        return tl + s * level


class LearnedFeedforward:
    """``tau_r`` of the module docstring: ``gain`` times the residual map, non-finite outputs -> 0."""

    def __init__(self, residual: LearnedResidual, gain: float):
        self.residual = residual
        self.gain = float(gain)
        self.nonfinite = 0
        self.note = ""
        self.period = residual.period

    def match_period(self, dt: float) -> None:
        """The map's velocity filters assume its ``dt`` (the training log's sample period): a
        controller running at another period rebuilds the map with its own (history restarts), so
        the filters keep their time constants in seconds."""
        if dt > 0.0 and abs(dt - self.period) > 1e-6 * self.period:
            self.residual = LearnedResidual.from_config({**self.residual.to_config(), "dt": float(dt)})
            self.period = float(dt)

    def reset(self) -> None:
        self.residual.reset()

    def torque(self, q: float, v: float, previous_command: float, t: float = 0.0, dt: float = 0.0) -> float:
        """``tau_r`` [N*m] for this period of ``dt`` [s] (advances the map's history)."""
        if dt and dt != self.period:
            self.match_period(dt)
        r = self.residual.step(q, v, previous_command)
        if r - r == 0.0:  # finite (nan - nan and inf - inf are nan)
            return self.gain * r
        self.nonfinite += 1
        if self.nonfinite == 1:
            self.note = (
                f"learned residual returned {r!r} at t = {t:.3f} s (q = {q:.6g} rad, v = {v:.6g} rad/s): "
                "its term is set to 0 for every such sample (count in diagnostics residual_nonfinite)"
            )
        return 0.0
