"""``joints`` and the per-joint ROS parameters of the multi-joint nodes (layout:
:mod:`friction_ros.core.joint_config`).

:func:`declare_joint_config` declares the node's schema as usual (node-level values, the defaults
of every joint), then one ROS parameter for each per-joint key given in the parameter files
(``gains.j3.p``, ``friction.j3.model`` ...), with the descriptor and checks of the node-level field
it stands for, so ``ros2 param set /node gains.j3.p 120.0`` is validated like ``pid.p``.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from typing import Any

import rclpy.exceptions
from rcl_interfaces.msg import ParameterDescriptor, ParameterType
from rclpy.parameter import Parameter

from friction_ros.core.config import Field, Schema, flatten, unflatten
from friction_ros.core.joint_config import JointLayout, check_joint_list, joint_values
from friction_ros.core.joint_type import check_joint_type, joint_field
from friction_ros.core.validation import ParameterError
from friction_ros.nodes.parameters import (
    ParameterNode,
    _add_runtime_validation,
    _declare_one,
    _value,
    check_unknown_parameters,
    declare_config,
)


def declare_joints(node: ParameterNode, reserved: set[str]) -> list[str]:
    """Declare ``joints`` (read-only string array) and return the node's joints: the list, or
    ``[joint_name]`` when it is empty (the single-joint case; ``joint_name`` is declared by the
    node's schema)."""
    desc = ParameterDescriptor(
        name="joints",
        type=ParameterType.PARAMETER_STRING_ARRAY,
        description=(
            "the joints this node handles, in joint_states / joint_commands names; per-joint values "
            "as gains.<joint>.<key> and <section>.<joint>.<key> (unset: the one joint joint_name)"
        ),
        read_only=True,
    )
    given = node.given_parameters.pop("joints", None)
    try:
        if given is not None and given.type_ != Parameter.Type.STRING_ARRAY:
            raise rclpy.exceptions.InvalidParameterTypeException(given, "string array")
        joints = node.declare_parameter("joints", Parameter.Type.STRING_ARRAY, desc).value
    except (
        rclpy.exceptions.InvalidParameterTypeException,
        rclpy.exceptions.InvalidParameterValueException,
    ):
        raise ParameterError(
            "joints must be a list of joint names, e.g. joints: [shoulder, elbow] (leave it out for one joint)"
        ) from None
    joints = check_joint_list(list(joints or []), reserved)
    node.joint_prefixes = set(joints)
    return joints


def layout_for(schema: Schema, joints: list[str], gains_section: str | None, plain_keys) -> JointLayout:
    sections = [s.name for s in schema if isinstance(s, Schema)]
    gains = {} if gains_section is None else schema.items.get(gains_section)
    gains_keys = [f.name for f in gains] if isinstance(gains, Schema) else []
    return JointLayout(joints, sections, gains_section, gains_keys, plain_keys)


def declare_joint_config(
    node: ParameterNode,
    schema: Schema,
    joints: list[str],
    apply: Callable[[dict[str, Any]], None] | None = None,
    gains_section: str | None = None,
    plain_keys=(),
) -> tuple[dict[str, Any], JointLayout, dict[str, dict[str, Any]]]:
    """Declare ``schema`` (node level) and the given per-joint keys of ``joints``.

    Returns ``(node values nested, layout, {joint: {node-level name: value}})``. Unknown names,
    per-joint keys of unknown joints' sections or with no node-level counterpart are refused with
    one line naming the key. Node-level fields get the units of the node's ``joint_type``, a
    joint's own fields those of its own ``joint_type`` when it has one.
    """
    layout = layout_for(schema, joints, gains_section, plain_keys)
    per_joint_given = {k: p for k, p in node.given_parameters.items() if layout.split(k) is not None}
    values = declare_config(node, schema, None, check_unknown=False)  # open sections skip joint keys
    by_name = dict(schema.fields())
    types = {j: values.get("joint_type", "revolute") for j in joints}
    for name, param in per_joint_given.items():
        if layout.split(name)[1] == "joint_type":
            types[layout.split(name)[0]] = check_joint_type(param.value, f"{node.get_name()}: {name}")
    open_sections = {p for p, s in schema.sections() if s.open}
    overrides: dict[str, dict[str, Any]] = {j: {} for j in joints}
    for name, param in per_joint_given.items():
        joint, base = layout.split(name)
        spec = by_name.get(base)
        if spec is None:
            section = base.rsplit(".", 1)[0]
            if section not in open_sections:
                raise ParameterError(
                    f"{node.get_name()}: {name} = {param.value!r}: {base} is not a parameter of this "
                    f"node, so it has no per-joint value"
                )
            value = param.value
            default = list(value) if hasattr(value, "tolist") or isinstance(value, tuple) else value
            spec = Field(name, default, f"{joint}: {base}", allow_inf=True)
        else:
            spec = joint_field(dataclasses.replace(spec, name=name, doc=f"{joint}: {spec.doc}"), types[joint])
        _declare_one(node, name, spec)
        node.parameter_fields[name] = spec
        overrides[joint][base] = spec.check(_value(node, name, spec), name)
    check_unknown_parameters(
        node,
        f"per-joint values are gains.<joint>.<key> or <section>.<joint>.<key> for joints "
        f"{', '.join(joints)}; see the node's parameter list (ros2 param list)",
    )
    if apply is not None:  # after every declaration: declaring runs the set-parameter callbacks
        _add_runtime_validation(node, apply)
    return values, layout, overrides


def current_joint_values(
    node: ParameterNode, layout: JointLayout, changes: dict[str, Any] | None = None
) -> tuple[dict[str, Any], dict[str, dict[str, Any]]]:
    """Every declared parameter's current value with ``changes`` applied: (node values nested,
    {joint: {node-level name: value}})."""
    flat = {name: _value(node, name, spec) for name, spec in node.parameter_fields.items()}
    flat.update(changes or {})
    node_flat, per_joint = layout.split_all(flat)
    return unflatten(node_flat), per_joint


def values_of_joint(node_values: dict[str, Any], overrides: dict[str, Any], joint: str, single: bool) -> dict:
    """One joint's nested values (its ``joint_name`` set to the joint)."""
    out = joint_values(node_values, overrides)
    if not single:
        out["joint_name"] = joint
    return out


__all__ = ["declare_joints", "declare_joint_config", "current_joint_values", "values_of_joint", "flatten"]
