"""ROS parameters of the nodes: declaration with descriptors, validation, run-time changes."""

from __future__ import annotations

import math
import sys
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from typing import Any

import rclpy
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

from friction_ros.core.validation import ParameterError

_TYPES = {
    bool: ParameterType.PARAMETER_BOOL,
    int: ParameterType.PARAMETER_INTEGER,
    float: ParameterType.PARAMETER_DOUBLE,
    str: ParameterType.PARAMETER_STRING,
    list: ParameterType.PARAMETER_DOUBLE_ARRAY,
}


@dataclass
class Param:
    """One declared ROS parameter: default value, description, optional range/choices."""

    name: str
    default: Any
    description: str
    lo: float | None = None
    hi: float | None = None
    choices: tuple[str, ...] = ()
    read_only: bool = False
    unit: str = ""

    @property
    def ptype(self) -> int:
        if isinstance(self.default, list):
            if self.default and isinstance(self.default[0], str):
                return ParameterType.PARAMETER_STRING_ARRAY
            return ParameterType.PARAMETER_DOUBLE_ARRAY
        return _TYPES[type(self.default)]

    def descriptor(self) -> ParameterDescriptor:
        text = self.description + (f" [{self.unit}]" if self.unit else "")
        constraints = ""
        if self.choices:
            constraints = "one of: " + ", ".join(self.choices)
        d = ParameterDescriptor(
            name=self.name,
            type=self.ptype,
            description=text,
            additional_constraints=constraints,
            read_only=self.read_only,
        )
        if self.lo is not None or self.hi is not None:
            lo = -sys.float_info.max if self.lo is None else self.lo
            hi = sys.float_info.max if self.hi is None else self.hi
            if isinstance(self.default, bool):
                pass
            elif isinstance(self.default, int):
                d.integer_range = [IntegerRange(from_value=int(lo), to_value=int(hi), step=0)]
            elif isinstance(self.default, float):
                d.floating_point_range = [
                    FloatingPointRange(from_value=float(lo), to_value=float(hi), step=0.0)
                ]
        return d

    def check(self, value: Any) -> Any:
        """Validate ``value``; raise ParameterError naming this parameter and the allowed values."""
        if isinstance(self.default, float) and isinstance(value, int) and not isinstance(value, bool):
            value = float(value)
        if isinstance(self.default, list):
            if not isinstance(value, (list, tuple)):
                raise ParameterError(f"{self.name} = {value!r} must be a list")
            value = list(value)
            if self.ptype == ParameterType.PARAMETER_DOUBLE_ARRAY:
                value = [float(v) for v in value]
                if any(math.isnan(v) for v in value):
                    raise ParameterError(f"{self.name} = {value!r} must not contain NaN")
            return value
        if type(value) is not type(self.default):
            want = type(self.default).__name__
            raise ParameterError(f"{self.name} = {value!r} has type {type(value).__name__}: must be {want}")
        if isinstance(value, float) and math.isnan(value):
            raise ParameterError(f"{self.name} = nan is not a number")
        if self.choices and value not in self.choices:
            raise ParameterError(
                f"{self.name} = {value!r} is not allowed: must be one of {', '.join(self.choices)}"
            )
        if isinstance(value, (int, float)) and not isinstance(value, bool):
            if (self.lo is not None and value < self.lo) or (self.hi is not None and value > self.hi):
                lo = "-inf" if self.lo is None else f"{self.lo:g}"
                hi = "inf" if self.hi is None else f"{self.hi:g}"
                rng = f"[{lo}, {hi}]"
                unit = f" {self.unit}" if self.unit else ""
                raise ParameterError(f"{self.name} = {value:g} is out of range: must be in {rng}{unit}")
        return value


