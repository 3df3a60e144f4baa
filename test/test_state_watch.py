"""The experiment CLI's first-state watch: its waits are bounded whatever the graph does, so the CLI's
own wall-time limit always holds (the spinning happens in a thread of the watch's own)."""

from __future__ import annotations

import time

import pytest

pytest.importorskip("rclpy")

from friction_ros.cli.state_watch import FirstStateWatch  # noqa: E402


def test_poll_and_close_return_within_their_bounds_when_no_state_comes():
    watch = FirstStateWatch("/friction_state_watch_test/nobody_publishes_here")
    try:
        t0 = time.monotonic()
        assert watch.poll(0.3) is False
        assert 0.25 <= time.monotonic() - t0 < 2.0
        assert watch.seen is False
    finally:
        t0 = time.monotonic()
        watch.close(grace=2.0)
        assert time.monotonic() - t0 < 5.0
    watch.close()  # a second close does nothing
    assert watch.poll(0.0) is False


def test_a_published_state_is_seen():
    import rclpy
    from sensor_msgs.msg import JointState

    topic = "/friction_state_watch_test/joint_states"
    watch = FirstStateWatch(topic)
    ctx = rclpy.Context()
    rclpy.init(args=[], context=ctx)
    node = rclpy.create_node("friction_state_watch_test_pub", context=ctx)
    pub = node.create_publisher(JointState, topic, 10)
    try:
        deadline = time.monotonic() + 20.0
        while not watch.poll(0.1) and time.monotonic() < deadline:
            pub.publish(JointState(name=["joint1"], position=[0.0], velocity=[0.0], effort=[0.0]))
        assert watch.seen
    finally:
        watch.close()
        node.destroy_node()
        ctx.try_shutdown()
