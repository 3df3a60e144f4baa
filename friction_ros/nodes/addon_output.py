"""The outputs of compensating_controller in add-on mode (``mode: compensation_only``).

* ``compensation_command`` (std_msgs/Float64MultiArray, ``joints`` order): the compensation of
  every period;
* with ``sum_base_command``: the arm controller's command (``base_command``, JointState effort by
  name) plus the compensation, as ``joint_commands`` (JointState) and ``commands``
  (Float64MultiArray). In lockstep (sim time) a base command stamped for a state not yet computed
  waits for that state, so each stamp is answered once, with the compensation of its own state.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence

from rclpy.node import Node
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray, MultiArrayDimension

from friction_ros.nodes.commands import stamp_to_ns
from friction_ros.nodes.qos import COMMAND_QOS
from friction_ros.nodes.safe_subscription import safe_subscription


class AddonOutput:
    """Publishers, base-command subscription and the sum (see the module docstring).

    ``send(sec, nanosec, efforts)``: the node's joint_commands publication (it keeps the bytes for
    lockstep re-sends); ``channels``: the node's joints (``joint``, ``compensation``).
    """

    def __init__(self, node: Node, channels: Sequence, sum_base: bool, send: Callable, sim_clock: bool):
        self.node, self.channels, self.sum_base, self.send = node, channels, sum_base, send
        self.sim_clock = sim_clock
        n = len(channels)
        dim = [MultiArrayDimension(label="joints", size=n, stride=n)]
        self.compensation_pub = node.create_publisher(Float64MultiArray, "compensation_command", COMMAND_QOS)
        self._compensation = Float64MultiArray()
        self._compensation.layout.dim = dim
        self._joints = {ch.joint for ch in channels}
        self.base: dict[str, float] = {}
        self._pending_ns: int | None = None
        self.last_state_ns: int | None = None
        if sum_base:
            safe_subscription(node, JointState, "base_command", self._on_base_command, COMMAND_QOS)
            self.sum_pub = node.create_publisher(Float64MultiArray, "commands", COMMAND_QOS)
            self._sum = Float64MultiArray()
            self._sum.layout.dim = list(dim)

    def state_done(self, sec: int, nanosec: int, t_ns: int) -> None:
        """After a state was computed: publish the compensation (and the sum, if its base waits)."""
        self._compensation.data = [ch.compensation for ch in self.channels]
        self.compensation_pub.publish(self._compensation)
        if t_ns >= 0:
            self.last_state_ns = t_ns
        if not self.sum_base:
            self.send(sec, nanosec, [ch.compensation for ch in self.channels])
        elif self._pending_ns == t_ns:  # the base command of this state came first
            self._pending_ns = None
            self.publish_sum(sec, nanosec)

    def _on_base_command(self, msg: JointState) -> None:
        names = list(msg.name)
        if len(msg.effort) != len(names):
            self.node.get_logger().warning(
                f"base_command ignored: {len(msg.effort)} efforts for {len(names)} names",
                throttle_duration_sec=5.0,
            )
            return
        for n, e in zip(names, msg.effort):
            if n in self._joints and math.isfinite(e):
                self.base[n] = float(e)
        stamp = stamp_to_ns(msg.header.stamp)
        if self.sim_clock and (self.last_state_ns is None or stamp > self.last_state_ns):
            self._pending_ns = stamp
            return
        self.publish_sum(msg.header.stamp.sec, msg.header.stamp.nanosec)

    def publish_sum(self, sec: int, nanosec: int) -> None:
        """Base command + compensation on joint_commands and commands."""
        base = self.base
        # the sum sent to the joint stays inside the joint's limits (effort_limit / u_clamp)
        total = [
            min(
                max(base.get(ch.joint, 0.0) + ch.compensation, ch.controller.u_clamp_min),
                ch.controller.u_clamp_max,
            )
            for ch in self.channels
        ]
        self.send(sec, nanosec, total)
        self._sum.data = total
        self.sum_pub.publish(self._sum)

    def publish_safe(self, sec: int, nanosec: int) -> None:
        """Timeout or shutdown: the channels' compensation is already 0 where unsafe."""
        if self.sum_base:
            self.publish_sum(sec, nanosec)
        else:
            self.state_done(sec, nanosec, -1)
