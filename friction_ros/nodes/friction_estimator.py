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

import math
import re
import time

from friction_msgs.msg import FrictionEstimate
from sensor_msgs.msg import JointState

from friction_ros.core.coefficient_exchange import to_fields
from friction_ros.core.config import Field, Schema
from friction_ros.core.control_period import control_period_field
from friction_ros.core.estimation.estimator import ESTIMATOR_SCHEMA, OnlineFrictionEstimator
from friction_ros.core.input_gate import DUPLICATE, REJECTED, RESYNC, JointInputGate
from friction_ros.core.joint_config import GAINS, joint_values, name_joint_error
from friction_ros.core.joint_type import JOINT_TYPE_FIELD, units_of
from friction_ros.core.validation import ParameterError
from friction_ros.core.wire import FrictionEstimateEncoder, JointStateDecoder
from friction_ros.nodes.diagnostics import OK, WARN, DiagnosticsPublisher
from friction_ros.nodes.joint_parameters import current_joint_values, declare_joint_config, declare_joints
from friction_ros.nodes.parameters import (
    SCHEDULING,
    ParameterNode,
    current_values,
    declare_config,
    input_gate_schema,
)
from friction_ros.nodes.qos import RECORDED_QOS, STATE_QOS
from friction_ros.nodes.runtime import apply_scheduling, run_node
from friction_ros.nodes.safe_subscription import BYTES, safe_subscription

NODE_FIELDS = [
    Field(
        "joint_name",
        "joint1",
        "joint to estimate (name in joint_states); not used when joints is set",
        read_only=True,
    ),
    JOINT_TYPE_FIELD,
    control_period_field("nominal sample period (used when stamps do not advance)", hi=1.0),
    Field(
        "publish_every",
        10,
        "publish one estimate every N samples (every sample is still processed)",
        lo=1,
        hi=100000,
    ),
    Field("diagnostics_period", 1.0, "period of the diagnostics status", lo=0.05, hi=60.0, unit="s"),
]

#: the estimator's plain keys: per joint as ``gains.<joint>.<key>``
PLAIN_KEYS = tuple(name for name, item in ESTIMATOR_SCHEMA.items.items() if isinstance(item, Field)) + (
    "joint_type",
)
_ESTIMATOR_PREFIX = re.compile(r"(?<![\w.])estimator\.")


JOINTS_FIELD = Field(
    "joints",
    [],
    "the joints to estimate (names in joint_states); per-joint gains.<joint>.<key> (estimator keys), "
    "initial.<joint>.<coef>, lugre.<joint>.<key>, input_gate.<joint>.<key> (empty: the one joint "
    "joint_name)",
    kind=str,
    read_only=True,
)


def parameter_schema(with_joints: bool = True) -> Schema:
    """The node's parameters: ``joints``, its own, the estimator's (:data:`ESTIMATOR_SCHEMA`), the
    input gate. ``joints`` is declared by
    :func:`~friction_ros.nodes.joint_parameters.declare_joints` (the node builds the schema without it)."""
    joints = [JOINTS_FIELD] if with_joints else []
    return Schema(
        "friction_estimator",
        [*joints, *NODE_FIELDS, *ESTIMATOR_SCHEMA, input_gate_schema(), *SCHEDULING],
    )


def core_config(values: dict) -> dict:
    """The estimator's config (:data:`ESTIMATOR_SCHEMA` keys) from a joint's nested values."""
    return {k: values[k] for k in ESTIMATOR_SCHEMA.items if k in values}


def joint_config(node_values: dict, overrides: dict) -> dict:
    """One joint's nested values: node-level values with the joint's overrides (node-level flat
    names) on top; see the module docstring for ``initial`` / ``lugre``."""
    out = joint_values(node_values, overrides, {"lugre": "model"})
    if "model" in overrides and overrides["model"] != node_values.get("model"):
        own = {k[len("initial.") :]: v for k, v in overrides.items() if k.startswith("initial.")}
        out["initial"] = joint_values({}, own)
    return out


