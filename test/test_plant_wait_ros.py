"""A lockstep plant with ``wait_for_subscribers`` publishes its first state only once that many
subscribers listen on joint_states (a monitor or recorder then sees the run from its first period)."""

from __future__ import annotations

import time

import pytest
from ros_graph import Graph, Listener

from friction_ros.cli.bringup import NodeSpec
from friction_ros.nodes.qos import STATE_QOS

pytestmark = pytest.mark.ros


def test_the_first_state_waits_for_the_subscribers_asked_for():
    from sensor_msgs.msg import JointState

    spec = NodeSpec("plant_simulator", "", [], {"mode": "lockstep", "wait_for_subscribers": 2})
    with Listener() as lis, Graph([spec]) as g:
        first = lis.subscribe(JointState, "/joint_states")
        assert lis.wait_for(lambda: lis.matched("/joint_states") == 1, 30, g), (
            "the plant was never discovered"
        )
        time.sleep(1.5)  # seven resend periods with one subscriber: nothing goes out
        assert first == []
        second: list = []
        lis.node.create_subscription(JointState, "/joint_states", second.append, STATE_QOS)
        assert lis.wait_for(lambda: first and second, 30, g), "no state after the second subscriber came"
        g.assert_alive()
    # nothing was answered: the plant holds its first state (stamp 0) and offers it again
    assert first[0].header.stamp.sec == 0 and first[0].header.stamp.nanosec == 0
    assert second[0].header.stamp.sec == 0 and second[0].header.stamp.nanosec == 0
