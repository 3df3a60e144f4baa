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
from friction_ros.core.control.controller import (
    CONTROLLER_DEFAULTS,
    ControllerTerms,
    controller_from_ros_parameters,
)
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
from friction_ros.nodes.node_utils import (
    ERROR,
    OK,
    RECORDED_QOS,
    SCHEDULING_PARAMS,
    STATE_QOS,
    WARN,
    CommandPublisher,
    DiagnosticsPublisher,
    Param,
    ParameterNode,
    add_runtime_validation,
    apply_scheduling,
    declare,
    gate_params,
    override_values,
    run_node,
    section_specs,
    stamp_to_ns,
    unflatten,
)

NODE_PARAMS = [
    Param("joint_name", "joint1", "joint to control (name in joint_states / joint_commands)", read_only=True),
    Param(
        "control_period",
        0.001,
        "nominal control period (dt of the control law)",
        lo=1e-5,
        hi=0.1,
        unit="s",
        read_only=True,
    ),
    Param("adopt_estimator_coefficients", False, "hot-swap the friction model with converged estimates"),
    Param(
        "state_timeout",
        0.05,
        "zero torque once no joint state came for this long (wall)",
        lo=0.001,
        hi=60.0,
        unit="s",
    ),
    Param("diagnostics_period", 1.0, "period of the diagnostics status", lo=0.05, hi=60.0, unit="s"),
    *gate_params(),
    *SCHEDULING_PARAMS,
]
# Core controller keys that are plain values (not sections).
TOP_KEYS = [k for k, v in CONTROLLER_DEFAULTS.items() if not isinstance(v, dict)]
DOCS = {
    "mode": "controller mode: pid, cascade, dnpf, gain_scheduling, sliding_mode",
    "feedforward_gain": "velocity feedforward gain (command += gain * reference velocity)",
    "inertia": "J_hat for the inertia feedforward J_hat * reference acceleration",
    "load_feedforward": "constant torque added to the command: holds a known load such as gravity",
    "limit_cycle_detection": "switch friction compensation off (latched) when it causes a limit cycle",
    "limit_cycle_min_frequency": "limit cycle: lowest oscillation frequency that counts",
    "limit_cycle_min_amplitude": "limit cycle: smallest error amplitude (RMS) that counts (also 4 encoder counts)",
    "limit_cycle_window": "limit cycle: averaging time constant of the detector",
    "limit_cycle_hold": "limit cycle: how long the oscillation must hold before the fallback",
    "u_clamp_max": "upper torque limit",
    "u_clamp_min": "lower torque limit",
    "rate_limit": "torque rate limit",
    "velocity_source": "measured (joint_states velocity) or differentiated (filtered position difference)",
    "velocity_filter_time_constant": "velocity filter time constant",
    "position_jump_limit": "reject position samples that jump more than this (lost encoder bits)",
}
UNITS = {
    "inertia": "kg*m^2",
    "load_feedforward": "N*m",
    "limit_cycle_min_frequency": "Hz",
    "limit_cycle_min_amplitude": "rad",
    "limit_cycle_window": "s",
    "limit_cycle_hold": "s",
    "u_clamp_max": "N*m",
    "u_clamp_min": "N*m",
    "rate_limit": "N*m/s",
    "velocity_filter_time_constant": "s",
    "position_jump_limit": "rad",
    "feedforward_gain": "N*m*s/rad",
}
SCHEME_SECTIONS = ("pid", "dnpf", "gain_scheduling", "cascade", "sliding_mode")
DEFAULT_REFERENCE = {"type": "constant"}


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
        specs = list(NODE_PARAMS)
        for k in TOP_KEYS:
            v = CONTROLLER_DEFAULTS[k]
            specs.append(
                Param(
                    k,
                    float(v) if isinstance(v, int) and not isinstance(v, bool) else v,
                    DOCS.get(k, k),
                    unit=UNITS.get(k, ""),
                )
            )
        for s in SCHEME_SECTIONS:
            specs += section_specs(self, s, CONTROLLER_DEFAULTS[s], f"{s} parameter")
        comp_defaults = {k: v for k, v in CONTROLLER_DEFAULTS["friction"].items() if k != "model"}
        specs += section_specs(self, "compensation", comp_defaults, "friction compensation option")
        model_given = override_values(self, "friction")
        specs += section_specs(self, "friction", {} if model_given else {"model": "none"}, "friction model")
        ref_given = override_values(self, "reference")
        specs += section_specs(
            self, "reference", {} if ref_given else DEFAULT_REFERENCE, "reference generator"
        )
        self.specs = specs
        values = declare(self, specs)
        self.values = unflatten(values)
        self.controller, ref_cfg = controller_from_ros_parameters(self.values)  # ParameterError -> refuses
        self.reference = reference_from_config(ref_cfg)
        self.trajectory: TrajectoryReference | None = None
        add_runtime_validation(self, specs, self._apply)

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
        # raw: joint states decoded by node_utils' JointState codec (no message object per period)
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
        self.get_logger().info(
            f"mode {self.controller.mode}, friction model "
            f"{self.controller.friction.model.name if self.controller.friction.model else 'none'}, "
            f"reference {self.reference.config().get('type', '?')}"
        )
        if self.controller.feedback_bound_note:
            self.get_logger().warning(self.controller.feedback_bound_note)

    # -- parameters -------------------------------------------------------------------------------
    def _apply(self, changes: dict) -> None:
        """Validate a run-time change by building the new controller first; commit only if valid."""
        flat = {**{p.name: self.get_parameter(p.name).value for p in self.specs}, **changes}
        values = unflatten(
            {k: (list(v) if hasattr(v, "tolist") or isinstance(v, tuple) else v) for k, v in flat.items()}
        )
        new_ctrl, ref_cfg = controller_from_ros_parameters(values)  # ParameterError -> change rejected
        new_ref = reference_from_config(ref_cfg)
        if self.controller.compensation_fallback:
            self.get_logger().info(
                "compensation fallback cleared by a parameter change: compensation active again"
            )
            self._fallback_logged = False
        note_changed = new_ctrl.feedback_bound_note != self.controller.feedback_bound_note
        self.controller, self.reference, self.values = new_ctrl, new_ref, values
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
