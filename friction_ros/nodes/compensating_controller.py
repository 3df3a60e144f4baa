"""compensating_controller: friction_ros.core.control.CompensatingController as a ROS 2 node.

Event-driven: every ``joint_states`` message is one control period. The command answers the state
it was computed from (its header stamp is the state's stamp), which is what makes the lockstep
graph deterministic and lets the plant/drive measure state-to-command latency.

Topics (all relative, so one namespace per joint works):

* in  ``joint_states`` (sensor_msgs/JointState), ``reference`` (trajectory_msgs/JointTrajectory,
  optional: replaces the built-in reference generator), ``friction_estimate``
  (friction_msgs/FrictionEstimate, adopted when ``adopt_estimator_coefficients`` is true)
* out ``joint_commands`` (sensor_msgs/JointState effort = joint torque N*m, keep-last 1),
  ``controller_state`` (friction_msgs/ControllerState), ``diagnostics``

Parameters: the node's own (below) plus the sections of the core controller, one ROS parameter per
leaf (``pid.p``, ``compensation.source``, ``friction.model`` + that model's coefficients,
``reference.type`` ...). See README "Nodes" for the full table.
"""

from __future__ import annotations

import dataclasses
import math
import time

from friction_msgs.msg import ControllerState, FrictionEstimate
from sensor_msgs.msg import JointState
from trajectory_msgs.msg import JointTrajectory

from friction_ros.core.coefficient_exchange import from_fields
from friction_ros.core.config import Field, Schema
from friction_ros.core.control.controller import ControllerTerms, controller_from_ros_parameters
from friction_ros.core.control.controller_config import controller_parameter_schema
from friction_ros.core.control_period import control_period_field
from friction_ros.core.experiment.references import reference_from_config
from friction_ros.core.experiment.trajectory import TrajectoryReference
from friction_ros.core.input_gate import (
    DUPLICATE,
    REJECTED,
    RESYNC,
    JointInputGate,
)
from friction_ros.core.validation import ParameterError
from friction_ros.core.wire import CONTROLLER_STATE_FLOATS, ControllerStateEncoder, JointStateDecoder
from friction_ros.nodes.commands import CommandPublisher, stamp_to_ns
from friction_ros.nodes.diagnostics import ERROR, OK, WARN, DiagnosticsPublisher
from friction_ros.nodes.parameters import (
    SCHEDULING,
    ParameterNode,
    current_values,
    declare_config,
    input_gate_schema,
)
from friction_ros.nodes.qos import RECORDED_QOS, STATE_QOS
from friction_ros.nodes.runtime import apply_scheduling, run_node

NODE_FIELDS = [
    Field("joint_name", "joint1", "joint to control (name in joint_states / joint_commands)", read_only=True),
    control_period_field("nominal control period (dt of the control law)"),
    Field("adopt_estimator_coefficients", False, "hot-swap the friction model with converged estimates"),
    Field(
        "state_timeout",
        0.05,
        "zero torque once no joint state came for this long (wall)",
        lo=0.001,
        hi=60.0,
        unit="s",
    ),
    Field("diagnostics_period", 1.0, "period of the diagnostics status", lo=0.05, hi=60.0, unit="s"),
]


def parameter_schema(given_section=lambda prefix: {}) -> Schema:
    """The node's parameters; ``given_section(prefix)``: keys given for a section (friction model
    and reference defaults apply only when none is given)."""
    return Schema(
        "compensating_controller",
        [
            *NODE_FIELDS,
            *controller_parameter_schema(
                friction_model=not given_section("friction"), reference=not given_section("reference")
            ),
            input_gate_schema(),
            *SCHEDULING,
        ],
    )