class ParameterNode(Node):
    """A Node that knows which parameters it was given (parameter files, ``-p``, ``parameter_overrides``).

    rclpy keeps those "overrides" to itself until a parameter of the same name is declared, but the
    nodes need them earlier: to find the keys a nested YAML section has (:func:`section_specs`), to
    choose defaults from a given value (the experiment's ``profile``) and to report given parameters
    that no node declares (:func:`declare`). Public rclpy API only: the node is created with
    ``automatically_declare_parameters_from_overrides``, reads the parameters rclpy declared that
    way into :attr:`given_parameters` (name -> rclpy ``Parameter``) and undeclares them again, so
    that :func:`declare` declares each one with its own descriptor (type, range, read-only) and the
    given value, exactly as without the automatic declaration. The parameters rclpy declares for
    itself (``use_sim_time``, the read-only ``start_type_description_service``) stay declared and
    are not listed.
    """

    def __init__(self, node_name: str, **kwargs):
        super().__init__(node_name, automatically_declare_parameters_from_overrides=True, **kwargs)
        self.given_parameters: dict[str, rclpy.parameter.Parameter] = {}
        for name in self.list_parameters([], 0).names:  # depth 0: every name
            if name == "use_sim_time" or self.describe_parameter(name).read_only:
                continue  # rclpy's own (time source, start_type_description_service)
            self.given_parameters[name] = self.get_parameter(name)
            self.undeclare_parameter(name)


def declare(node: ParameterNode, params: Iterable[Param], check_unknown: bool = True) -> dict[str, Any]:
    """Declare ``params`` with descriptors and return their validated values.

    Raises ParameterError (the node refuses to start) when a value from a parameter file is invalid.
    Parameters given in the file but not declared are reported too, so typos do not pass silently.
    """
    values: dict[str, Any] = {}
    specs = list(params)
    given = node.given_parameters
    for p in specs:
        g = given.get(p.name)
        given_value = p.default if g is None else g.value
        try:
            if g is not None and isinstance(p.default, float) and g.type_ == g.Type.INTEGER:
                # YAML "gain: 3" for a double parameter: accept it as 3.0 instead of a type error.
                given_value = float(g.value)
                node.declare_parameter(p.name, given_value, p.descriptor(), ignore_override=True)
            else:  # rclpy applies the given value (checked against the default's type)
                node.declare_parameter(p.name, p.default, p.descriptor(), ignore_override=False)
        except (
            rclpy.exceptions.InvalidParameterValueException,
            rclpy.exceptions.InvalidParameterTypeException,
        ) as exc:
            allowed = p.descriptor()
            rng = ""
            if allowed.floating_point_range:
                r = allowed.floating_point_range[0]
                rng = f"; allowed range [{r.from_value:g}, {r.to_value:g}]"
            elif allowed.integer_range:
                r = allowed.integer_range[0]
                rng = f"; allowed range [{r.from_value}, {r.to_value}]"
            raise ParameterError(
                f"{node.get_name()}: parameter {p.name} = {given_value!r} is invalid "
                f"(expected {type(p.default).__name__}{rng}): {p.description}"
            ) from exc
    for p in specs:
        value = node.get_parameter(p.name).value
        values[p.name] = p.check(value)
    if not check_unknown:
        return values
    declared = set(node.list_parameters([], 0).names) | {"use_sim_time"}
    unknown = sorted(k for k in given if k not in declared and not k.startswith("qos_overrides"))
    if unknown:
        raise ParameterError(
            f"{node.get_name()}: unknown parameter(s) {', '.join(unknown)} in the parameter file; "
            f"declared parameters are: {', '.join(sorted(declared))}"
        )
    return values


