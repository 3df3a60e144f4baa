"""The compensating_controller's inputs besides joint states: ``friction_estimate`` (adopted
coefficients) and its references: ``reference`` (trajectory_msgs/JointTrajectory) and
``desired_joint_states`` (sensor_msgs/JointState), checked at the door against each joint's limits
(:mod:`friction_ros.core.control.command_safety`): a trajectory with any sample that is not finite
or beyond a limit is refused whole, with one ERROR line naming the sample; the previous reference
stays."""

from __future__ import annotations

import math

from friction_msgs.msg import FrictionEstimate
from rclpy.serialization import deserialize_message
from sensor_msgs.msg import JointState
from trajectory_msgs.msg import JointTrajectory

from friction_ros.core.coefficient_exchange import from_fields
from friction_ros.core.control.command_safety import check_reference_sample, check_trajectory
from friction_ros.core.experiment.trajectory import TrajectoryReference
from friction_ros.core.validation import ParameterError
from friction_ros.nodes.commands import stamp_to_ns


class ReferenceInputs:
    """Mixin of the compensating_controller node (its ``channels``, ``joints``, ``counts``,
    ``_t0_ns``, ``_last_ns`` and ``_label``)."""

    def _on_trajectory(self, msg: JointTrajectory) -> None:
        names = list(msg.joint_names)
        mine = [ch for ch in self.channels if ch.joint in names]
        try:
            if not mine:
                raise ParameterError(f"none of the joints {', '.join(self.joints)} is in joint_names {names}")
            times = [p.time_from_start.sec + p.time_from_start.nanosec * 1e-9 for p in msg.points]
            stamp = stamp_to_ns(msg.header.stamp)
            if stamp == 0 or self._t0_ns is None:
                start = (self._last_ns - self._t0_ns) * 1e-9 if self._last_ns is not None else 0.0
            else:
                start = (stamp - self._t0_ns) * 1e-9
            built = []
            for ch in mine:
                j = names.index(ch.joint)
                pos = [p.positions[j] if j < len(p.positions) else math.nan for p in msg.points]
                vel = (
                    [p.velocities[j] for p in msg.points]
                    if all(len(p.velocities) > j for p in msg.points)
                    else None
                )
                acc = (
                    [p.accelerations[j] for p in msg.points]
                    if all(len(p.accelerations) > j for p in msg.points)
                    else None
                )
                try:  # refused whole when any sample is not finite or beyond the joint's limits
                    check_trajectory(ch.reference_limits, times, pos, vel, acc)
                except ParameterError as exc:
                    raise ParameterError(f"{self._label(ch)}{exc}") from None
                built.append((ch, TrajectoryReference(times, pos, vel, start_time=start)))
        except ParameterError as exc:
            self.counts["rejected_references"] += 1
            self.get_logger().error(f"rejected reference trajectory: {exc}; keeping the previous reference")
            return
        for ch, traj in built:
            ch.trajectory, ch.desired = traj, None

    def _on_desired(self, msg: JointState) -> None:
        """The arm's desired state per joint (position, velocity; acceleration from the effort
        field is not assumed): the newest one is the reference of the next period."""
        names = list(msg.name)
        for ch in self.channels:
            if ch.joint in names:
                i = names.index(ch.joint)
                pos = float(msg.position[i]) if i < len(msg.position) else math.nan
                vel = float(msg.velocity[i]) if i < len(msg.velocity) else 0.0
                why = check_reference_sample(ch.reference_limits, pos, vel, 0.0)
                if why:
                    self.counts["rejected_references"] += 1
                    self.get_logger().error(
                        f"{self._label(ch)}rejected desired_joint_states: {why}; keeping the previous reference",
                        throttle_duration_sec=1.0,
                    )
                    continue
                ch.desired, ch.trajectory = (pos, vel, 0.0), None

    @property
    def adopting(self) -> bool:
        """Whether any joint adopts the estimator's coefficients (``adopt_estimator_coefficients``)."""
        return any(ch.values.get("adopt_estimator_coefficients") for ch in self.channels)

    def _on_estimate(self, data: bytes) -> None:
        if not self.adopting:
            return  # nothing adopts: no message object
        msg = deserialize_message(data, FrictionEstimate)
        if not msg.converged:
            return
        ch = self._by_joint.get(msg.joint_name) if msg.joint_name else self.channels[0]
        if ch is None or not ch.values.get("adopt_estimator_coefficients"):
            return
        try:
            ch.controller.set_coefficients(from_fields(msg.model, msg.coefficient_names, msg.coefficients))
            self.counts["adopted"] += 1
        except (ParameterError, ValueError) as exc:
            self.counts["rejected_estimates"] += 1
            self.get_logger().warning(
                f"{self._label(ch)}estimator coefficients not adopted: {exc}", throttle_duration_sec=5.0
            )