# ControllerTerms fields copied into friction_msgs/ControllerState every period (hot path: no asdict)
_STATE_FIELDS = tuple(
    f.name
    for f in dataclasses.fields(ControllerTerms)
    if f.name not in ("time", "mode", "saturated", "compensation_fallback")
)  # compensation_fallback is not in friction_msgs/ControllerState: diagnostics and the log carry it
assert set(_STATE_FIELDS) == set(CONTROLLER_STATE_FLOATS), (
    "ControllerTerms and ControllerStateEncoder disagree"
)
assert CONTROLLER_STATE_FLOATS == tuple(
    k for k, t in ControllerState.get_fields_and_field_types().items() if t == "double"
), "friction_msgs/ControllerState and the wire encoder disagree"


class CompensatingControllerNode(ParameterNode):
    """Thin adapter over CompensatingController; see the module docstring."""

    def __init__(self):
        super().__init__("compensating_controller")
        self.values = declare_config(self, parameter_schema(self.given_section), self._apply)
        self.controller, ref_cfg = controller_from_ros_parameters(self.values)  # ParameterError -> refuses
        self.reference = reference_from_config(ref_cfg)
        self.trajectory: TrajectoryReference | None = None

        self.joint = self.values["joint_name"]
        self.dt = self.values["control_period"]
        # plausibility gate of the joint states (stamps, jumps, magnitudes): bad samples never
        # reach the controller's state (integrator, filters, observers, limit-cycle detector)
        self.gate = JointInputGate(self.joint, self.values.get("input_gate"), period=self.dt)
        self._sim_clock = bool(self.get_parameter("use_sim_time").value)
        self.commands = CommandPublisher(self, self.joint)
        self.state_pub = self.create_publisher(ControllerState, "controller_state", RECORDED_QOS)
        self._state_encoder = ControllerStateEncoder(self.joint)
        self._decoder = JointStateDecoder()
        # raw: joint states decoded by the wire module's JointStateDecoder (no message object per period)
        self.create_subscription(JointState, "joint_states", self._on_state, STATE_QOS, raw=True)
        self.create_subscription(JointTrajectory, "reference", self._on_trajectory, STATE_QOS)
        self.create_subscription(FrictionEstimate, "friction_estimate", self._on_estimate, STATE_QOS)
        self.diag = DiagnosticsPublisher(self, "compensating_controller", self.joint)
        self.create_timer(self.values["diagnostics_period"], self._publish_diagnostics)
        self.create_timer(max(self.values["state_timeout"] / 2, 0.005), self._check_state_timeout)

        self._t0_ns: int | None = None
        self._last_ns: int | None = None
        self._last_t = 0.0
        self._diag_rejected = 0
        self._last_state_wall = time.monotonic()
        self._timed_out = False
        self._fallback_logged = False
        self._residual_logged = False
        self.counts = {
            "cycles": 0,
            "duplicates": 0,
            "rejected_references": 0,
            "saturated": 0,
            "adopted": 0,
            "rejected_estimates": 0,
        }
        self._compute_times: list[float] = []
        apply_scheduling(self, self.values)
        c = self.controller
        self.get_logger().info(
            f"mode {c.mode}, friction model {c.friction.model.name if c.friction.model else 'none'}, "
            f"load feedforward {'on' if c.load.active else 'off'}, "
            f"learned residual {c.residual.residual.kind if c.residual is not None else 'off'}, "
            f"reference {self.reference.config().get('type', '?')}"
        )
        if self.controller.feedback_bound_note:
            self.get_logger().warning(self.controller.feedback_bound_note)

    # -- parameters -------------------------------------------------------------------------------
    def _apply(self, changes: dict) -> None:
        """Validate a run-time change by building the new controller first; commit only if valid."""
        values = current_values(self, changes)
        new_ctrl, ref_cfg = controller_from_ros_parameters(values)  # ParameterError -> change rejected
        new_ref = reference_from_config(ref_cfg)
        if all(k.startswith("pid.") for k in changes) and not self.controller.compensation_fallback:
            # gains only: change them in the running controller (its integrator and states stay)
            note = self.controller.feedback_bound_note
            self.controller.set_pid_gains(**{k[4:]: v for k, v in changes.items()})
            self.values = values
            self.get_logger().info(f"parameters changed: {', '.join(sorted(changes))} (states kept)")
            if self.controller.feedback_bound_note != note and self.controller.feedback_bound_note:
                self.get_logger().warning(self.controller.feedback_bound_note)
            return
        if self.controller.compensation_fallback:
            self.get_logger().info(
                "compensation fallback cleared by a parameter change: compensation active again"
            )
            self._fallback_logged = False
        note_changed = new_ctrl.feedback_bound_note != self.controller.feedback_bound_note
        self.controller, self.reference, self.values = new_ctrl, new_ref, values
        self._residual_logged = False
        self.get_logger().info(f"parameters changed: {', '.join(sorted(changes))}")
        if note_changed and new_ctrl.feedback_bound_note:
            self.get_logger().warning(new_ctrl.feedback_bound_note)

    # -- inputs -----------------------------------------------------------------------------------
    def _on_trajectory(self, msg: JointTrajectory) -> None:
        try:
            if self.joint not in msg.joint_names:
                raise ParameterError(f"joint {self.joint} is not in joint_names {list(msg.joint_names)}")
            j = list(msg.joint_names).index(self.joint)
            times = [p.time_from_start.sec + p.time_from_start.nanosec * 1e-9 for p in msg.points]
            pos = [p.positions[j] if j < len(p.positions) else math.nan for p in msg.points]
            vel = (
                [p.velocities[j] for p in msg.points]
                if all(len(p.velocities) > j for p in msg.points)
                else None
            )
            stamp = stamp_to_ns(msg.header.stamp)
            if stamp == 0 or self._t0_ns is None:
                start = (self._last_ns - self._t0_ns) * 1e-9 if self._last_ns is not None else 0.0
            else:
                start = (stamp - self._t0_ns) * 1e-9
            self.trajectory = TrajectoryReference(times, pos, vel, start_time=start)
        except ParameterError as exc:
            self.counts["rejected_references"] += 1
            self.get_logger().error(f"rejected reference trajectory: {exc}; keeping the previous reference")

    def _on_estimate(self, msg: FrictionEstimate) -> None:
        if not (self.values.get("adopt_estimator_coefficients") and msg.converged):
            return
        try:
            self.controller.set_coefficients(from_fields(msg.model, msg.coefficient_names, msg.coefficients))
            self.counts["adopted"] += 1
        except (ParameterError, ValueError) as exc:
            self.counts["rejected_estimates"] += 1
            self.get_logger().warning(f"estimator coefficients not adopted: {exc}", throttle_duration_sec=5.0)

    def _now_ns(self) -> int:
        if self._sim_clock:
            return self.get_clock().now().nanoseconds
        return time.time_ns()  # = the ROS system clock, without an rclpy Time object per period

    def _on_state(self, data: bytes) -> None:
        msg = self._decoder.decode(data)
        gate = self.gate
        status = gate.admit(msg, self._now_ns())
        if status >= DUPLICATE:
            if status == REJECTED:
                if gate.log_line:
                    self.get_logger().warning(f"{gate.log_line}; sample ignored, holding the last command")
                return
            if status == DUPLICATE:
                if self.commands.last is not None:
                    self.counts["duplicates"] += 1
                    self.commands.republish()  # lockstep re-send: same answer, no recompute
                return
            if status == RESYNC:
                self._resync()
        elif gate.log_line:
            self.get_logger().info(gate.log_line)
        pos, vel = gate.position, gate.velocity
        t_ns = gate.stamp_ns
        if self._t0_ns is None:
            self._t0_ns = t_ns
        t = (t_ns - self._t0_ns) * 1e-9
        self._last_state_wall = time.monotonic()
        if self._timed_out:
            self._timed_out = False
            self.get_logger().info("joint states valid again: controlling")
        ref = self.trajectory.sample(t) if self.trajectory is not None else self.reference.sample(t)
        c0 = time.perf_counter()
        terms = self.controller.compute(t, ref, (pos, vel), self.dt)
        self._compute_times.append(time.perf_counter() - c0)
        self._last_ns = t_ns
        self._last_t = t
        self.commands.publish_stamp(msg.sec, msg.nanosec, terms.command)
        if self.controller.compensation_fallback and not self._fallback_logged:
            self._fallback_logged = True
            self.get_logger().error(self.controller.fallback_reason)
            self._publish_diagnostics()
        self.counts["cycles"] += 1
        self.counts["saturated"] += int(terms.saturated)
        if self.state_pub.get_subscription_count():  # 0.6 us; nobody listening: nothing to send
            t = terms
            self.state_pub.publish(
                self._state_encoder.pack(
                    msg.sec,
                    msg.nanosec,
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
            )

    def _resync(self) -> None:
        """The gate adopted a new reference after a run of consistent rejected samples."""
        self.get_logger().warning(self.gate.log_line or "joint state reference re-synchronised")
        if self.gate.resync_reason != "jump" and self._t0_ns is not None:
            # a new time base: the controller's time continues one period after the last accepted
            self._t0_ns = self.gate.stamp_ns - int(round((self._last_t + self.dt) * 1e9))
        self.controller.velocity.reset()  # no difference across the discontinuity

    def _publish_command(self, stamp, torque: float) -> None:
        self.commands.publish(stamp, torque)

    # -- safety and health --------------------------------------------------------------------------
    def _check_state_timeout(self) -> None:
        if self._last_ns is None or self._timed_out:
            return
        if self.get_parameter("use_sim_time").value:
            return  # lockstep: time only moves with the plant; nothing to time out
        if time.monotonic() - self._last_state_wall > self.values["state_timeout"]:
            self._timed_out = True
            log = self.gate.log
            why = (
                f" ({log.total} rejected so far, last reason {log.last_reason}: see the rejection lines)"
                if log.total
                else ""
            )
            self.get_logger().warning(
                f"no valid joint state for {self.values['state_timeout']:g} s{why}: commanding zero torque"
            )
            self._publish_command(self.get_clock().now().to_msg(), 0.0)

    def _publish_diagnostics(self) -> None:
        ct = sorted(self._compute_times[-5000:])
        self._compute_times = self._compute_times[-5000:]
        values = dict(self.counts)
        gate = self.gate
        values["rejected_states"] = gate.log.total
        values.update(gate.log.values())
        values.update(unstamped_states=gate.counts["unstamped"], resyncs=gate.counts["resyncs"])
        new_rejections = gate.log.total - self._diag_rejected
        self._diag_rejected = gate.log.total
        if ct:
            values["compute_p50_s"] = ct[len(ct) // 2]
            values["compute_p99_s"] = ct[min(len(ct) - 1, int(len(ct) * 0.99))]
        level, text = OK, f"{self.controller.mode} running"
        if new_rejections:
            level = WARN
            text = (
                f"{new_rejections} joint states rejected since the last status (last: {gate.log.last_reason})"
            )
        if self._timed_out:
            level, text = WARN, "no joint state: commanding zero torque"
        if self.controller.compensation_fallback:
            level, text = ERROR, self.controller.fallback_reason
        values["residual_nonfinite"] = self.controller.residual_nonfinite
        if self.controller.residual_note and not self._residual_logged:
            self._residual_logged = True  # once per controller (a parameter change builds a new one)
            self.get_logger().error(self.controller.residual_note)
        if self.controller.residual_nonfinite and level == OK:
            level, text = WARN, self.controller.residual_note
        values["compensation_fallback"] = int(self.controller.compensation_fallback)
        values["feedback_bound_limited"] = int(bool(self.controller.feedback_bound_note))
        if self.controller.feedback_bound_note:
            values["feedback_bound"] = self.controller.feedback_bound_note
        self.diag.publish(level, text, values)

    def on_shutdown(self) -> None:
        """Leave the joint safe: the last command is zero torque."""
        for _ in range(3):
            self._publish_command(self.get_clock().now().to_msg(), 0.0)
            time.sleep(0.01)


def main(args=None) -> int:
    return run_node(CompensatingControllerNode, args)


if __name__ == "__main__":
    raise SystemExit(main())
