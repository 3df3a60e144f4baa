"""friction_estimator: friction_ros.core.estimation.OnlineFrictionEstimator as a ROS 2 node, for one
joint or N joints.

* in  ``joint_states`` (sensor_msgs/JointState; effort = joint torque N*m). Works the same on live
  data, in lockstep and on a bag replayed by ``bag_player``.
* out ``friction_estimate`` (friction_msgs/FrictionEstimate: friction torque from the torque balance
  or disturbance observer, model prediction, states, adapted coefficients with their one-sigma
  std, excitation and convergence flags; one message per joint, ``joint_name`` names it),
  ``diagnostics``.

Joints: ``joint_name`` (one joint, the default) or ``joints: [j1, j2, ...]`` (read-only; then
``joint_name`` is not used): one core estimator and one input gate per joint, all fed from the same
``joint_states`` message (decoded once per message). A joint missing from a message (or rejected
by its gate) is skipped for that message only: its estimate does not advance, the other joints'
do. Every ``publish_every`` samples of a joint, one FrictionEstimate of that joint is published.

Per-joint values (layout of :mod:`friction_ros.core.joint_config`), on top of the node-level
values, which are the defaults of every joint:

* ``gains.<joint>.<key>`` for the estimator's plain keys (:data:`ESTIMATOR_SCHEMA`: ``method``,
  ``model``, ``inertia``, ``forgetting_factor``, ``min_velocity`` ...), e.g.
  ``gains.j3.forgetting_factor: 0.995``, ``gains.j3.inertia: 0.02``;
* ``initial.<joint>.<coef>`` (start values, e.g. ``initial.j3.fv``; not yet the nested names of the
  asymmetric models, ``positive.fc``: the per-joint declaration takes one level),
  ``lugre.<joint>.<key>`` (the LuGre config of ``model: lugre``; one that names its ``model``
  replaces the node-level one as a whole) and ``input_gate.<joint>.<key>`` (read-only, e.g.
  ``input_gate.j3.max_velocity``).

A joint whose ``gains.<joint>.model`` differs from the node-level ``model`` takes only its own
``initial.<joint>.*`` values (the node-level ones are another model's coefficients). The node's own
settings (``control_period``, ``publish_every``, ``diagnostics_period``, ``realtime_priority``,
``cpu_affinity``) have no per-joint value. Only per-joint keys given at start-up exist as parameters
(a per-joint value cannot be added at run time). A run-time change of a node-level value restarts
the estimator of every joint whose configuration it changes (not those with their own value); a
per-joint change restarts that joint's estimator only. An invalid value is refused (at start-up: the
node does not start) with one line naming the parameter as written, e.g.
``gains.j3.forgetting_factor = 2 is out of range``, or ``joint j3: ...`` when the bad value is a
node-level one. With ``joints``, ``diagnostics`` holds one status per joint
(``friction_estimator/<joint>``).

The coefficients are published as the friction library model config (flattened, see
``friction_ros.core.coefficient_exchange``), so the compensating controller can adopt them without
a restart when its ``adopt_estimator_coefficients`` parameter is true.
"""

from __future__ import annotations

import time

from friction_msgs.msg import FrictionEstimate
from sensor_msgs.msg import JointState

from friction_ros.core.estimation.estimator import OnlineFrictionEstimator
from friction_ros.core.estimation.joint_estimators import EstimatorGroup
from friction_ros.core.input_gate import JointInputGate
from friction_ros.core.joint_channel import JointChannel
from friction_ros.core.joint_config import GAINS, joint_errors
from friction_ros.core.joint_type import units_of
from friction_ros.core.wire import FrictionEstimateEncoder, JointStateDecoder
from friction_ros.nodes.diagnostics import DiagnosticsPublisher
from friction_ros.nodes.estimator_parameters import (  # noqa: F401 (parameter_schema, core_config: the node's API)
    PLAIN_KEYS,
    core_config,
    joint_config,
    joint_names,
    parameter_schema,
)
from friction_ros.nodes.joint_parameters import current_joint_values, declare_joint_config, declare_joints
from friction_ros.nodes.parameters import ParameterNode, current_values, declare_config
from friction_ros.nodes.qos import RECORDED_QOS, STATE_QOS
from friction_ros.nodes.runtime import apply_scheduling, log_events, run_node
from friction_ros.nodes.safe_subscription import BYTES, safe_subscription


