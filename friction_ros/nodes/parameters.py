"""ROS parameters of the friction_ros nodes, derived from the configuration schemas.

Every node describes its parameters as a :class:`~friction_ros.core.config.Schema` (its own fields
plus the sections of the core objects it builds) and calls :func:`declare_config` once: that
declares one ROS parameter per field (dotted names for sections, ``pid.p``), with a descriptor
made from the field (type, range, read-only, description with unit, allowed choices), validates the
given values with the field's own checks, refuses parameters that no node declares and, when the
node passes ``apply``, validates run-time changes with the same rules. Public rclpy API only.
"""

from __future__ import annotations

import sys
from collections.abc import Callable
from typing import Any

import rclpy.exceptions
import rclpy.parameter
from rcl_interfaces.msg import (
    FloatingPointRange,
    IntegerRange,
    ParameterDescriptor,
    ParameterType,
    SetParametersResult,
)
from rclpy.node import Node

from friction_ros.core.config import Field, Schema, unflatten
from friction_ros.core.joint_type import DEFAULT_JOINT_TYPE, check_joint_type, joint_schema
from friction_ros.core.validation import ParameterError

_SCALAR_TYPES = {
    bool: ParameterType.PARAMETER_BOOL,
    int: ParameterType.PARAMETER_INTEGER,
    float: ParameterType.PARAMETER_DOUBLE,
    str: ParameterType.PARAMETER_STRING,
}
_ARRAY_TYPES = {
    bool: ParameterType.PARAMETER_BOOL_ARRAY,
    int: ParameterType.PARAMETER_INTEGER_ARRAY,
    float: ParameterType.PARAMETER_DOUBLE_ARRAY,
    str: ParameterType.PARAMETER_STRING_ARRAY,
}
_ARRAY_DECLARE = {
    bool: rclpy.parameter.Parameter.Type.BOOL_ARRAY,
    int: rclpy.parameter.Parameter.Type.INTEGER_ARRAY,
    float: rclpy.parameter.Parameter.Type.DOUBLE_ARRAY,
    str: rclpy.parameter.Parameter.Type.STRING_ARRAY,
}


class ParameterNode(Node):
    """A Node that knows which parameters it was given (parameter files, ``-p``, ``parameter_overrides``).

    rclpy keeps those "overrides" to itself until a parameter of the same name is declared, but the
    nodes need them earlier: to find the keys an open section has (a friction model's
    coefficients), to choose defaults from a given value (the experiment's ``profile``) and to
    report given parameters that no node declares (:func:`declare_config`). Public rclpy API only:
    the node is created with ``automatically_declare_parameters_from_overrides``, reads the
    parameters rclpy declared that way into :attr:`given_parameters` (name -> rclpy ``Parameter``)
    and undeclares them again, so that :func:`declare_config` declares each one with its own
    descriptor (type, range, read-only) and the given value, exactly as without the automatic
    declaration. The parameters rclpy declares for itself (``use_sim_time``, the read-only
    ``start_type_description_service``) stay declared and are not listed.
    """

    def __init__(self, node_name: str, **kwargs):
        try:
            super().__init__(node_name, automatically_declare_parameters_from_overrides=True, **kwargs)
        except ValueError as exc:
            if "PARAMETER_NOT_SET" not in str(exc):
                raise
            raise ParameterError(
                f"{node_name}: the parameter file has a key with no value or an empty list (key: [] "
                "or key: ~): ROS 2 cannot type it; leave the key out (list parameters default to [])"
            ) from None
        self.given_parameters: dict[str, rclpy.parameter.Parameter] = {}
        #: every field declared by :func:`declare_config` (dotted name -> field)
        self.parameter_fields: dict[str, Field] = {}
        #: joints of a multi-joint node: ``<section>.<joint>.<key>`` names are per-joint values, not
        #: keys of the open section (``friction_ros.nodes.joint_parameters``)
        self.joint_prefixes: set[str] = set()
        for name in self.list_parameters([], 0).names:  # depth 0: every name
            if name == "use_sim_time" or self.describe_parameter(name).read_only:
                continue  # rclpy's own (time source, start_type_description_service)
            self.given_parameters[name] = self.get_parameter(name)
            self.undeclare_parameter(name)

    def given_section(self, prefix: str) -> dict[str, Any]:
        """Values given for ``<prefix>.*`` in the parameter files / command line (dotted names)."""
        out = {}
        for k, v in self.given_parameters.items():
            if k.startswith(prefix + "."):
                parts = k.split(".")
                if len(parts) >= 3 and parts[1] in self.joint_prefixes:
                    continue  # a per-joint value (friction.j3.fc), not a key of the section
                out[k] = v.value
        return out


