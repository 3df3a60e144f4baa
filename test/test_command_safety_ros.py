"""Commands finite and inside the joint's limits over DDS (plant_simulator + compensating_controller as
processes): absurd references and run-time parameters as an attacker or a careless user sends them,
a node without a torque limit, and the compensation watch in realtime mode on a correct and on an
over-compensating file."""

from __future__ import annotations

import math
import subprocess
import sys

import pytest
from ros_graph import Graph, Listener, write_params

from friction_ros.cli.bringup import NodeSpec
from friction_ros.core.experiment.joint_scale import JointScale
from friction_ros.core.experiment.tracking_design import tracking_gains, tracking_reference
from friction_ros.core.presets import load_preset
from friction_ros.nodes.qos import RECORDED_QOS

pytestmark = pytest.mark.ros

LIMIT = 4.9  # the abb_m19s preset's drive limit [N*m]


def _controller(tmp_path, **params) -> str:
    base = {"mode": "pid", "effort_limit": LIMIT, "pid": {"p": 200.0, "d": 0.15}, "state_timeout": 5.0}
    return write_params(
        tmp_path / "c.yaml", {"compensating_controller": {"ros__parameters": {**base, **params}}}
    )


def test_a_controller_without_a_torque_limit_does_not_start(tmp_path):
    path = write_params(
        tmp_path / "p.yaml", {"compensating_controller": {"ros__parameters": {"mode": "pid"}}}
    )
    out = subprocess.run(
        [
            sys.executable,
            "-m",
            "friction_ros.nodes.compensating_controller",
            "--ros-args",
            "--params-file",
            path,
        ],
        capture_output=True,
        text=True,
        timeout=60,
    )
    lines = [ln for ln in out.stderr.splitlines() if ln.strip()]
    assert out.returncode == 2 and len(lines) == 1 and "effort_limit is not set" in lines[0], out.stderr


def test_absurd_references_and_parameters_never_command_beyond_the_limit(tmp_path):
    from rcl_interfaces.msg import Parameter, ParameterType, ParameterValue
    from rcl_interfaces.srv import SetParameters
    from sensor_msgs.msg import JointState
    from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

    specs = [
        NodeSpec("plant_simulator", "", [], {"preset": "abb_m19s", "mode": "realtime"}),
        NodeSpec("compensating_controller", "", [_controller(tmp_path)]),
    ]
    with Listener() as lis:
        commands = lis.subscribe(JointState, "joint_commands", RECORDED_QOS)
        client = lis.node.create_client(SetParameters, "compensating_controller/set_parameters")
        traj_pub = lis.publisher(JointTrajectory, "reference")
        desired_pub = lis.publisher(JointState, "desired_joint_states")
        with Graph(specs) as g:
            assert lis.wait_for(lambda: len(commands) > 200, 60, g)
            assert client.wait_for_service(timeout_sec=20)

            def set_param(name, **value):
                req = SetParameters.Request(
                    parameters=[
                        Parameter(
                            name=name, value=ParameterValue(type=ParameterType.PARAMETER_DOUBLE, **value)
                        )
                    ]
                )
                fut = client.call_async(req)
                assert lis.wait_for(fut.done, 20)
                return fut.result().results[0]

            def settle(n=300):
                k = len(commands)
                assert lis.wait_for(lambda: len(commands) > k + n, 30, g)

            # a trajectory whose velocity is 1e308: refused whole (beyond the plausible speed)
            traj = JointTrajectory(joint_names=["joint1"])
            traj.points = [JointTrajectoryPoint(positions=[0.0], velocities=[1e308])]
            traj.points[0].time_from_start.sec = 1
            traj_pub.publish(traj)
            settle()
            assert (
                "rejected reference trajectory: point 0 (t = 1 s): reference velocity 1e+308 exceeds"
                in g.output("compensating_controller")
            )
            # a desired position of 1e300 rad: not a joint position (the input gate's bound): refused
            desired_pub.publish(JointState(name=["joint1"], position=[1e300], velocity=[0.0]))
            settle()
            assert "rejected desired_joint_states: reference position 1e+300 is outside" in g.output(
                "compensating_controller"
            )
            # 1e6 rad (plausible, no position limits set): followed, with at most the limit
            desired_pub.publish(JointState(name=["joint1"], position=[1e6], velocity=[0.0]))
            settle()
            # run-time parameters out of physical range are refused; an infinite clamp leaves the limit
            assert not set_param("pid.p", double_value=1e308).successful
            assert not set_param("effort_limit", double_value=math.inf).successful
            assert set_param("u_clamp_max", double_value=math.inf).successful
            desired_pub.publish(JointState(name=["joint1"], position=[-1e6], velocity=[0.0]))
            settle()
            g.assert_alive()
    efforts = [m.effort[0] for m in commands]
    assert all(math.isfinite(u) and abs(u) <= LIMIT for u in efforts), max(map(abs, efforts))
    assert max(efforts) == pytest.approx(LIMIT) and min(efforts) == pytest.approx(-LIMIT)


@pytest.mark.parametrize("edited", [False, True], ids=["fitted", "coulomb_x4_gain_2"])
def test_the_watch_in_realtime_mode(tmp_path, edited):
    """The true friction as the model (what a good fit writes): no fallback in realtime mode; the same
    file with Coulomb x4 and gain 2: over-compensation, switched off, one ERROR line."""
    from diagnostic_msgs.msg import DiagnosticArray

    preset = load_preset("abb_m19s")
    scale = JointScale.from_preset(preset, period=1e-3)
    gains = tracking_gains(scale)
    model = preset.friction.to_config()
    if edited:
        model = {**model, "fc": 4.0 * model["fc"], "fs": 4.0 * model["fs"]}
    path = _controller(
        tmp_path,
        pid={"p": gains["p"], "d": gains["d"]},
        inertia=scale.inertia,
        friction=model,
        compensation={"source": "blended", "gain": 2.0 if edited else 1.0},
        reference=tracking_reference(scale, duration=20.0),
        diagnostics_period=0.2,
    )
    specs = [
        NodeSpec("plant_simulator", "", [], {"preset": "abb_m19s", "mode": "realtime"}),
        NodeSpec("compensating_controller", "", [path]),
    ]
    with Listener() as lis:
        diags = lis.subscribe(DiagnosticArray, "diagnostics")

        def fallback() -> bool:
            return any(
                kv.key == "compensation_fallback" and kv.value == "1"
                for m in diags
                for s in m.status
                for kv in s.values
            )

        with Graph(specs) as g:
            assert lis.wait_for(lambda: len(diags) > 3, 60, g)
            got = lis.wait_for(fallback, 6.0, g)
            out = g.output("compensating_controller")
            g.assert_alive()
    if edited:
        assert got and "over-compensation" in out, out[-2000:]
        assert sum("friction compensation switched off" in ln for ln in out.splitlines()) == 1
    else:
        assert not got and "switched off" not in out, out[-2000:]
