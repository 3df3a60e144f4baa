"""friction_estimator: friction_ros.core.estimation.OnlineFrictionEstimator as a ROS 2 node.

* in  ``joint_states`` (sensor_msgs/JointState; effort = joint torque N*m). Works the same on live
  data, in lockstep and on a bag replayed by ``bag_player``.
* out ``friction_estimate`` (friction_msgs/FrictionEstimate: friction torque from the torque balance
  or disturbance observer, model prediction, states, adapted coefficients with their one-sigma
  std, excitation and convergence flags), ``diagnostics``.

The coefficients are published as the friction library model config (flattened, see
``friction_ros.core.coefficient_exchange``), so the compensating controller can adopt them without
a restart when its ``adopt_estimator_coefficients`` parameter is true.
"""

from __future__ import annotations

import math
import time

from friction_msgs.msg import FrictionEstimate
from sensor_msgs.msg import JointState

from friction_ros.core.coefficient_exchange import to_fields
from friction_ros.core.config import Field, Schema
from friction_ros.core.control_period import control_period_field
from friction_ros.core.estimation.estimator import ESTIMATOR_SCHEMA, OnlineFrictionEstimator
from friction_ros.core.input_gate import DUPLICATE, REJECTED, RESYNC, JointInputGate
from friction_ros.core.wire import JointStateDecoder
from friction_ros.nodes.diagnostics import OK, WARN, DiagnosticsPublisher
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
    Field("joint_name", "joint1", "joint to estimate (name in joint_states)", read_only=True),
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


def parameter_schema() -> Schema:
    """The node's parameters: its own, the estimator's (:data:`ESTIMATOR_SCHEMA`), the input gate."""
    return Schema("friction_estimator", [*NODE_FIELDS, *ESTIMATOR_SCHEMA, input_gate_schema(), *SCHEDULING])


class FrictionEstimatorNode(ParameterNode):
    """Thin adapter over OnlineFrictionEstimator; see the module docstring."""

    def __init__(self):
        super().__init__("friction_estimator")
        self.values = declare_config(self, parameter_schema(), self._apply)
        self.estimator = OnlineFrictionEstimator(
            self._core_config(self.values)
        )  # refuses to start if invalid
        self.joint = self.values["joint_name"]
        self.pub = self.create_publisher(FrictionEstimate, "friction_estimate", RECORDED_QOS)
        self._decoder = JointStateDecoder()
        # the controller's plausibility gate: bad samples never reach the estimator's filters
        self.gate = JointInputGate(
            self.joint,
            self.values.get("input_gate"),
            period=self.values["control_period"],
            need_velocity=True,
            need_effort=True,
        )
        self._sim_clock = bool(self.get_parameter("use_sim_time").value)
        self._diag_rejected = 0
        # raw: joint states decoded by the wire module's JointStateDecoder (no message object per sample)
        self.create_subscription(JointState, "joint_states", self._on_state, STATE_QOS, raw=True)
        self.diag = DiagnosticsPublisher(self, "friction_estimator", self.joint)
        self.create_timer(self.values["diagnostics_period"], self._publish_diagnostics)
        self._last_ns: int | None = None
        self._n = 0
        self.counts = {"samples": 0, "excited_samples": 0, "published": 0}
        self._publish_every = self.values["publish_every"]
        apply_scheduling(self, self.values)

    @staticmethod
    def _core_config(values: dict) -> dict:
        return {k: values[k] for k in ESTIMATOR_SCHEMA.items if k in values}

    def _apply(self, changes: dict) -> None:
        values = current_values(self, changes)
        est = OnlineFrictionEstimator(self._core_config(values))  # raises -> change rejected
        self.estimator, self.values = est, values
        self._publish_every = values["publish_every"]
        self.get_logger().info(f"parameters changed: {', '.join(sorted(changes))} (estimator restarted)")

    def _on_state(self, data: bytes) -> None:
        msg = self._decoder.decode(data)
        gate = self.gate
        now = self.get_clock().now().nanoseconds if self._sim_clock else time.time_ns()
        status = gate.admit(msg, now)
        if status == REJECTED:
            if gate.log_line:
                self.get_logger().warning(f"{gate.log_line}; sample ignored")
            return
        if status == DUPLICATE:
            return  # lockstep re-send
        if gate.log_line:  # one call site per severity: rclpy refuses a severity change at a call site
            if status == RESYNC:
                self.get_logger().warning(gate.log_line)
            else:
                self.get_logger().info(gate.log_line)
        t_ns = gate.stamp_ns
        if status == RESYNC:
            self.estimator.reset()  # new time base or position reference (a bag loop): start over
            self._last_ns = None
        dt = (t_ns - self._last_ns) * 1e-9 if self._last_ns is not None else self.values["control_period"]
        self._last_ns = t_ns
        pos, vel, eff = gate.position, gate.velocity, gate.effort
        e = self.estimator.update(t_ns * 1e-9, pos, vel, eff, dt)
        self.counts["samples"] += 1
        self.counts["excited_samples"] += int(e.excitation_ok)
        self._n += 1
        if self._n % self._publish_every:
            return
        out = FrictionEstimate()
        out.header.stamp.sec, out.header.stamp.nanosec = msg.sec, msg.nanosec
        out.joint_name = self.joint
        model, names, coefs = to_fields(self.estimator.model_config())
        out.model = model
        out.friction_torque = e.friction_torque
        out.model_torque = e.model_torque
        out.velocity = e.velocity
        out.state = [float(x) for x in e.state]
        out.coefficient_names = names
        out.coefficients = coefs
        std = self.estimator.coefficient_std
        out.coefficient_std = [float(std.get(n, math.nan)) for n in names] if std else []
        out.excitation_ok = e.excitation_ok
        out.converged = e.converged
        self.pub.publish(out)
        self.counts["published"] += 1

    def _publish_diagnostics(self) -> None:
        values = dict(self.counts)
        log = self.gate.log
        values["rejected_states"] = log.total
        values.update(log.values())
        values.update(unstamped_states=self.gate.counts["unstamped"], resyncs=self.gate.counts["resyncs"])
        new_rejections, self._diag_rejected = log.total - self._diag_rejected, log.total
        values.update({f"coef.{k}": v for k, v in self.estimator.coefficients.items()})
        level = OK if self.estimator.converged else WARN
        text = "converged" if self.estimator.converged else "adapting (not converged yet)"
        if new_rejections:
            level = WARN
            text += (
                f"; {new_rejections} joint states rejected since the last status (last: {log.last_reason})"
            )
        self.diag.publish(level, text, values)


def main(args=None) -> int:
    return run_node(FrictionEstimatorNode, args)


if __name__ == "__main__":
    raise SystemExit(main())
