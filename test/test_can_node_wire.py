"""drive_interface's wire shortcuts: pre-serialised state messages and the joint_commands reader.

Both must agree exactly with rclpy's own (de)serialiser: StatePackets is checked against
``deserialize_message``; the command path (a raw subscription read by friction_ros.core.wire's
JointStateDecoder, as the node takes it) against messages that went through the middleware.
"""

from __future__ import annotations

import math
import os
import random
import time

import pytest
import rclpy
from friction_msgs.msg import DriveState
from rclpy.executors import SingleThreadedExecutor
from rclpy.qos import QoSProfile
from rclpy.serialization import deserialize_message
from sensor_msgs.msg import JointState

from friction_ros.core.wire import JointStateDecoder
from friction_ros.nodes.drive_state_publishers import StatePackets


@pytest.mark.parametrize(
    "joint,protocol", [("j1", "odrive_cansimple"), ("", "mit"), ("élbow_joint_3", "mit")]
)
def test_state_packets_round_trip(joint, protocol):
    p = StatePackets(joint, protocol)
    assert p.verify() == ""
    js = deserialize_message(p.set_joint(1_700_000_000, 5, math.nan, -0.0, 1e300), JointState)
    assert (js.header.stamp.sec, js.header.stamp.nanosec, list(js.name)) == (1_700_000_000, 5, [joint])
    assert math.isnan(js.position[0]) and js.velocity[0] == 0.0 and js.effort[0] == 1e300
    vals = (math.nan, math.inf, 1.0, 2.0, 3.0, 4.0, 0xFFFFFFFF, 0, 63, False)
    ds = deserialize_message(p.set_drive(3, 999_999_999, *vals), DriveState)
    assert (ds.joint_name, ds.protocol, ds.header.stamp.nanosec) == (joint, protocol, 999_999_999)
    assert math.isnan(ds.motor_position) and ds.motor_velocity == math.inf
    assert (ds.axis_state, ds.axis_error, ds.fault_flags, ds.enabled) == (0xFFFFFFFF, 0, 63, False)


@pytest.mark.ros
def test_raw_commands_decode_like_the_middleware():
    os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    ctx = rclpy.Context()
    rclpy.init(context=ctx)
    try:
        a = rclpy.create_node("wire_sub", context=ctx)
        b = rclpy.create_node("wire_pub", context=ctx)
        topic = f"wire_test_{os.getpid()}"
        qos = QoSProfile(depth=10)
        received: list[bytes] = []
        sub = a.create_subscription(JointState, topic, received.append, qos, raw=True)  # as the node
        executor = SingleThreadedExecutor(context=ctx)
        executor.add_node(a)
        pub = b.create_publisher(JointState, topic, qos)
        rng = random.Random(6)
        dec = JointStateDecoder()
        end = time.time() + 10
        while sub.get_publisher_count() == 0 and time.time() < end:
            time.sleep(0.01)
        for _ in range(120):
            m = JointState()
            m.header.frame_id = "f" * rng.randint(0, 5)
            m.name = ["n" * rng.randint(0, 6) for _ in range(rng.randint(0, 3))]
            m.position = [rng.uniform(-9, 9) for _ in range(rng.randint(0, 3))]
            m.velocity = [rng.uniform(-9, 9) for _ in range(rng.randint(0, 3))]
            m.effort = [rng.uniform(-9, 9) for _ in range(rng.randint(0, 3))]
            pub.publish(m)
            got = None
            for _ in range(500):
                executor.spin_once(timeout_sec=0.002)
                if received:
                    got = received.pop(0)
                    break
            assert got is not None, "message not received"
            assert isinstance(got, bytes)
            cmd = dec.decode(got)
            assert (list(cmd.name), tuple(cmd.effort)) == (list(m.name), tuple(m.effort))
            ref = deserialize_message(got, JointState)
            assert list(ref.effort) == list(m.effort)
        executor.remove_node(a)
        a.destroy_subscription(sub)
    finally:
        rclpy.shutdown(context=ctx)