def given_joint_type(node: ParameterNode) -> str:
    """The node's ``joint_type`` as given (default revolute), read before the declaration so the
    descriptions and messages carry the joint's units; a bad value is one line naming the choices."""
    given = node.given_parameters.get("joint_type")
    if given is None:
        return DEFAULT_JOINT_TYPE
    return check_joint_type(given.value, f"{node.get_name()}: joint_type")


def descriptor(spec: Field, name: str | None = None) -> ParameterDescriptor:
    """The ROS parameter descriptor of a field: type, description with unit, choices, range, read-only.

    A field that admits infinity (a ROS range cannot hold it) or has ``ros_range`` False gets no ROS
    range; its range is checked by the field itself.
    """
    name = spec.name if name is None else name
    d = ParameterDescriptor(
        name=name,
        type=(_ARRAY_TYPES if spec.is_list else _SCALAR_TYPES)[spec.kind],
        description=spec.doc + (f" [{spec.unit}]" if spec.unit else ""),
        additional_constraints=("one of: " + ", ".join(spec.choices)) if spec.choices else "",
        read_only=spec.read_only,
    )
    bounded = spec.lo is not None or spec.hi is not None
    if not spec.is_list and not spec.allow_inf and spec.ros_range and bounded:
        lo = -sys.float_info.max if spec.lo is None else spec.lo
        hi = sys.float_info.max if spec.hi is None else spec.hi
        if spec.kind is int:
            lo = -(2**63) if spec.lo is None else int(lo)
            hi = 2**63 - 1 if spec.hi is None else int(hi)
            d.integer_range = [IntegerRange(from_value=lo, to_value=hi, step=0)]
        elif spec.kind is float:
            d.floating_point_range = [FloatingPointRange(from_value=float(lo), to_value=float(hi), step=0.0)]
    return d


def schema_fields(node: ParameterNode, schema: Schema) -> list[tuple[str, Field]]:
    """``(ROS parameter name, field)`` of every field of ``schema``; an open section also gets a
    field for each key given in the node's parameter files (type taken from the given value)."""
    out = list(schema.fields())
    known = {name for name, _ in out}
    for prefix, section in schema.sections():
        if not section.open:
            continue
        for key, value in node.given_section(prefix).items():
            if key not in known:
                default = (
                    list(value) if isinstance(value, (list, tuple)) or hasattr(value, "tolist") else value
                )
                doc = f"{section.doc}: {key.rsplit('.', 1)[1]}" if section.doc else key
                out.append((key, Field(key, default, doc, read_only=section.read_only, allow_inf=True)))
                known.add(key)
    return out


def _declare_one(node: ParameterNode, name: str, spec: Field) -> None:
    given = node.given_parameters.get(name)
    desc = descriptor(spec, name)
    if spec.default is None and given is None:
        value: Any = _ARRAY_DECLARE[spec.kind] if spec.is_list else None
        if value is None:
            spec.check(None, name)  # required and not given: ParameterError
    else:
        value = spec.default
    given_value = spec.default if given is None else given.value
    try:
        if (
            given is not None
            and spec.kind is float
            and not spec.is_list
            and given.type_ == given.Type.INTEGER
        ):
            # YAML "gain: 3" for a double parameter: accept it as 3.0 instead of a type error.
            node.declare_parameter(name, float(given.value), desc, ignore_override=True)
        elif value is None:  # required: the given value decides the type
            node.declare_parameter(name, given.value, desc, ignore_override=True)
        else:  # rclpy applies the given value (checked against the default's type and the range)
            if spec.is_list and not value:
                value = _ARRAY_DECLARE[spec.kind]
            node.declare_parameter(name, value, desc, ignore_override=False)
    except (
        rclpy.exceptions.InvalidParameterValueException,
        rclpy.exceptions.InvalidParameterTypeException,
    ) as exc:
        spec.check(given_value, name)  # names the value and what is allowed, in the schema's words
        raise ParameterError(
            f"{node.get_name()}: parameter {name} = {given_value!r} is invalid "
            f"(expected {spec.type_name}{'; ' + spec.range_text() if spec.range_text() else ''}): {spec.doc}"
        ) from exc


