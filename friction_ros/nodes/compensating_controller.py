"""compensating_controller: friction_ros.core.control.CompensatingController as a ROS 2 node, for
one joint or a whole arm.

Event-driven: every ``joint_states`` message is one control period of every joint it carries. The
command answers the state it was computed from (its header stamp is the state's stamp), which is
what makes the lockstep graph deterministic and lets the plant/drive measure state-to-command
latency.

Joints: ``joint_name`` (one joint, the simple case) or ``joints: [j1, j2, ...]``: one core
controller, input gate and reference per joint, one ``joint_states`` message in, one
``joint_commands`` message (all joints, in ``joints`` order) out. Per-joint values in the layout
of ros2_controllers (:mod:`friction_ros.core.joint_config`): ``gains.<joint>.p`` (PID keys and the
plain keys: ``gains.<joint>.inertia``, ``.u_clamp_max``, ``.mode`` ...), ``<section>.<joint>.<key>``
(``friction.j3.model``, ``compensation.j3.gain``, ``load.j3.gravity``, ``reference.j3.type``),
on top of the node-level values. A joint missing from a message (or rejected by its gate) holds
its last command; after ``state_timeout`` with no valid state it gets zero torque, the others stay
controlled.

Add-on (``mode: compensation_only`` for every joint): the output is only the friction and load
compensation for an arm that has its own controller, following ``reference``,
``desired_joint_states`` or ``reference.*`` (see :mod:`friction_ros.nodes.addon_output`);
``~/set_feedforward_control`` (std_srvs/SetBool) switches compensation on and off.

Topics (all relative, so one namespace per joint or arm works):

* in  ``joint_states`` (sensor_msgs/JointState), ``reference`` (trajectory_msgs/JointTrajectory,
  optional: replaces the built-in reference generator for the joints it names),
  ``desired_joint_states`` (sensor_msgs/JointState), ``friction_estimate``
  (friction_msgs/FrictionEstimate per joint, adopted when ``adopt_estimator_coefficients`` is
  true), ``base_command`` (add-on with ``sum_base_command``)
* out ``joint_commands`` (sensor_msgs/JointState effort = joint torque N*m, keep-last 1),
  ``compensation_command`` and ``commands`` (add-on), ``controller_state`` (friction_msgs/ControllerState, one per
  joint per period: every term, for plotting), ``diagnostics`` (one status per joint)

Parameters: the node's own (below) plus the sections of the core controller, one ROS parameter per
leaf (``pid.p``, ``compensation.source``, ``friction.model`` + that model's coefficients,
``reference.type`` ...). See README "Nodes" for the full table.
"""

from __future__ import annotations

import time

from friction_msgs.msg import ControllerState, FrictionEstimate
from sensor_msgs.msg import JointState
from std_srvs.srv import SetBool
from trajectory_msgs.msg import JointTrajectory

from friction_ros.core.control.controller import CompensatingController
from friction_ros.core.control.controller_terms import state_floats
from friction_ros.core.experiment.references import reference_from_config
from friction_ros.core.input_gate import JointInputGate
from friction_ros.core.joint_config import GAINS
from friction_ros.core.joint_group import COMPUTED, RESEND, JointGroup
from friction_ros.core.joint_group_inputs import control_channel
from friction_ros.core.validation import ParameterError
from friction_ros.core.wire import (
    CONTROLLER_STATE_FLOATS,
    ControllerStateEncoder,
    JointStateDecoder,
    JointStateEncoder,
)
from friction_ros.nodes.addon_output import AddonOutput
from friction_ros.nodes.command_owner import CommandOwnerWatch, command_source
from friction_ros.nodes.controller_inputs import ReferenceInputs
from friction_ros.nodes.controller_parameters import (  # noqa: F401 (parameter_schema: the node's API)
    PER_JOINT_PLAIN_KEYS,
    build_controller,
    parameter_schema,
)
from friction_ros.nodes.diagnostics import ERROR, DiagnosticsPublisher
from friction_ros.nodes.joint_parameters import (
    current_joint_values,
    declare_joint_config,
    declare_joints,
    values_of_joint,
)
from friction_ros.nodes.loops import LatencyHistogram
from friction_ros.nodes.parameters import ParameterNode
from friction_ros.nodes.qos import COMMAND_QOS, RECORDED_QOS, STATE_QOS
from friction_ros.nodes.runtime import apply_scheduling, log_events, run_node
from friction_ros.nodes.safe_subscription import BYTES, safe_subscription
from friction_ros.nodes.terms_file import TermsFile

assert CONTROLLER_STATE_FLOATS == tuple(
    k for k, t in ControllerState.get_fields_and_field_types().items() if t == "double"
), "friction_msgs/ControllerState and the wire encoder disagree"