def add_runtime_validation(
    node: Node, specs: Iterable[Param], apply: Callable[[dict[str, Any]], None] | None = None
) -> None:
    """Validate run-time parameter changes with the same rules; reject with a clear reason.

    ``apply`` receives ``{name: value}`` of an accepted change and may raise ParameterError (for
    cross-parameter checks done by the core); the change is then rejected and the node keeps its
    last good state.
    """
    by_name = {p.name: p for p in specs}

    def _callback(changes) -> SetParametersResult:
        accepted: dict[str, Any] = {}
        try:
            for c in changes:
                if c.name == "use_sim_time":
                    continue
                spec = by_name.get(c.name)
                if spec is None:
                    raise ParameterError(f"{c.name} is not a parameter of {node.get_name()}")
                if spec.read_only:
                    raise ParameterError(f"{c.name} is read-only (restart the node to change it)")
                accepted[c.name] = spec.check(c.value)
            if apply is not None and accepted:
                apply(accepted)
        except (ParameterError, ValueError) as exc:
            node.get_logger().warning(f"rejected parameter change: {exc}")
            return SetParametersResult(successful=False, reason=str(exc))
        return SetParametersResult(successful=True)

    node.add_on_set_parameters_callback(_callback)


SCHEDULING_PARAMS = [
    Param(
        "realtime_priority",
        0,
        "SCHED_FIFO priority of the node's threads (0: normal scheduling; needs CAP_SYS_NICE)",
        lo=0,
        hi=99,
        read_only=True,
    ),
    Param(
        "cpu_affinity", -1, "pin the node's threads to this CPU (-1: any CPU)", lo=-1, hi=4095, read_only=True
    ),
]


def gate_params() -> list[Param]:
    """``input_gate.*`` parameters of the joint-state plausibility gate (:mod:`friction_ros.core.input_gate`)."""
    from friction_ros.core.input_gate import GATE_DEFAULTS, GATE_DOCS

    return [
        Param(
            f"input_gate.{k}",
            v,
            GATE_DOCS[k][0],
            lo=1 if isinstance(v, int) else 0.0,
            unit=GATE_DOCS[k][1],
            read_only=True,
        )
        for k, v in GATE_DEFAULTS.items()
    ]


def flatten(config: dict[str, Any], prefix: str = "") -> dict[str, Any]:
    """Nested config dict -> dotted ROS parameter names (``{'pid': {'p': 1}} -> {'pid.p': 1}``)."""
    flat: dict[str, Any] = {}
    for key, value in config.items():
        name = f"{prefix}{key}"
        if isinstance(value, dict):
            flat.update(flatten(value, name + "."))
        else:
            flat[name] = value
    return flat


def unflatten(flat: dict[str, Any]) -> dict[str, Any]:
    """Dotted ROS parameter names -> nested config dict (inverse of :func:`flatten`)."""
    nested: dict[str, Any] = {}
    for name, value in flat.items():
        parts = name.split(".")
        d = nested
        for p in parts[:-1]:
            d = d.setdefault(p, {})
        d[parts[-1]] = value
    return nested


def override_values(node: ParameterNode, prefix: str) -> dict[str, Any]:
    """Values given for ``<prefix>.*`` in the node's parameter files / command line (dotted names)."""
    return {k: v.value for k, v in node.given_parameters.items() if k.startswith(prefix + ".")}


def section_specs(
    node: ParameterNode, prefix: str, defaults: dict[str, Any], doc: str, read_only: bool = False
) -> list[Param]:
    """Param specs for every ``<prefix>.<key>`` of a nested core section (defaults + keys given in files).

    Keys only present in the parameter file (e.g. the coefficients of the chosen friction model) are
    declared too, with their type taken from the given value; the core object built from the section
    then validates names and ranges and raises one ParameterError naming the key if anything is off.
    """
    flat = {f"{prefix}.{k}": v for k, v in flatten(defaults).items() if v is not None}
    for key, value in override_values(node, prefix).items():
        flat.setdefault(key, value)
    return [
        Param(
            key, list(v) if isinstance(v, tuple) else v, f"{doc}: {key.split('.', 1)[1]}", read_only=read_only
        )
        for key, v in flat.items()
    ]


def declare_section(
    node: ParameterNode, prefix: str, defaults: dict[str, Any], doc: str, read_only: bool = False
) -> dict[str, Any]:
    """Declare a section (see :func:`section_specs`) and return it as a nested dict."""
    values = declare(node, section_specs(node, prefix, defaults, doc, read_only), check_unknown=False)
    return unflatten(values).get(prefix, {})
