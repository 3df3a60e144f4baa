"""joint_states and drive_state of drive_interface, published as pre-serialised CDR bytes.

Both are packed by the wire encoders of :mod:`friction_ros.core.wire` (one ``struct.pack`` each)
and published as bytes (same wire types): no message objects, no rclpy conversion, no middleware
serialisation per period. The packers are checked once against rclpy's own deserialiser; message
objects are published instead if the check fails, and for joint_states that carry only some of the
drives (no made-up values for a drive without fresh telemetry).
"""

from __future__ import annotations

import math

from friction_msgs.msg import DriveState
from rclpy.node import Node
from rclpy.serialization import deserialize_message
from sensor_msgs.msg import JointState

from friction_ros.core.can.axis import DriveAxis, JointSample
from friction_ros.core.can.drive_set import AxisPort
from friction_ros.core.wire import DriveStateEncoder, JointStateEncoder
from friction_ros.nodes.qos import RECORDED_QOS, SENSOR_QOS


class StatePackets:
    """joint_states of one joint and its drive_state as CDR bytes (rclpy ``publish_raw``).

    :meth:`verify` checks both against rclpy's deserialiser.
    """

    def __init__(self, joint: str, protocol: str):
        self.joint, self.protocol = joint, protocol
        self.set_joint = JointStateEncoder([joint]).pack  # (sec, nanosec, position, velocity, effort)
        # (sec, nanosec, motor_position .. bus_voltage, axis_state, axis_error, fault_flags, enabled)
        self.set_drive = DriveStateEncoder(joint, protocol).pack

    def verify(self) -> str:
        """Empty string when both templates deserialise to exactly the values packed, else why not."""
        try:
            js = deserialize_message(self.set_joint(12, 345, 1.5, -2.25, 3.125), JointState)
            ok_js = (
                (js.header.stamp.sec, js.header.stamp.nanosec, js.header.frame_id) == (12, 345, "")
                and list(js.name) == [self.joint]
                and (list(js.position), list(js.velocity), list(js.effort)) == ([1.5], [-2.25], [3.125])
            )
            vals = (0.5, -1.5, 2.5, -3.5, 4.5, 24.0, 8, 0xDEADBEEF, 33, True)
            ds = deserialize_message(self.set_drive(-7, 999_999_999, *vals), DriveState)
            got = (
                ds.motor_position, ds.motor_velocity, ds.current_setpoint, ds.current_measured,
                ds.torque_estimate, ds.bus_voltage, ds.axis_state, ds.axis_error, ds.fault_flags, ds.enabled,
            )  # fmt: skip
            ok_ds = (
                (ds.header.stamp.sec, ds.header.stamp.nanosec, ds.header.frame_id) == (-7, 999_999_999, "")
                and (ds.joint_name, ds.protocol) == (self.joint, self.protocol)
                and got == vals
            )
        except Exception as exc:
            return f"{type(exc).__name__}: {exc}"
        return "" if ok_js and ok_ds else "round trip through rclpy's deserialiser differs"


def drive_values(axis: DriveAxis, sample: JointSample | None, flags: int) -> tuple:
    """The drive_state fields of ``axis`` after a period (motor position/velocity NaN without a sample)."""
    tel = axis.telemetry
    return (
        tel.motor_position if sample is not None else math.nan,
        tel.motor_velocity if sample is not None else math.nan,
        tel.current_setpoint,
        tel.current_measured,
        tel.torque_estimate,
        tel.bus_voltage,
        tel.axis_state & 0xFFFFFFFF,
        tel.axis_error & 0xFFFFFFFF,
        flags,
        axis.enabled,
    )


