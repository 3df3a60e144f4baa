"""One owner per joint command, over DDS: two controllers on one simulated joint (references 0 and
0.5 rad) used to swing it -0.1..0.71 rad with commands of +-120 N*m and no log line. The plant now
refuses to follow two sources (zero torque, ERROR naming both), both controllers report the conflict
in their log and diagnostics, and when one controller stops the conflict clears and the other one
controls the joint. Two controllers each commanding its own joint of one plant are no conflict
(test_plant_multi_joint)."""

from __future__ import annotations

import time

import pytest
from ros_graph import Graph, Listener, write_params

from friction_ros.cli.bringup import NodeSpec
from friction_ros.nodes.qos import RECORDED_QOS

pytestmark = pytest.mark.ros


def _controller(tmp_path, name: str, offset: float) -> NodeSpec:
    params = {
        "mode": "pid",
        "effort_limit": 4.9,
        "pid": {"p": 200.0, "d": 0.15},
        "reference": {"type": "constant", "offset": offset},
    }
    path = write_params(tmp_path / f"{name}.yaml", {f"/**/{name}": {"ros__parameters": params}})
    return NodeSpec("compensating_controller", "", [path], name=name)


@pytest.mark.realtime  # wall-clock timing: a CPU of its own, after the other tests
def test_two_controllers_on_one_joint_are_refused_and_reported(tmp_path):
    from diagnostic_msgs.msg import DiagnosticArray
    from sensor_msgs.msg import JointState

    plant = NodeSpec("plant_simulator", "", [], {"preset": "abb_m19s", "mode": "realtime"})
    first = _controller(tmp_path, "ctrl_a", 0.5)
    second = _controller(tmp_path, "ctrl_b", 0.0)
    with Listener() as lis:
        states = lis.subscribe(JointState, "joint_states", RECORDED_QOS)
        diags = lis.subscribe(DiagnosticArray, "diagnostics")
        with Graph([plant, first]) as g:
            assert lis.wait_for(lambda: len(states) > 100, 60, g)
            # one controller: it moves the joint towards 0.5 rad
            assert lis.wait_for(lambda: states[-1].position[0] > 0.3, 30, g), states[-1].position
            with Graph([second]) as g2:
                assert lis.wait_for(
                    lambda: "commanded by 2 sources on /joint_commands" in g.output("plant_simulator"), 30, g
                )
                n = len(states)
                time.sleep(1.5)
                held = [m.position[0] for m in states[n:]]
                assert held, "no joint states during the conflict"
                # zero torque: the joint coasts to rest wherever it was; it does not swing between the
                # two references
                assert max(held) - min(held) < 0.1, (min(held), max(held))
                plant_log = g.output("plant_simulator")
                line = next(ln for ln in plant_log.splitlines() if "commanded by 2 sources" in ln)
                assert "ERROR" in line and "/ctrl_a" in line and "/ctrl_b" in line and "zero torque" in line
                assert lis.wait_for(
                    lambda: any(
                        s.level in (2, b"\x02") and "two command sources on /joint_commands" in s.message
                        for m in diags
                        for s in m.status
                    ),
                    10,
                    g2,
                ), "no diagnostics ERROR from a controller"
                # the second controller sees the first one on its topic once its own reader of that
                # topic has matched the first one's publisher (discovery: up to seconds on a loaded machine)
                assert lis.wait_for(lambda: "commanded by 2 sources" in g2.output("ctrl_b"), 15, g2), (
                    g2.output("ctrl_b")
                )
            # the second controller stopped: cleared, the first one controls again
            assert lis.wait_for(lambda: "cleared" in g.output("plant_simulator"), 30, g)
            assert lis.wait_for(lambda: abs(states[-1].position[0] - 0.5) < 0.05, 30, g), states[-1].position
            g.assert_alive()
