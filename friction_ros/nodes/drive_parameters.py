"""drive_interface's parameters: the bus and the loop, one drive (:data:`~friction_ros.core.can.axis_config.AXIS_SCHEMA`),
the scheduling and, with ``joints``, every drive's own ``<joint>.<key>``
(:data:`~friction_ros.core.can.drive_set.AXIS_KEYS`)."""

from __future__ import annotations

from collections.abc import Callable

import can
import rclpy
from rcl_interfaces.msg import ParameterDescriptor, ParameterType
from rclpy.parameter import Parameter

from friction_ros.core.can.axis_config import AXIS_SCHEMA
from friction_ros.core.can.drive_set import AXIS_KEYS, axis_param_specs, axis_values, check_joint_names
from friction_ros.core.config import Field, Schema, flatten
from friction_ros.core.control_period import DEFAULT_CONTROL_PERIOD
from friction_ros.core.joint_type import check_joint_type, joint_schema
from friction_ros.core.validation import ParameterError
from friction_ros.nodes.parameters import SCHEDULING, ParameterNode, declare_config

INTERFACES = tuple(sorted(can.VALID_INTERFACES))

NODE_FIELDS = [
    Field(
        "interface",
        "socketcan",
        "python-can interface (socketcan on robots; virtual in tests)",
        choices=INTERFACES,
        read_only=True,
    ),
    Field("channel", "can0", "CAN channel (socketcan: network interface name)", read_only=True),
    Field(
        "bitrate",
        1000000,
        "bitrate for interfaces that set it (socketcan: set with ip link)",
        lo=10000,
        hi=1000000,
        read_only=True,
        unit="bit/s",
    ),
    Field("joint_name", "joint1", "joint name in joint_states / joint_commands", read_only=True),
    Field(
        "control_period",
        DEFAULT_CONTROL_PERIOD,
        "period of the joint_states publication and the torque commands (1 / the rate)",
        lo=2e-4,
        hi=1.0,
        read_only=True,
        unit="s",
    ),
    Field(
        "enable_on_start", False, "enable the drive (closed loop, zero torque) as soon as telemetry arrives"
    ),
    Field(
        "loop_spin",
        0.0,
        "busy-wait before each period for timing accuracy (costs spin/period of a core)",
        lo=0.0,
        hi=0.001,
        read_only=True,
        unit="s",
    ),
    Field("diagnostics_period", 1.0, "diagnostics publication period", lo=0.05, hi=60.0, unit="s"),
    Field("bus_error_limit", 20, "consecutive failed sends before the bus counts as dead", lo=1, hi=100000),
    Field("bus_recovery_period", 1.0, "wait before reopening a dead bus", lo=0.01, hi=60.0, unit="s"),
]


def parameter_schema(joint_type: str = "revolute") -> Schema:
    """The node's parameters: the bus and loop, one drive (:data:`~friction_ros.core.can.axis_config.AXIS_SCHEMA`;
    with ``joints``, :data:`~friction_ros.core.can.drive_set.AXIS_KEYS` also per joint) and the
    scheduling, in the units of ``joint_type``."""
    return joint_schema(Schema("drive_interface", [*NODE_FIELDS, *AXIS_SCHEMA, *SCHEDULING]), joint_type)


def declare_joints(node: ParameterNode) -> list[str]:
    """Declare and validate ``joints`` (several axes on one bus); [] = one axis (``joint_name``)."""
    desc = ParameterDescriptor(
        name="joints",
        type=ParameterType.PARAMETER_STRING_ARRAY,
        description=(
            "several drives on this bus: their joint names, each with its own <joint>.node_id (and "
            "optionally <joint>.gear_ratio, torque_constant, direction, zero_offset, limits); "
            "unset = one drive (joint_name, node_id)"
        ),
        read_only=True,
    )
    try:
        joints = node.declare_parameter("joints", Parameter.Type.STRING_ARRAY, desc).value
    except (
        rclpy.exceptions.InvalidParameterTypeException,
        rclpy.exceptions.InvalidParameterValueException,
    ):
        raise ParameterError(
            "joints must be a list of joint names, e.g. joints: [shoulder, elbow] (leave it out for one drive)"
        ) from None
    joints = list(joints or [])
    check_joint_names(joints, {name.split(".")[0] for name, _ in parameter_schema().fields()})
    return joints


def declare_drive_parameters(
    node: ParameterNode, apply: Callable[[dict], None]
) -> tuple[list[str], dict, list[dict]]:
    """Declare every parameter of the node: ``(joints, the node-level values, each drive's values)``.

    Run-time changes of any of them go to ``apply`` (see
    :func:`~friction_ros.nodes.parameters.declare_config`); ``<joint>.joint_type`` given at start
    sets the units of that joint's parameters.
    """
    joints = declare_joints(node)
    v = flatten(declare_config(node, parameter_schema(), check_unknown=not joints))
    given = {j: node.given_parameters.get(f"{j}.joint_type") for j in joints}
    types = {j: check_joint_type(p.value, f"{j}.joint_type") for j, p in given.items() if p is not None}
    per_joint = flatten(declare_config(node, Schema("axes", axis_param_specs(joints, v, types)), apply))
    return joints, v, axis_values(joints, v, per_joint, AXIS_KEYS)
