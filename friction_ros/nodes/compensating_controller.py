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

import dataclasses
import time

from friction_msgs.msg import ControllerState, FrictionEstimate
from sensor_msgs.msg import JointState
from std_srvs.srv import SetBool
from trajectory_msgs.msg import JointTrajectory

from friction_ros.core.config import Field, Schema
from friction_ros.core.control.controller import (
    CompensatingController,
    ControllerTerms,
    controller_from_ros_parameters,
)
from friction_ros.core.control.controller_config import CONTROLLER_FIELDS, controller_parameter_schema
from friction_ros.core.control_period import control_period_field
from friction_ros.core.experiment.references import reference_from_config
from friction_ros.core.input_gate import (
    DUPLICATE,
    REJECTED,
    RESYNC,
)
from friction_ros.core.joint_config import GAINS, name_joint_error
from friction_ros.core.joint_type import JOINT_TYPE_FIELD, units_of
from friction_ros.core.validation import ParameterError
from friction_ros.core.wire import (
    CONTROLLER_STATE_FLOATS,
    JointStateDecoder,
    JointStateEncoder,
)
from friction_ros.nodes.addon_output import AddonOutput
from friction_ros.nodes.command_owner import CommandOwnerWatch, command_source
from friction_ros.nodes.controller_inputs import ReferenceInputs
from friction_ros.nodes.controller_joints import JointChannel
from friction_ros.nodes.diagnostics import ERROR, DiagnosticsPublisher
from friction_ros.nodes.joint_parameters import (
    current_joint_values,
    declare_joint_config,
    declare_joints,
    values_of_joint,
)
from friction_ros.nodes.loops import LatencyHistogram
from friction_ros.nodes.parameters import (
    SCHEDULING,
    ParameterNode,
    input_gate_schema,
)
from friction_ros.nodes.qos import COMMAND_QOS, RECORDED_QOS, STATE_QOS
from friction_ros.nodes.runtime import apply_scheduling, run_node
from friction_ros.nodes.safe_subscription import BYTES, safe_subscription
from friction_ros.nodes.terms_file import TermsFile

NODE_FIELDS = [
    Field("joint_name", "joint1", "joint to control (name in joint_states / joint_commands)", read_only=True),
    Field(
        "terms_file",
        "",
        "write every period's terms (controller_state fields) to this CSV file ('' = off)",
        read_only=True,
    ),
    JOINT_TYPE_FIELD,
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
    Field(
        "sum_base_command",
        False,
        "add-on (mode compensation_only): add the arm controller's command (base_command) and "
        "publish the sum as joint_commands",
        read_only=True,
    ),
]

#: keys ``gains.<joint>.<key>`` accepts besides the PID keys (ros2_controllers puts
#: feedforward_gain and u_clamp_max there too)
PER_JOINT_PLAIN_KEYS = (*(f.name for f in CONTROLLER_FIELDS), "adopt_estimator_coefficients", "joint_type")


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


