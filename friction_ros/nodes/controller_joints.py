"""One joint of the compensating_controller node: its controller, reference, input gate, its
ControllerState message and its diagnostics status (the node itself:
:mod:`friction_ros.nodes.compensating_controller`)."""

from __future__ import annotations

import dataclasses
import time

from friction_ros.core.control.command_safety import JointLimits
from friction_ros.core.control.controller import ControllerTerms
from friction_ros.core.experiment.references import reference_from_config
from friction_ros.core.experiment.trajectory import TrajectoryReference
from friction_ros.core.input_gate import JointInputGate
from friction_ros.core.wire import ControllerStateEncoder
from friction_ros.nodes.diagnostics import ERROR, OK, WARN


class JointChannel:
    """One joint of the node: its controller, reference, plausibility gate and health."""

    def __init__(self, node, joint: str, values: dict, overrides: dict):
        """``node``: the compensating_controller node (its ``build_controller``, ``given_section``,
        ``values``, ``dt``; diagnostics are published on it)."""
        self.joint = joint
        self.values = values
        self.overrides = overrides
        self.controller, ref_cfg = node.build_controller(joint, values, overrides)
        self.reference = reference_from_config(ref_cfg)
        # add-on: the built-in generator counts only when a reference section was given
        self.has_reference = bool(node.given_section("reference")) or any(
            k.startswith("reference.") for k in overrides
        )
        self.trajectory: TrajectoryReference | None = None
        self.desired: tuple[float, float, float] | None = None  # from desired_joint_states
        # plausibility gate of the joint states (stamps, jumps, magnitudes): bad samples never
        # reach the controller's state (integrator, filters, observers, limit-cycle detector)
        self.gate = JointInputGate(joint, node.values.get("input_gate"), period=node.dt)
        self.state_encoder = ControllerStateEncoder(joint)
        self.command = 0.0
        self.compensation = 0.0
        self.last_state_wall = time.monotonic()
        self.timed_out = False
        self.fallback_logged = ""  # the fallback reason last logged
        self.residual_logged = False
        self.diag_rejected = 0
        self.waiting_logged = False

    @property
    def reference_limits(self) -> JointLimits:
        """The limits a reference must respect at the door: the joint's own, and no more than the
        input gate's plausibility bounds (``input_gate.max_position`` / ``max_velocity``)."""
        lim, gate = self.controller.limits, self.gate
        return dataclasses.replace(
            lim,
            position_min=max(lim.position_min, -gate.max_position),
            position_max=min(lim.position_max, gate.max_position),
            velocity_limit=min(lim.velocity_limit, gate.max_velocity),
        )

    def replace(self, controller, reference, values, overrides) -> None:
        controller.compensation_enabled = self.controller.compensation_enabled
        self.controller, self.reference, self.values, self.overrides = (
            controller,
            reference,
            values,
            overrides,
        )
        self.residual_logged = False

    def log_dropped_terms(self, logger, label: str, t: float) -> None:
        """Log a dropped non-finite or out-of-limit term once when it starts and once when it has been
        valid again for 1 s (:class:`~friction_ros.core.control.command_safety.TermGuard`)."""
        guard = self.controller.guard
        for why in guard.take_new():
            logger.error(f"{label}{why}: term dropped, its state reset")
        for name in guard.clear_quiet(t, 1.0):
            logger.info(f"{label}{name}: valid again for 1 s (cleared)")

    def terms_message(self, sec: int, nanosec: int, t: ControllerTerms) -> bytes:
        """friction_msgs/ControllerState CDR bytes of one period's terms."""
        return self.state_encoder.pack(
            sec,
            nanosec,
            t.mode,
            (
                t.reference_position,
                t.reference_velocity,
                t.reference_acceleration,
                t.position,
                t.velocity,
                t.error,
                t.error_dot,
                t.p_term,
                t.i_term,
                t.d_term,
                t.velocity_feedforward,
                t.inertia_feedforward,
                t.friction_feedforward,
                t.friction_feedback,
                t.load_feedforward,
                t.learned_feedforward,
                t.command_unlimited,
                t.command,
            ),
            t.saturated,
        )

    def status(self, counts: dict, compute, addon: bool, log) -> tuple[int, str, dict]:
        """Diagnostics of this joint: (level, text, values); ``compute``: the node's compute times
        of the period (a :class:`~friction_ros.nodes.loops.LatencyHistogram`, s)."""
        values = dict(counts)
        gate, ctrl = self.gate, self.controller
        values["rejected_states"] = gate.log.total
        values.update(gate.log.values())
        values.update(unstamped_states=gate.counts["unstamped"], resyncs=gate.counts["resyncs"])
        new_rejections = gate.log.total - self.diag_rejected
        self.diag_rejected = gate.log.total
        if compute.n:
            values["compute_p50_s"] = compute.percentile(50)
            values["compute_p99_s"] = compute.percentile(99)
        level, text = OK, f"{ctrl.mode} running"
        if not ctrl.compensation_enabled:
            text = f"{ctrl.mode} running, compensation switched off (~/set_feedforward_control)"
        if addon and not (self.has_reference or self.trajectory or self.desired):
            level, text = WARN, "waiting for a desired trajectory: compensation output 0"
        if new_rejections:
            level = WARN
            text = (
                f"{new_rejections} joint states rejected since the last status (last: {gate.log.last_reason})"
            )
        if self.timed_out:
            level, text = WARN, "no joint state: commanding zero torque"
        if ctrl.compensation_fallback:
            level, text = ERROR, ctrl.fallback_reason
        values["dropped_terms"] = ctrl.guard.total
        if ctrl.guard.active:
            level, text = ERROR, "; ".join(ctrl.guard.active.values()) + ": term dropped, its state reset"
        values["residual_nonfinite"] = ctrl.residual_nonfinite
        if ctrl.residual_note and not self.residual_logged:
            self.residual_logged = True  # once per controller (a parameter change builds a new one)
            log(ctrl.residual_note)
        if ctrl.residual_nonfinite and level == OK:
            level, text = WARN, ctrl.residual_note
        # what compensates: the source with a friction model, else none (friction-bringup's summary)
        fr = ctrl.friction
        values["compensation"] = fr.source if fr.model is not None and fr.source != "none" else "none"
        values["compensation_fallback"] = int(ctrl.compensation_fallback)
        values["compensation_enabled"] = int(ctrl.compensation_enabled)
        values["feedback_bound_limited"] = int(bool(ctrl.feedback_bound_note))
        if ctrl.feedback_bound_note:
            values["feedback_bound"] = ctrl.feedback_bound_note
        return level, text, values
