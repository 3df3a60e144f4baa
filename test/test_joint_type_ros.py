"""joint_type on the ROS nodes: a prismatic joint's parameters are described in m, m/s and N, a bad
joint type is one line, and a plant_simulator process started from a YAML file reports it."""

from __future__ import annotations

import os
import time

import pytest
from ros_graph import Graph, Listener, write_params

from friction_ros.cli.bringup import NodeSpec
from friction_ros.core.validation import ParameterError

pytestmark = pytest.mark.ros


def _in_process(cls, params: str):
    """Build node ``cls`` from a parameter file in this process; returns it (destroyed by the caller)."""
    import rclpy

    rclpy.init(args=["--ros-args", "--params-file", params])
    try:
        return cls()
    except BaseException:
        rclpy.try_shutdown()
        raise


def _close(node) -> None:
    import rclpy

    try:
        if hasattr(node, "on_shutdown"):
            node.on_shutdown()
        node.destroy_node()
    finally:
        rclpy.try_shutdown()


def _description(node, name: str) -> str:
    return node.describe_parameter(name).description


def test_bad_joint_type_is_one_line_naming_the_choices(tmp_path):
    from friction_ros.nodes.plant_simulator import PlantSimulator

    params = write_params(
        tmp_path / "p.yaml", {"plant_simulator": {"ros__parameters": {"joint_type": "linear"}}}
    )
    with pytest.raises(ParameterError) as e:
        _in_process(PlantSimulator, params)
    text = str(e.value)
    assert "\n" not in text
    assert text == "plant_simulator: joint_type = 'linear' is not allowed: must be one of revolute, prismatic"


def test_prismatic_controller_and_estimator_speak_newtons_and_metres(tmp_path):
    from friction_ros.nodes.compensating_controller import CompensatingControllerNode
    from friction_ros.nodes.friction_estimator import FrictionEstimatorNode

    doc = {
        "compensating_controller": {
            "ros__parameters": {
                "joint_type": "prismatic",
                "effort_limit": 500.0,
                "friction": {"model": "coulomb_viscous", "fc": 10.0, "fv": 50.0},
            }
        },
        "friction_estimator": {
            "ros__parameters": {"joint_type": "prismatic", "model": "coulomb_viscous", "inertia": 35.0}
        },
    }
    params = write_params(tmp_path / "p.yaml", doc)
    node = _in_process(CompensatingControllerNode, params)
    try:
        assert node.get_parameter("joint_type").value == "prismatic"
        assert _description(node, "u_clamp_max").endswith("[N]")
        assert _description(node, "inertia").endswith("[kg]")
        assert _description(node, "feedforward_gain").endswith("[N*s/m]")
        assert node.describe_parameter("joint_type").read_only
    finally:
        _close(node)
    node = _in_process(FrictionEstimatorNode, params)
    try:
        assert node.get_parameter("joint_type").value == "prismatic"
        assert _description(node, "min_velocity").endswith("[m/s]")
        assert _description(node, "observer_bandwidth").endswith("[rad/s]")  # a frequency
    finally:
        _close(node)


def test_prismatic_friction_coefficient_error_names_newtons(tmp_path):
    from friction_ros.nodes.compensating_controller import CompensatingControllerNode

    doc = {
        "compensating_controller": {
            "ros__parameters": {
                "joint_type": "prismatic",
                "friction": {"model": "lugre", "fc": 0.0, "fs": 1.0, "vs": 0.1, "sigma0": 1e4, "sigma1": 1.0},
            }
        }
    }
    with pytest.raises(ParameterError) as e:
        _in_process(CompensatingControllerNode, write_params(tmp_path / "p.yaml", doc))
    assert str(e.value) == "friction.fc = 0 is out of range: must be > 0 [N]"