def declare_config(
    node: ParameterNode,
    schema: Schema,
    apply: Callable[[dict[str, Any]], None] | None = None,
    check_unknown: bool = True,
    overrides: dict[str, Any] | None = None,
) -> dict[str, Any]:
    """Declare every field of ``schema`` as a ROS parameter and return the validated values, nested
    like the schema (``{"pid": {"p": 200.0}, ...}``).

    Raises ParameterError (the node refuses to start) when a given value is invalid or, with
    ``check_unknown``, when a given parameter is declared nowhere (typos do not pass silently).
    With ``apply``, run-time changes of every parameter declared so far are validated with the same
    field checks; read-only ones are refused; ``apply({name: value})`` then receives an accepted
    change and may raise ParameterError (cross-parameter checks by the core), which rejects it.
    ``overrides`` (name -> value, None: not given) are values from outside ROS (a tool's own
    command-line options); they replace the parameter values, checked by the same fields.
    A schema with a ``joint_type`` field gets the units of the given joint type.
    """
    if "joint_type" in schema.items:
        schema = joint_schema(schema, given_joint_type(node))
    specs = schema_fields(node, schema)
    for name, spec in specs:
        _declare_one(node, name, spec)
        node.parameter_fields[name] = spec
    values = {name: spec.check(_value(node, name, spec), name) for name, spec in specs}
    by_name = dict(specs)
    for name, value in (overrides or {}).items():
        if value is not None and name in by_name:
            values[name] = by_name[name].check(_plain(value), name)
    if check_unknown:
        check_unknown_parameters(node)
    if apply is not None:
        _add_runtime_validation(node, apply)
    return unflatten(values)


def check_unknown_parameters(node: ParameterNode, hint: str | None = None) -> None:
    """Refuse given parameters that no declaration took (typos do not pass silently); ``hint``
    replaces the list of declared names in the message."""
    declared = set(node.list_parameters([], 0).names) | {"use_sim_time"}
    unknown = sorted(
        k for k in node.given_parameters if k not in declared and not k.startswith("qos_overrides")
    )
    if unknown:
        renamed = "".join(f"; {k} is now {RENAMED[k]}" for k in unknown if k in RENAMED)
        raise ParameterError(
            f"{node.get_name()}: unknown parameter(s) {', '.join(unknown)} in the parameter file{renamed}; "
            + (hint or f"declared parameters are: {', '.join(sorted(declared))}")
        )


#: parameters that were renamed -> what to set instead (said when an old file sets them)
RENAMED = {"control_rate_hz": "control_period [s] = 1 / the rate (one name across nodes)"}


def _value(node: ParameterNode, name: str, spec: Field) -> Any:
    try:
        value = node.get_parameter(name).value
    except rclpy.exceptions.ParameterUninitializedException:  # an empty array declared by its type
        return spec.default
    return spec.default if value is None else _plain(value)


def _plain(value: Any) -> Any:
    """rclpy returns arrays as array.array / numpy: hand lists to the field checks."""
    return list(value) if hasattr(value, "tolist") or isinstance(value, tuple) else value


def _add_runtime_validation(node: ParameterNode, apply: Callable[[dict[str, Any]], None]) -> None:
    fields = node.parameter_fields

    def _callback(changes) -> SetParametersResult:
        accepted: dict[str, Any] = {}
        try:
            for c in changes:
                if c.name == "use_sim_time":
                    continue
                spec = fields.get(c.name)
                if spec is None:
                    raise ParameterError(f"{c.name} is not a parameter of {node.get_name()}")
                if spec.read_only:
                    raise ParameterError(f"{c.name} is read-only (restart the node to change it)")
                accepted[c.name] = spec.check(_plain(c.value), c.name)
            if accepted:
                apply(accepted)
        except (ParameterError, ValueError) as exc:
            node.get_logger().warning(f"rejected parameter change: {exc}")
            return SetParametersResult(successful=False, reason=str(exc))
        return SetParametersResult(successful=True)

    node.add_on_set_parameters_callback(_callback)


def current_values(node: ParameterNode, changes: dict[str, Any] | None = None) -> dict[str, Any]:
    """Every declared parameter's current value with ``changes`` applied, nested like the schemas."""
    # _value: an empty array declared by its type (a list field defaulting to []) is "uninitialized"
    flat = {name: _value(node, name, spec) for name, spec in node.parameter_fields.items()}
    flat.update(changes or {})
    return unflatten(flat)


SCHEDULING = Schema(
    "scheduling",
    [
        Field(
            "realtime_priority",
            0,
            "SCHED_FIFO priority of the node's threads (0: normal scheduling; needs CAP_SYS_NICE)",
            lo=0,
            hi=99,
            read_only=True,
        ),
        Field(
            "cpu_affinity",
            -1,
            "pin the node's threads to this CPU (-1: any CPU)",
            lo=-1,
            hi=4095,
            read_only=True,
        ),
    ],
)
"""``realtime_priority`` / ``cpu_affinity`` of every node with a control loop (``runtime.apply_scheduling``)."""


def input_gate_schema() -> Schema:
    """``input_gate.*``: the joint-state plausibility gate (:mod:`friction_ros.core.input_gate`), read-only."""
    from friction_ros.core.input_gate import GATE_DEFAULTS, GATE_DOCS

    return Schema(
        "input_gate",
        [
            Field(
                k,
                v,
                GATE_DOCS[k][0],
                lo=1 if isinstance(v, int) else 0.0,
                unit=GATE_DOCS[k][1],
                read_only=True,
            )
            for k, v in GATE_DEFAULTS.items()
        ],
        doc="joint-state plausibility gate",
    )