class CompensatingControllerNode(ReferenceInputs, ParameterNode):
    """Thin adapter over one CompensatingController per joint; see the module docstring."""

    def __init__(self, **kwargs):
        super().__init__("compensating_controller", **kwargs)
        schema = parameter_schema(self.given_section)
        joints = declare_joints(self, {name.split(".")[0] for name, _ in schema.fields()} | {GAINS})
        self.values, self.layout, overrides = declare_joint_config(
            self,
            schema,
            joints or ["_"],
            self._apply,
            gains_section="pid",
            plain_keys=PER_JOINT_PLAIN_KEYS,
        )
        self.single = not joints
        self.joints = joints or [self.values["joint_name"]]
        self.dt = self.values["control_period"]
        if self.single:
            overrides = {self.joints[0]: {}}
        self.channels = [
            JointChannel(self, j, values_of_joint(self.values, overrides[j], j, self.single), overrides[j])
            for j in self.joints
        ]
        modes = {ch.joint: ch.controller.mode == "compensation_only" for ch in self.channels}
        self.addon = any(modes.values())
        if self.addon and not all(modes.values()):
            raise ParameterError(
                "mode: compensation_only must be the mode of every joint or of none (joints "
                f"{', '.join(j for j, a in modes.items() if a)} are add-on, the others are not)"
            )
        self.joint = self.joints[0]
        self._sim_clock = bool(self.get_parameter("use_sim_time").value)
        # header.frame_id = this node: plants and drives tell command sources apart by it (command_owner)
        self._cmd_encoder = JointStateEncoder(self.joints, ("effort",), frame_id=command_source(self))
        self.commands = self.create_publisher(JointState, "joint_commands", COMMAND_QOS)
        self.last_command: bytes | None = None
        self.state_pub = self.create_publisher(ControllerState, "controller_state", RECORDED_QOS)
        self._decoder = JointStateDecoder()
        self._by_joint = {ch.joint: ch for ch in self.channels}
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

        self._t0_ns: int | None = None
        self._last_ns: int | None = None
        self._last_t = 0.0
        self.counts = {
            "cycles": 0,
            "duplicates": 0,
            "rejected_references": 0,
            "saturated": 0,
            "adopted": 0,
            "rejected_estimates": 0,
        }
        self._compute = compute_histogram()  # compute time per state since the last diagnostics
        self.terms_file = TermsFile(self.values["terms_file"]) if self.values["terms_file"] else None
        apply_scheduling(self, self.values)
        for ch in self.channels:
            c = ch.controller
            self.get_logger().info(
                f"{'' if self.single else ch.joint + ': '}mode {c.mode}, friction model "
                f"{c.friction.model.name if c.friction.model else 'none'}, "
                f"load feedforward {'on' if c.load.active else 'off'}, "
                f"learned residual {c.residual.residual.kind if c.residual is not None else 'off'}, "
                f"reference {ch.reference.config().get('type', '?') if ch.has_reference or not self.addon else 'topic'}"
            )
            if c.feedback_bound_note:
                self.get_logger().warning(self._label(ch) + c.feedback_bound_note)

    @property
    def controller(self) -> CompensatingController:
        """The (first) joint's controller: single-joint code and tools read this one."""
        return self.channels[0].controller

    def _label(self, ch: JointChannel) -> str:
        return "" if self.single else f"{ch.joint}: "

    # -- parameters -------------------------------------------------------------------------------
    def build_controller(self, joint: str, values: dict, overrides: dict):
        """(controller, reference config) of one joint; errors name the joint's parameter."""
        try:
            with units_of(values.get("joint_type", "revolute")):
                ctrl, ref = controller_from_ros_parameters(values)
            if not ctrl.limits_given:
                raise ParameterError(
                    "effort_limit is not set: give the joint's torque (force) limit, e.g. effort_limit: 2.5 "
                    "(per joint gains.<joint>.effort_limit; or finite u_clamp_min/u_clamp_max): the plant "
                    "preset's, the drive's torque_limit, or the one friction-fit writes"
                )
            return ctrl, ref
        except ParameterError as exc:
            if self.single:
                raise
            raise ParameterError(name_joint_error(str(exc), self.layout, joint, overrides)) from None

    def _apply(self, changes: dict) -> None:
        """Validate a run-time change by building the new controllers first; commit only if all are valid."""
        values, overrides = current_joint_values(self, self.layout, changes)
        touched = {ch.joint for ch in self.channels}
        node_level = [k for k in changes if self.layout.split(k) is None]
        if not node_level:
            touched = {self.layout.split(k)[0] for k in changes}
        plan = []
        for ch in self.channels:
            if ch.joint not in touched:
                continue
            ov = {} if self.single else overrides[ch.joint]
            jv = values_of_joint(values, ov, ch.joint, self.single)
            keys = [self.layout.split(k)[1] if self.layout.split(k) else k for k in changes]
            if all(k.startswith("pid.") for k in keys) and not ch.controller.compensation_fallback:
                gains = {k[4:]: jv["pid"][k[4:]] for k in keys}
                plan.append((ch, None, None, jv, ov, gains))
                continue
            new_ctrl, ref_cfg = self.build_controller(ch.joint, jv, ov)  # ParameterError -> rejected
            plan.append((ch, new_ctrl, reference_from_config(ref_cfg), jv, ov, None))
        self.values = values
        for ch, new_ctrl, new_ref, jv, ov, gains in plan:
            label = self._label(ch)
            if gains is not None:  # gains only: change them in the running controller (states stay)
                note = ch.controller.feedback_bound_note
                ch.controller.set_pid_gains(**gains)
                ch.values, ch.overrides = jv, ov
                self.get_logger().info(
                    f"{label}parameters changed: {', '.join(sorted(changes))} (states kept)"
                )
                if ch.controller.feedback_bound_note != note and ch.controller.feedback_bound_note:
                    self.get_logger().warning(label + ch.controller.feedback_bound_note)
                continue
            if ch.controller.compensation_fallback:
                self.get_logger().info(
                    f"{label}compensation fallback cleared by a parameter change: compensation active again"
                )
                ch.fallback_logged = ""
            note_changed = new_ctrl.feedback_bound_note != ch.controller.feedback_bound_note
            ch.replace(new_ctrl, new_ref, jv, ov)
            self.get_logger().info(f"{label}parameters changed: {', '.join(sorted(changes))}")
            if note_changed and new_ctrl.feedback_bound_note:
                self.get_logger().warning(label + new_ctrl.feedback_bound_note)

    def _on_set_feedforward(self, request, response):
        """``~/set_feedforward_control`` (std_srvs/SetBool): compensation on/off for every joint."""
        for ch in self.channels:
            ch.controller.compensation_enabled = bool(request.data)
        response.success = True
        response.message = f"friction/load compensation {'on' if request.data else 'off'}"
        self.get_logger().info(response.message)
        return response

    # -- inputs -----------------------------------------------------------------------------------
    def _now_ns(self) -> int:
        if self._sim_clock:
            return self.get_clock().now().nanoseconds
        return time.time_ns()  # = the ROS system clock, without an rclpy Time object per period

    def _on_state(self, data: bytes) -> None:
        msg = self._decoder.decode(data)
        now = self._now_ns()
        admitted = []
        duplicates = 0
        for ch in self.channels:
            gate = ch.gate
            status = gate.admit(msg, now)
            if status >= DUPLICATE:
                if status == REJECTED:
                    if gate.log_line:
                        self.get_logger().warning(
                            f"{gate.log_line}; sample ignored, holding the last command"
                        )
                    continue
                if status == DUPLICATE:
                    duplicates += 1
                    continue
                if status == RESYNC:
                    self._resync(ch)
            elif gate.log_line:
                self.get_logger().info(gate.log_line)
            admitted.append(ch)
        if not admitted:
            if duplicates and self.last_command is not None:
                self.counts["duplicates"] += 1
                self.commands.publish(self.last_command)  # lockstep re-send: same answer, no recompute
            return
        t_ns = admitted[0].gate.stamp_ns
        if self._t0_ns is None:
            self._t0_ns = t_ns
        t = (t_ns - self._t0_ns) * 1e-9
        wall = time.monotonic()
        c0 = time.perf_counter()
        listening = self.state_pub.get_subscription_count()  # 0.6 us; nobody listening: nothing to send
        for ch in admitted:
            ch.last_state_wall = wall
            if ch.timed_out:
                ch.timed_out = False
                self.get_logger().info(f"{self._label(ch)}joint states valid again: controlling")
            pos, vel = ch.gate.position, ch.gate.velocity
            if ch.desired is not None:
                ref = ch.desired
            elif ch.trajectory is not None:
                ref = ch.trajectory.sample(t)
            elif self.addon and not ch.has_reference:
                if not ch.waiting_logged:
                    ch.waiting_logged = True
                    self.get_logger().warning(
                        f"{self._label(ch)}no desired trajectory yet (reference, desired_joint_states or "
                        "reference.* parameters): compensation output 0"
                    )
                ch.command = ch.compensation = 0.0
                continue
            else:
                ref = ch.reference.sample(t)
            terms = ch.controller.compute(t, ref, (pos, vel), self.dt)
            ch.command = ch.compensation = terms.command
            if ch.controller.guard.active:
                ch.log_dropped_terms(self.get_logger(), self._label(ch), t)
            self.counts["saturated"] += int(terms.saturated)
            if ch.controller.compensation_fallback and ch.fallback_logged != ch.controller.fallback_reason:
                ch.fallback_logged = ch.controller.fallback_reason  # each stage once: fallback, unstable loop
                self.get_logger().error(self._label(ch) + ch.controller.fallback_reason)
                self._publish_diagnostics()
            if listening:
                self.state_pub.publish(ch.terms_message(msg.sec, msg.nanosec, terms))
            if self.terms_file is not None:
                self.terms_file.add(t_ns, ch.joint, terms)
        self._compute.add(time.perf_counter() - c0)
        self._last_ns = t_ns
        self._last_t = t
        self.counts["cycles"] += 1
        self._publish_commands(msg.sec, msg.nanosec, t_ns)

    def _publish_commands(self, sec: int, nanosec: int, t_ns: int) -> None:
        if self.addon_output is not None:
            self.addon_output.state_done(sec, nanosec, t_ns)
            return
        self._send(sec, nanosec, [ch.command for ch in self.channels])

    def _send(self, sec: int, nanosec: int, efforts) -> None:
        """joint_commands (all joints); the bytes are kept for a lockstep re-send."""
        self.last_command = self._cmd_encoder.pack(sec, nanosec, *efforts)
        self.commands.publish(self.last_command)

    def _resync(self, ch: JointChannel) -> None:
        """The gate adopted a new reference after a run of consistent rejected samples."""
        self.get_logger().warning(
            self._label(ch) + (ch.gate.log_line or "joint state reference re-synchronised")
        )
        if ch.gate.resync_reason != "jump" and self._t0_ns is not None and ch is self.channels[0]:
            # a new time base: the controller's time continues one period after the last accepted
            self._t0_ns = ch.gate.stamp_ns - int(round((self._last_t + self.dt) * 1e9))
        ch.controller.velocity.reset()  # no difference across the discontinuity

    # -- safety and health --------------------------------------------------------------------------
    def _check_state_timeout(self) -> None:
        if self._last_ns is None:
            return
        if self._sim_clock:
            return  # lockstep: time only moves with the plant; nothing to time out
        now = time.monotonic()
        limit = self.values["state_timeout"]
        newly = [ch for ch in self.channels if not ch.timed_out and now - ch.last_state_wall > limit]
        if not newly:
            return
        for ch in newly:
            ch.timed_out = True
            ch.command = ch.compensation = 0.0
            log = ch.gate.log
            why = (
                f" ({log.total} rejected so far, last reason {log.last_reason}: see the rejection lines)"
                if log.total
                else ""
            )
            self.get_logger().warning(
                f"{self._label(ch)}no valid joint state for {limit:g} s{why}: commanding zero torque"
            )
        stamp = self.get_clock().now().to_msg()
        self._publish_safe(stamp.sec, stamp.nanosec)

    def _publish_safe(self, sec: int, nanosec: int) -> None:
        """Publish the channels' commands now (a timed-out joint's is 0; the add-on: its sum)."""
        if self.addon_output is not None:
            self.addon_output.publish_safe(sec, nanosec)
        else:
            self._send(sec, nanosec, [ch.command for ch in self.channels])

    def _publish_diagnostics(self) -> None:
        compute, self._compute = self._compute, compute_histogram()
        statuses = []
        for ch in self.channels:
            log = lambda text, ch=ch: self.get_logger().error(self._label(ch) + text)  # noqa: E731
            statuses.append((ch.joint, *ch.status(self.counts, compute, self.addon, log)))
        if self.owner.conflict:  # another source commands these joints too
            statuses = [(j, ERROR, self.owner.status(), v) for j, _, _, v in statuses]
        if self.single:
            self.diag.publish(*statuses[0][1:])
        else:
            self.diag.publish_joints(statuses)

    def on_shutdown(self) -> None:
        """Leave the joints safe: the last command is zero torque (the add-on: the base command
        alone when it sums, else zero compensation)."""
        for ch in self.channels:
            ch.command = ch.compensation = 0.0
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
    raise SystemExit(main())