def test_per_joint_type_on_a_multi_joint_controller(tmp_path):
    """gains.<joint>.joint_type: each joint's own parameters are described in its own units."""
    from friction_ros.nodes.compensating_controller import CompensatingControllerNode

    doc = {
        "compensating_controller": {
            "ros__parameters": {
                "joints": ["x", "wrist"],
                "friction": {"model": "coulomb_viscous", "fc": 1.0, "fv": 0.1},
                "gains": {
                    "x": {"joint_type": "prismatic", "u_clamp_max": 200.0, "effort_limit": 300.0},
                    "wrist": {"u_clamp_max": 2.0, "effort_limit": 3.0},
                },
            }
        }
    }
    node = _in_process(CompensatingControllerNode, write_params(tmp_path / "p.yaml", doc))
    try:
        assert node.get_parameter("joint_type").value == "revolute"
        assert node.get_parameter("gains.x.joint_type").value == "prismatic"
        assert _description(node, "gains.x.u_clamp_max").endswith("[N]")
        assert _description(node, "gains.wrist.u_clamp_max").endswith("[N*m]")
    finally:
        _close(node)


def test_prismatic_drive_without_lead_is_refused(tmp_path):
    from friction_ros.nodes.drive_interface import DriveInterface

    base = {"joint_type": "prismatic", "interface": "virtual", "channel": "jt_test"}
    params = write_params(tmp_path / "p.yaml", {"drive_interface": {"ros__parameters": base}})
    with pytest.raises(ParameterError, match=r"joint_type = prismatic needs lead > 0 \[m/rev\]"):
        _in_process(DriveInterface, params)
    params = write_params(
        tmp_path / "q.yaml", {"drive_interface": {"ros__parameters": {**base, "lead": 0.005}}}
    )
    node = _in_process(DriveInterface, params)
    try:
        assert node.axis.cfg.conversion.joint_position(6.283185307179586) == pytest.approx(0.005)
        assert _description(node, "torque_limit").endswith("[N]")
        assert _description(node, "torque_constant").endswith("[N*m/A]")  # the motor's own
    finally:
        _close(node)


def test_plant_simulator_process_reports_prismatic_from_its_yaml(tmp_path):
    """A plant_simulator process started with a parameter file: its parameters over ROS say prismatic."""
    from rcl_interfaces.srv import DescribeParameters, GetParameters

    params = write_params(
        tmp_path / "plant.yaml",
        {"/**/plant_simulator": {"ros__parameters": {"joint_type": "prismatic", "preset": "seed002_x"}}},
    )
    ns = f"joint_type_{os.getpid()}"  # a namespace of its own: no other plant answers
    with Listener("joint_type_probe") as lis, Graph([NodeSpec("plant_simulator", ns, [params])]) as g:
        get = lis.node.create_client(GetParameters, f"/{ns}/plant_simulator/get_parameters")
        describe = lis.node.create_client(DescribeParameters, f"/{ns}/plant_simulator/describe_parameters")
        deadline = time.monotonic() + 60
        while not (get.service_is_ready() and describe.service_is_ready()):
            g.assert_alive()
            assert time.monotonic() < deadline, "plant_simulator's parameter services never came up"
            time.sleep(0.1)
        values = get.call_async(GetParameters.Request(names=["joint_type", "preset"]))
        descs = describe.call_async(DescribeParameters.Request(names=["initial_position", "max_effort"]))
        assert lis.wait_for(lambda: values.done() and descs.done(), 30, g)
        assert [v.string_value for v in values.result().values] == ["prismatic", "seed002_x"]
        d = descs.result().descriptors
        assert d[0].description.endswith("[m]") and d[1].description.endswith("[N]")


def test_drives_of_both_types_on_one_bus(tmp_path):
    """<joint>.joint_type and <joint>.lead: a screw axis and a rotary wrist on one drive_interface."""
    from friction_ros.nodes.drive_interface import DriveInterface

    params = {
        "interface": "virtual",
        "channel": "jt_multi",
        "joints": ["x", "wrist"],
        "x": {"node_id": 1, "joint_type": "prismatic", "lead": 0.01},
        "wrist": {"node_id": 2, "gear_ratio": 10.0},
    }
    node = _in_process(
        DriveInterface, write_params(tmp_path / "p.yaml", {"drive_interface": {"ros__parameters": params}})
    )
    try:
        x, wrist = (a.cfg.conversion for a in node.axes)
        assert x.joint_position(2 * 3.141592653589793) == pytest.approx(0.01)
        assert wrist.joint_position(10.0) == pytest.approx(1.0)
        assert _description(node, "x.torque_limit").endswith("[N]")
        assert _description(node, "wrist.torque_limit").endswith("[N*m]")
    finally:
        _close(node)