class DriveStatePublishers:
    """``joint_states`` (every joint in one message, RECORDED_QOS) and ``drive_state`` (one message
    per drive, SENSOR_QOS) of the drives ``joints`` speaking ``protocol``."""

    def __init__(self, node: Node, joints: list[str], protocol: str):
        self.joints = list(joints)
        self.pub_joint = node.create_publisher(JointState, "joint_states", RECORDED_QOS)
        self.pub_drive = node.create_publisher(DriveState, "drive_state", SENSOR_QOS)
        self.packets = [StatePackets(j, protocol) for j in self.joints]
        self._ds = [DriveState(joint_name=j, protocol=protocol) for j in self.joints]
        n = len(self.joints)
        self._js = JointState(
            name=list(self.joints), position=[0.0] * n, velocity=[0.0] * n, effort=[0.0] * n
        )
        self._pack_joints = JointStateEncoder(
            self.joints
        ).pack  # (sec, nsec, *positions, *velocities, *efforts)
        # why the packers cannot be used ("" = they can)
        self.fallback_reason = self.packets[0].verify() or self._verify_joint_packer()
        self.raw = not self.fallback_reason

    def _verify_joint_packer(self) -> str:
        n = len(self.joints)
        vals = [0.5 + i for i in range(3 * n)]
        try:
            js = deserialize_message(self._pack_joints(3, 4, *vals), JointState)
        except Exception as exc:
            return f"{type(exc).__name__}: {exc}"
        got = [*js.position, *js.velocity, *js.effort]
        return "" if list(js.name) == self.joints and got == vals else "joint_states template differs"

    def publish_joints(self, sec: int, nsec: int, samples: list[JointSample | None]) -> None:
        """joint_states of the period: every joint, or only those with a sample (None: no fresh telemetry)."""
        if None not in samples:
            if self.raw:
                self.pub_joint.publish(
                    self._pack_joints(
                        sec,
                        nsec,
                        *[s.position for s in samples],
                        *[s.velocity for s in samples],
                        *[s.effort for s in samples],
                    )
                )
            else:
                self._publish_joint_objects(sec, nsec, self.joints, samples)
        elif any(s is not None for s in samples):  # no made-up values: only the drives with telemetry
            fresh = [(j, s) for j, s in zip(self.joints, samples) if s is not None]
            self._publish_joint_objects(sec, nsec, [j for j, _ in fresh], [s for _, s in fresh])

    def drive_state_wanted(self) -> bool:
        """Someone listens on drive_state (else nothing is sent)."""
        return self.pub_drive.get_subscription_count() > 0

    def publish_drives(
        self, sec: int, nsec: int, ports: list[AxisPort], samples: list[JointSample | None]
    ) -> None:
        """drive_state of every drive after a period (``samples``: their joint samples)."""
        for k, (port, sample) in enumerate(zip(ports, samples)):
            self.publish_drive(k, sec, nsec, drive_values(port.axis, sample, port.flags))

    def publish_drive(self, k: int, sec: int, nsec: int, drive: tuple) -> None:
        """drive_state of drive ``k`` with the fields :func:`drive_values` returns."""
        if self.raw:
            self.pub_drive.publish(self.packets[k].set_drive(sec, nsec, *drive))
            return
        ds = self._ds[k]
        ds.header.stamp.sec, ds.header.stamp.nanosec = sec, nsec
        (
            ds.motor_position, ds.motor_velocity, ds.current_setpoint, ds.current_measured, ds.torque_estimate,
            ds.bus_voltage, ds.axis_state, ds.axis_error, ds.fault_flags, ds.enabled,
        ) = drive  # fmt: skip
        self.pub_drive.publish(ds)

    def _publish_joint_objects(self, sec: int, nsec: int, joints: list[str], samples: list) -> None:
        """joint_states as a message object (fallback path, or a subset of the joints)."""
        js = self._js if len(joints) == len(self.joints) else JointState()
        js.header.stamp.sec, js.header.stamp.nanosec = sec, nsec
        js.name = list(joints)
        js.position = [s.position for s in samples]
        js.velocity = [s.velocity for s in samples]
        js.effort = [s.effort for s in samples]
        self.pub_joint.publish(js)
