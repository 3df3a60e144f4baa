"""``joint_commands`` publishers (one joint; several joints in one message) and the header stamp helper."""

from __future__ import annotations

from rclpy.node import Node
from sensor_msgs.msg import JointState

from friction_ros.core.wire import JointStateEncoder
from friction_ros.nodes.qos import COMMAND_QOS


class CommandPublisher:
    """``joint_commands`` publisher of one joint (sensor_msgs/JointState effort, COMMAND_QOS).

    Every command answers a joint state and carries its stamp (lockstep and latency measurement);
    the last command is kept so a duplicate state (a lockstep re-send) gets the same answer again
    without recomputing. Commands are serialised by :class:`~friction_ros.core.wire.JointStateEncoder` and published as
    bytes (same wire type; no message object per command).
    """

    def __init__(self, node: Node, joint: str, topic: str = "joint_commands"):

        self.joint = joint
        self.pub = node.create_publisher(JointState, topic, COMMAND_QOS)
        # header.frame_id = this node: followers tell command sources apart by it (command_owner)
        self._encoder = JointStateEncoder([joint], ("effort",), frame_id=node.get_fully_qualified_name())
        self.last: bytes | None = None

    def publish(self, stamp, torque: float) -> None:
        """Publish ``torque`` [N*m] with header stamp ``stamp`` (builtin_interfaces/Time)."""
        self.publish_stamp(stamp.sec, stamp.nanosec, torque)

    def publish_stamp(self, sec: int, nanosec: int, torque: float) -> None:
        """Publish ``torque`` with the stamp given as (sec, nanosec) (hot path)."""
        self.last = self._encoder.pack(sec, nanosec, float(torque))
        self.pub.publish(self.last)

    def republish(self) -> bool:
        """Send the last command again; False if there is none yet."""
        if self.last is None:
            return False
        self.pub.publish(self.last)
        return True


class ArmCommandPublisher:
    """``joint_commands`` of several joints: one message with every joint's effort (same interface
    as :class:`~friction_ros.nodes.commands.CommandPublisher`: ``last``, ``republish``)."""

    def __init__(self, node, joints: list[str], topic: str = "joint_commands"):
        self.joints = list(joints)
        self.pub = node.create_publisher(JointState, topic, COMMAND_QOS)
        self._encoder = JointStateEncoder(self.joints, ("effort",), frame_id=node.get_fully_qualified_name())
        self.last: bytes | None = None

    def publish(self, stamp, torques) -> None:
        self.publish_stamp(stamp.sec, stamp.nanosec, torques)

    def publish_stamp(self, sec: int, nanosec: int, torques) -> None:
        self.last = self._encoder.pack(sec, nanosec, *(float(x) for x in torques))
        self.pub.publish(self.last)

    def republish(self) -> bool:
        if self.last is None:
            return False
        self.pub.publish(self.last)
        return True


def stamp_to_ns(stamp) -> int:
    """builtin_interfaces/Time -> integer nanoseconds."""
    return int(stamp.sec) * 1_000_000_000 + int(stamp.nanosec)