class _Joint:
    """One joint of the node: its estimator, input gate and counters."""

    __slots__ = (
        "name", "estimator", "config", "gate", "index", "last_ns", "n", "counts", "diag_rejected", "encoder",
    )  # fmt: skip

    def __init__(self, name: str, estimator: OnlineFrictionEstimator, config: dict, gate: JointInputGate):
        self.name = name
        self.estimator = estimator
        self.config = config
        self.gate = gate
        self.index = -1  # in the current joint_states layout (-1: not usable, the gate says why)
        self.last_ns: int | None = None
        self.n = 0
        self.counts = {"samples": 0, "excited_samples": 0, "published": 0}
        self.diag_rejected = 0
        self.encoder = FrictionEstimateEncoder(name)  # its FrictionEstimate as bytes, one struct.pack


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
        self._joints: list[_Joint] = []
        self.joint_types: dict[str, str] = {}
        for j in joints:
            values = self.values if self.single else joint_config(self.values, overrides[j])
            cfg = core_config(values)
            self.joint_types[j] = values["joint_type"]
            est = self._build(j, cfg, overrides[j], values["joint_type"])  # refuses to start if invalid
            # the controller's plausibility gate: bad samples never reach the estimator's filters
            gate = JointInputGate(
                j, values.get("input_gate"), period=period, need_velocity=True, need_effort=True
            )
            self._joints.append(_Joint(j, est, cfg, gate))
        self.joint = joints[0]
        self.pub = self.create_publisher(FrictionEstimate, "friction_estimate", RECORDED_QOS)
        self._decoder = JointStateDecoder()
        self._layout_key: tuple = ()
        self._sim_clock = bool(self.get_parameter("use_sim_time").value)
        # raw: joint states decoded by the wire module's JointStateDecoder (no message object per sample)
        safe_subscription(self, JointState, "joint_states", self._on_state, STATE_QOS, decode=BYTES)
        self.diag = DiagnosticsPublisher(self, "friction_estimator", self.joint)
        self.create_timer(self.values["diagnostics_period"], self._publish_diagnostics)
        self._publish_every = self.values["publish_every"]
        apply_scheduling(self, self.values)

    # -- single-joint attributes (tools and tests of the one-joint node read these) ------------------
    @property
    def estimator(self) -> OnlineFrictionEstimator:
        return self._joints[0].estimator

    @property
    def gate(self) -> JointInputGate:
        return self._joints[0].gate

    @property
    def counts(self) -> dict[str, int]:
        return self._joints[0].counts

    # -- configuration -------------------------------------------------------------------------------
    def _build(
        self, joint: str, cfg: dict, overrides: dict, joint_type: str = "revolute"
    ) -> OnlineFrictionEstimator:
        """The joint's estimator; a ParameterError names the joint's parameter as written, in the
        joint's units."""
        try:
            with units_of(joint_type):
                return OnlineFrictionEstimator(cfg)
        except ParameterError as exc:
            if self.single:
                raise
            text = _ESTIMATOR_PREFIX.sub("", str(exc))
            raise ParameterError(name_joint_error(text, self.layout, joint, overrides)) from None

    def _apply(self, changes: dict) -> None:
        if self.single:
            values = current_values(self, changes)
            new = {self.joint: (core_config(values), None)}
        else:
            values, overrides = current_joint_values(self, self.layout, changes)
            new = {}
            for jt in self._joints:
                cfg = core_config(joint_config(values, overrides[jt.name]))
                if cfg != jt.config:
                    new[jt.name] = (cfg, overrides[jt.name])
        # every estimator first (raises -> the change is rejected, nothing changed), then swap
        built = {j: (self._build(j, cfg, ov, self.joint_types[j]), cfg) for j, (cfg, ov) in new.items()}
        for jt in self._joints:
            if jt.name in built:
                jt.estimator, jt.config = built[jt.name]
        self.values = values
        self._publish_every = values["publish_every"]
        restarted = "" if self.single else f" of {', '.join(built) or 'no joint'}"
        self.get_logger().info(
            f"parameters changed: {', '.join(sorted(changes))} (estimator{restarted} restarted)"
        )

    # -- the per-message path ------------------------------------------------------------------------
    def _index(self, msg) -> None:
        """Each joint's index in this joint_states layout; -1 when its gate must look (missing joint,
        wrong lengths, unnamed message): the gate's ``admit`` then gives the reason."""
        names = msg.name
        n = len(names)
        self._layout_key = (names, len(msg.position), len(msg.velocity), len(msg.effort))
        whole = n > 0 and len(msg.position) == n and len(msg.velocity) == n and len(msg.effort) == n
        where = {name: i for i, name in enumerate(names)} if whole else {}
        for jt in self._joints:
            jt.index = where.get(jt.name, -1)

    def _on_state(self, data: bytes) -> None:
        msg = self._decoder.decode(data)  # once per message, whatever the number of joints
        now = self.get_clock().now().nanoseconds if self._sim_clock else time.time_ns()
        if (msg.name, len(msg.position), len(msg.velocity), len(msg.effort)) != self._layout_key:
            self._index(msg)
        stamp_ns = msg.stamp_ns
        pos, vel, eff = msg.position, msg.velocity, msg.effort
        log = self.get_logger()
        for jt in self._joints:
            gate = jt.gate
            i = jt.index
            status = gate.check(stamp_ns, now, pos[i], vel[i], eff[i]) if i >= 0 else gate.admit(msg, now)
            if status == REJECTED:
                if gate.log_line:
                    log.warning(f"{gate.log_line}; sample ignored")
                continue
            if status == DUPLICATE:
                continue  # lockstep re-send
            if gate.log_line:  # one call site per severity: rclpy refuses a severity change at a call site
                if status == RESYNC:
                    log.warning(gate.log_line)
                else:
                    log.info(gate.log_line)
            self._update(jt, msg, status)

    def _update(self, jt: _Joint, msg, status: int) -> None:
        gate = jt.gate
        t_ns = gate.stamp_ns
        if status == RESYNC:
            jt.estimator.reset()  # new time base or position reference (a bag loop): start over
            jt.last_ns = None
        dt = (t_ns - jt.last_ns) * 1e-9 if jt.last_ns is not None else self.values["control_period"]
        jt.last_ns = t_ns
        est = jt.estimator
        excited = est.step(t_ns * 1e-9, gate.position, gate.velocity, gate.effort, dt)
        counts = jt.counts
        counts["samples"] += 1
        counts["excited_samples"] += int(excited)
        jt.n += 1
        if jt.n % self._publish_every:
            return
        e = est.record()  # coefficient lists and convergence: only for a published estimate
        model, names, coefs = to_fields(est.model_config())
        std = est.coefficient_std
        self.pub.publish(
            jt.encoder.pack(
                msg.sec,
                msg.nanosec,
                model,
                float(e.friction_torque),
                float(e.model_torque),
                float(e.velocity),
                [float(x) for x in e.state],
                names,
                [float(c) for c in coefs],
                [float(std.get(n, math.nan)) for n in names] if std else [],
                e.excitation_ok,
                e.converged,
            )
        )
        counts["published"] += 1

    # -- diagnostics ---------------------------------------------------------------------------------
    def _status(self, jt: _Joint) -> tuple[int, str, dict]:
        values = dict(jt.counts)
        gate, est = jt.gate, jt.estimator
        log = gate.log
        values["rejected_states"] = log.total
        values.update(log.values())
        values.update(unstamped_states=gate.counts["unstamped"], resyncs=gate.counts["resyncs"])
        new_rejections, jt.diag_rejected = log.total - jt.diag_rejected, log.total
        values.update({f"coef.{k}": v for k, v in est.coefficients.items()})
        level = OK if est.converged else WARN
        text = "converged" if est.converged else "adapting (not converged yet)"
        if new_rejections:
            level = WARN
            text += (
                f"; {new_rejections} joint states rejected since the last status (last: {log.last_reason})"
            )
        return level, text, values

    def _publish_diagnostics(self) -> None:
        if self.single:
            self.diag.publish(*self._status(self._joints[0]))
            return
        self.diag.publish_joints((jt.name, *self._status(jt)) for jt in self._joints)


def main(args=None) -> int:
    return run_node(FrictionEstimatorNode, args)


if __name__ == "__main__":
    raise SystemExit(main())