class CompensatingControllerNode(ReferenceInputs, ParameterNode):
    """Thin adapter over a :class:`~friction_ros.core.joint_group.JointGroup` (one
    CompensatingController per joint); see the module docstring."""

    def __init__(self, **kwargs):
        super().__init__("compensating_controller", **kwargs)
        schema = parameter_schema(self.given_section)
        joints = declare_joints(self, {name.split(".")[0] for name, _ in schema.fields()} | {GAINS})
        self.values, self.layout, overrides = declare_joint_config(
            self, schema, joints or ["_"], self._apply, gains_section="pid", plain_keys=PER_JOINT_PLAIN_KEYS
        )
        self.single = not joints
        self.joints = joints or [self.values["joint_name"]]
        self.dt = self.values["control_period"]
        if self.single:
            overrides = {self.joints[0]: {}}
        given_ref = bool(self.given_section("reference"))
        channels = []
        for j in self.joints:
            ov = overrides[j]
            jv = values_of_joint(self.values, ov, j, self.single)
            ctrl, ref_cfg = build_controller(jv, self.layout, j, ov, self.single)
            # plausibility gate of the joint states: bad samples never reach the controller's state
            gate = JointInputGate(j, self.values.get("input_gate"), period=self.dt)
            has_ref = given_ref or any(k.startswith("reference.") for k in ov)
            channels.append(control_channel(j, ctrl, reference_from_config(ref_cfg), gate, jv, ov, has_ref))
        self.group = JointGroup(channels, self.dt, labelled=not self.single)  # ParameterError: mixed add-on
        self.addon = self.group.addon
        self.channels = self.group.channels
        self.joint = self.joints[0]
        self._sim_clock = bool(self.get_parameter("use_sim_time").value)
        # header.frame_id = this node: plants and drives tell command sources apart by it (command_owner)
        self._cmd_encoder = JointStateEncoder(self.joints, ("effort",), frame_id=command_source(self))
        self.commands = self.create_publisher(JointState, "joint_commands", COMMAND_QOS)
        self.last_command: bytes | None = None
        self.state_pub = self.create_publisher(ControllerState, "controller_state", RECORDED_QOS)
        self._state_encoders = {j: ControllerStateEncoder(j) for j in self.joints}
        self._decoder = JointStateDecoder()
        # raw: joint states decoded by the wire module's JointStateDecoder (no message object per period)
        safe_subscription(self, JointState, "joint_states", self._on_state, STATE_QOS, decode=BYTES)
        safe_subscription(self, JointTrajectory, "reference", self._on_trajectory, STATE_QOS)
        safe_subscription(self, JointState, "desired_joint_states", self._on_desired, STATE_QOS)
        # raw: an estimator publishes per joint (700 messages/s for 7 joints at publish_every 10);
        # they are deserialised only while a joint adopts them
        safe_subscription(
            self, FrictionEstimate, "friction_estimate", self._on_estimate, STATE_QOS, decode=BYTES
        )
        self.create_service(SetBool, "~/set_feedforward_control", self._on_set_feedforward)
        self.owner = CommandOwnerWatch(self, self.joints, role="commands")
        self.sum_base = bool(self.values["sum_base_command"])
        if self.sum_base and not self.addon:
            raise ParameterError("sum_base_command = true needs mode compensation_only (an add-on)")
        self.addon_output = (
            AddonOutput(self, self.channels, self.sum_base, self._send, self._sim_clock)
            if self.addon
            else None
        )
        # the node's own name: a PD and an add-on in one namespace have their own statuses
        self.diag = DiagnosticsPublisher(self, self.get_name(), self.joints[0] if self.single else "")
        self.create_timer(self.values["diagnostics_period"], self._publish_diagnostics)
        self.create_timer(max(self.values["state_timeout"] / 2, 0.005), self._check_state_timeout)
        self._compute = compute_histogram()  # compute time per state since the last diagnostics
        self.terms_file = TermsFile(self.values["terms_file"]) if self.values["terms_file"] else None
        apply_scheduling(self, self.values)
        log_events(self.get_logger(), self.group.summary())

    @property
    def controller(self) -> CompensatingController:
        """The (first) joint's controller: single-joint code and tools read this one."""
        return self.channels[0].controller

    # -- parameters -------------------------------------------------------------------------------
    def _apply(self, changes: dict) -> None:
        """Validate a run-time change by building the new controllers first; commit only if all are valid."""
        values, overrides = current_joint_values(self, self.layout, changes)
        touched = {ch.joint for ch in self.channels}
        split = self.layout.split
        if all(split(k) is not None for k in changes):
            touched = {split(k)[0] for k in changes}
        keys = [split(k)[1] if split(k) else k for k in changes]
        gains_only = all(k.startswith("pid.") for k in keys)
        plan = []
        for ch in self.channels:
            if ch.joint not in touched:
                continue
            ov = {} if self.single else overrides[ch.joint]
            jv = values_of_joint(values, ov, ch.joint, self.single)
            if gains_only and not ch.controller.compensation_fallback:
                plan.append((ch, None, {k[4:]: jv["pid"][k[4:]] for k in keys}, jv, ov))
                continue
            # a ParameterError rejects the whole change (nothing was committed yet)
            new_ctrl, ref_cfg = build_controller(jv, self.layout, ch.joint, ov, self.single)
            plan.append((ch, (new_ctrl, reference_from_config(ref_cfg)), None, jv, ov))
        self.values = values
        what = ", ".join(sorted(changes))
        for ch, new, gains, jv, ov in plan:
            if gains is not None:  # gains only: change them in the running controller (states stay)
                self.group.set_gains(ch, gains, jv, ov, what)
            else:
                self.group.replace(ch, *new, jv, ov, what)
        log_events(self.get_logger(), self.group.take_events())

    def _on_set_feedforward(self, request, response):
        """``~/set_feedforward_control`` (std_srvs/SetBool): compensation on/off for every joint."""
        self.group.set_compensation(request.data)
        response.success = True
        response.message = f"friction/load compensation {'on' if request.data else 'off'}"
        self.get_logger().info(response.message)
        return response

    # -- inputs -----------------------------------------------------------------------------------
    def _on_state(self, data: bytes) -> None:
        msg = self._decoder.decode(data)
        # the ROS system clock, without an rclpy Time object per period
        now = self.get_clock().now().nanoseconds if self._sim_clock else time.time_ns()
        group = self.group
        c0 = time.perf_counter()
        result = group.step(msg, now, time.monotonic())
        if group.events:
            log_events(self.get_logger(), group.take_events())
        if result != COMPUTED:
            if result == RESEND and self.last_command is not None:
                group.counts["duplicates"] += 1
                self.commands.publish(self.last_command)  # lockstep re-send: same answer, no recompute
            return
        if group.fallback_fired:
            group.fallback_fired = False
            self._publish_diagnostics()
        sec, nanosec = msg.sec, msg.nanosec
        if self.state_pub.get_subscription_count():  # 0.6 us; nobody listening: nothing to send
            for ch in group.computed:
                t = ch.terms
                self.state_pub.publish(
                    self._state_encoders[ch.joint].pack(sec, nanosec, t.mode, state_floats(t), t.saturated)
                )
        if self.terms_file is not None:
            for ch in group.computed:
                self.terms_file.add(group.last_ns, ch.joint, ch.terms)
        self._compute.add(time.perf_counter() - c0)
        if self.addon_output is not None:
            self.addon_output.state_done(sec, nanosec, group.last_ns)
        else:
            self._send(sec, nanosec, group.commands)

    def _send(self, sec: int, nanosec: int, efforts) -> None:
        """joint_commands (all joints); the bytes are kept for a lockstep re-send."""
        self.last_command = self._cmd_encoder.pack(sec, nanosec, *efforts)
        self.commands.publish(self.last_command)

    # -- safety and health --------------------------------------------------------------------------
    def _check_state_timeout(self) -> None:
        if self._sim_clock:
            return  # lockstep: time only moves with the plant; nothing to time out
        newly = self.group.check_timeout(time.monotonic(), self.values["state_timeout"])
        log_events(self.get_logger(), self.group.take_events())
        if newly:
            stamp = self.get_clock().now().to_msg()
            self._publish_safe(stamp.sec, stamp.nanosec)

    def _publish_safe(self, sec: int, nanosec: int) -> None:
        """Publish the joints' commands now (a timed-out joint's is 0; the add-on: its sum)."""
        if self.addon_output is not None:
            self.addon_output.publish_safe(sec, nanosec)
        else:
            self._send(sec, nanosec, self.group.commands)

    def _publish_diagnostics(self) -> None:
        compute, self._compute = self._compute, compute_histogram()
        times = (
            {"compute_p50_s": compute.percentile(50), "compute_p99_s": compute.percentile(99)}
            if compute.n
            else {}
        )
        statuses = self.group.statuses(times)
        log_events(self.get_logger(), self.group.take_events())
        if self.owner.conflict:  # another source commands these joints too
            statuses = [(j, ERROR, self.owner.status(), v) for j, _, _, v in statuses]
        if self.single:
            self.diag.publish(*statuses[0][1:])
        else:
            self.diag.publish_joints(statuses)

    def on_shutdown(self) -> None:
        """Leave the joints safe: the last command is zero torque (the add-on: the base command
        alone when it sums, else zero compensation)."""
        self.group.zero()
        for _ in range(3):
            stamp = self.get_clock().now().to_msg()
            self._publish_safe(stamp.sec, stamp.nanosec)
            time.sleep(0.01)
        if self.terms_file is not None:
            self.terms_file.close()


def compute_histogram() -> LatencyHistogram:
    """Compute times of one diagnostics period: 1 us bins up to 20 ms (no list to sort)."""
    return LatencyHistogram(bin_s=1e-6, bins=20_000)


def main(args=None) -> int:
    return run_node(CompensatingControllerNode, args)


if __name__ == "__main__":
    from friction_ros.nodes.process_exit import exit_now

    exit_now(main())  # everything is closed: no interpreter teardown (see process_exit)
