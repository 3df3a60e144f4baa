"""The compensating_controller's inputs besides joint states, unpacked from their messages for
its :class:`~friction_ros.core.joint_group.JointGroup` (which checks them at the door):
``reference`` (trajectory_msgs/JointTrajectory), ``desired_joint_states`` (sensor_msgs/JointState)
and ``friction_estimate`` (adopted coefficients, friction_msgs/FrictionEstimate)."""

from __future__ import annotations

from friction_msgs.msg import FrictionEstimate
from rclpy.serialization import deserialize_message
from sensor_msgs.msg import JointState
from trajectory_msgs.msg import JointTrajectory

from friction_ros.nodes.commands import stamp_to_ns


class ReferenceInputs:
    """Mixin of the compensating_controller node (its ``group``)."""

    def _on_trajectory(self, msg: JointTrajectory) -> None:
        pts = msg.points
        why = self.group.set_trajectory(
            msg.joint_names,
            [p.time_from_start.sec + p.time_from_start.nanosec * 1e-9 for p in pts],
            stamp_to_ns(msg.header.stamp),
            [p.positions for p in pts],
            [p.velocities for p in pts],
            [p.accelerations for p in pts],
        )
        if why:
            self.get_logger().error(f"rejected reference trajectory: {why}; keeping the previous reference")

    def _on_desired(self, msg: JointState) -> None:
        """The arm's desired state per joint (position, velocity; acceleration from the effort
        field is not assumed): the newest one is the reference of the next period."""
        for why in self.group.set_desired(msg.name, msg.position, msg.velocity):
            self.get_logger().error(why, throttle_duration_sec=1.0)

    def _on_estimate(self, data: bytes) -> None:
        if not self.group.adopting:
            return  # nothing adopts: no message object
        msg = deserialize_message(data, FrictionEstimate)
        if msg.converged:
            why = self.group.adopt(msg.joint_name, msg.model, msg.coefficient_names, msg.coefficients)
            if why:
                self.get_logger().warning(why, throttle_duration_sec=5.0)