class FrictionEstimatorNode(ParameterNode):
    """Thin adapter over one OnlineFrictionEstimator per joint; see the module docstring."""

    def __init__(self, **kwargs):
        super().__init__("friction_estimator", **kwargs)
        schema = parameter_schema(with_joints=False)
        names = [name for name, _ in schema.fields()] + [name for name, _ in schema.sections()]
        reserved = {part for name in names for part in name.split(".")}  # joint j: no <x>.j.<y> clash
        joints = declare_joints(self, reserved | {GAINS, "positive", "negative"})
        self.single = not joints
        if self.single:
            self.values = declare_config(self, schema, self._apply)
            self.layout = None
            joints = [self.values["joint_name"]]
            overrides = {joints[0]: {}}
        else:
            self.values, self.layout, overrides = declare_joint_config(
                self, schema, joints, self._apply, plain_keys=PLAIN_KEYS
            )
        self.joints = joints
        period = self.values["control_period"]
        channels = []
        self.joint_types: dict[str, str] = {}
        for j in joints:
            values = self.values if self.single else joint_config(self.values, overrides[j])
            cfg = core_config(values)
            self.joint_types[j] = values["joint_type"]
            # the controller's plausibility gate: bad samples never reach the estimator's filters
            gate = JointInputGate(
                j, values.get("input_gate"), period=period, need_velocity=True, need_effort=True
            )
            ch = JointChannel(j, gate)
            ch.estimator, ch.config = (
                self._build(j, cfg, overrides[j], values["joint_type"]),
                cfg,
            )  # or refuse
            channels.append(ch)
        self.group = EstimatorGroup(channels, period, self.values["publish_every"])
        self._encoders = {j: FrictionEstimateEncoder(j) for j in joints}  # one struct.pack per estimate
        self.joint = joints[0]
        self.pub = self.create_publisher(FrictionEstimate, "friction_estimate", RECORDED_QOS)
        self._decoder = JointStateDecoder()
        self._sim_clock = bool(self.get_parameter("use_sim_time").value)
        # raw: joint states decoded by the wire module's JointStateDecoder (no message object per sample)
        safe_subscription(self, JointState, "joint_states", self._on_state, STATE_QOS, decode=BYTES)
        self.diag = DiagnosticsPublisher(self, "friction_estimator", self.joint)
        self.create_timer(self.values["diagnostics_period"], self._publish_diagnostics)
        apply_scheduling(self, self.values)

    # -- single-joint attributes (tools and tests of the one-joint node read these) ------------------
    @property
    def estimator(self) -> OnlineFrictionEstimator:
        return self.group.channels[0].estimator

    @property
    def gate(self) -> JointInputGate:
        return self.group.channels[0].gate

    @property
    def counts(self) -> dict[str, int]:
        return self.group.channels[0].counts

    # -- configuration -------------------------------------------------------------------------------
    def _build(
        self, joint: str, cfg: dict, overrides: dict, joint_type: str = "revolute"
    ) -> OnlineFrictionEstimator:
        """The joint's estimator; a ParameterError names the joint's parameter as written
        (:func:`~friction_ros.nodes.estimator_parameters.joint_names`), in the joint's units."""
        names = joint_names(self.layout, joint, overrides)
        with units_of(joint_type), joint_errors(names):
            return OnlineFrictionEstimator(cfg, names)

    def _apply(self, changes: dict) -> None:
        if self.single:
            values = current_values(self, changes)
            new = {self.joint: (core_config(values), None)}
        else:
            values, overrides = current_joint_values(self, self.layout, changes)
            new = {}
            for ch in self.group.channels:
                cfg = core_config(joint_config(values, overrides[ch.joint]))
                if cfg != ch.config:
                    new[ch.joint] = (cfg, overrides[ch.joint])
        # every estimator first (raises -> the change is rejected, nothing changed), then swap
        built = {j: (self._build(j, cfg, ov, self.joint_types[j]), cfg) for j, (cfg, ov) in new.items()}
        for ch in self.group.channels:
            if ch.joint in built:
                ch.estimator, ch.config = built[ch.joint]
        self.values = values
        self.group.publish_every = values["publish_every"]
        restarted = "" if self.single else f" of {', '.join(built) or 'no joint'}"
        self.get_logger().info(
            f"parameters changed: {', '.join(sorted(changes))} (estimator{restarted} restarted)"
        )

    # -- the per-message path ------------------------------------------------------------------------
    def _on_state(self, data: bytes) -> None:
        msg = self._decoder.decode(data)  # once per message, whatever the number of joints
        now = self.get_clock().now().nanoseconds if self._sim_clock else time.time_ns()
        group = self.group
        due = group.step(msg, now)
        if group.events:
            log_events(self.get_logger(), group.take_events())
        for ch in due:
            self.pub.publish(self._encoders[ch.joint].pack(msg.sec, msg.nanosec, *group.estimate(ch)))
            ch.counts["published"] += 1

    def _publish_diagnostics(self) -> None:
        statuses = self.group.statuses()
        if self.single:
            self.diag.publish(*statuses[0][1:])
        else:
            self.diag.publish_joints(statuses)


def main(args=None) -> int:
    return run_node(FrictionEstimatorNode, args)


if __name__ == "__main__":
    raise SystemExit(main())
