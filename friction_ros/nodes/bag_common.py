"""rclpy helpers shared by bag_recorder and bag_player: parameters, message classes, QoS conversion."""

from __future__ import annotations

import importlib
import signal
import sys
import threading
from dataclasses import dataclass
from typing import Any

from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor, ParameterType
from rclpy.duration import Duration
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import DurabilityPolicy, HistoryPolicy, LivelinessPolicy, QoSProfile, ReliabilityPolicy

from friction_ros.core.bag import BagError, make_qos
from friction_ros.core.bag.msgdef import split_type
from friction_ros.core.validation import ParameterError

_PTYPES = {
    bool: ParameterType.PARAMETER_BOOL,
    int: ParameterType.PARAMETER_INTEGER,
    float: ParameterType.PARAMETER_DOUBLE,
    str: ParameterType.PARAMETER_STRING,
    list: ParameterType.PARAMETER_STRING_ARRAY,
}


@dataclass
class Spec:
    """A parameter: default (list = string array), description, optional range, unit, choices."""

    name: str
    default: Any
    description: str
    lo: float | None = None
    hi: float | None = None
    unit: str = ""
    choices: tuple[str, ...] = ()

    def descriptor(self) -> ParameterDescriptor:
        d = ParameterDescriptor(
            name=self.name,
            type=_PTYPES[type(self.default)],
            description=self.description + (f" [{self.unit}]" if self.unit else ""),
            additional_constraints=("one of: " + ", ".join(self.choices)) if self.choices else "",
            read_only=True,
        )
        if isinstance(self.default, float) and (self.lo is not None or self.hi is not None):
            d.floating_point_range = [
                FloatingPointRange(
                    from_value=float(self.lo or 0.0), to_value=float(self.hi or 1e300), step=0.0
                )
            ]
        if isinstance(self.default, int) and not isinstance(self.default, bool) and self.lo is not None:
            d.integer_range = [IntegerRange(from_value=int(self.lo), to_value=int(self.hi or 2**62), step=0)]
        return d


def declare_params(node: Node, specs: list[Spec], overrides: dict[str, Any] | None = None) -> dict[str, Any]:
    """Declare ``specs`` (with descriptors) and return validated values; ParameterError on bad values."""
    values = {}
    overrides = overrides or {}
    for s in specs:
        default = Parameter.Type.STRING_ARRAY if isinstance(s.default, list) else s.default
        try:
            p = node.declare_parameter(s.name, default, s.descriptor())
            v = p.value
        except Exception as exc:  # noqa: BLE001 - rclpy raises several exception types
            raise ParameterError(f"{node.get_name()}: parameter {s.name}: {exc}") from None
        if s.name in overrides and overrides[s.name] is not None:
            v = overrides[s.name]
        if v is None:
            v = list(s.default) if isinstance(s.default, list) else s.default
        if isinstance(s.default, float) and isinstance(v, int) and not isinstance(v, bool):
            v = float(v)
        if isinstance(s.default, list):
            v = [str(x) for x in v]
        elif type(v) is not type(s.default):
            raise ParameterError(
                f"{s.name} = {v!r} has type {type(v).__name__}: must be {type(s.default).__name__}"
            )
        if s.choices and v not in s.choices:
            raise ParameterError(f"{s.name} = {v!r} is not allowed: must be one of {', '.join(s.choices)}")
        if isinstance(v, (int, float)) and not isinstance(v, bool):
            if (s.lo is not None and v < s.lo) or (s.hi is not None and v > s.hi):
                raise ParameterError(
                    f"{s.name} = {v:g} is out of range: must be in [{s.lo if s.lo is not None else '-inf'}, "
                    f"{s.hi if s.hi is not None else 'inf'}]{(' ' + s.unit) if s.unit else ''}"
                )
        values[s.name] = v
    return values


def message_class(msgtype: str):
    """The Python class of ``pkg/msg/Type`` (imports ``pkg.msg``); BagError if not installed."""
    pkg, typ = split_type(msgtype)
    try:
        return getattr(importlib.import_module(f"{pkg}.msg"), typ)
    except (ImportError, AttributeError):
        raise BagError(
            f"message type {pkg}/msg/{typ} is not installed (cannot import {pkg}.msg.{typ})"
        ) from None


def _dur(d: Duration) -> dict:
    ns = int(d.nanoseconds)
    return {"sec": ns // 1_000_000_000, "nsec": ns % 1_000_000_000}


def qos_to_dict(q: QoSProfile) -> dict:
    """rclpy QoSProfile -> rosbag2 v9 profile dict."""
    out = make_qos(q.reliability.name.lower(), q.durability.name.lower(), q.history.name.lower(), q.depth)
    out["deadline"] = _dur(q.deadline)
    out["lifespan"] = _dur(q.lifespan)
    out["liveliness"] = q.liveliness.name.lower()
    out["liveliness_lease_duration"] = _dur(q.liveliness_lease_duration)
    out["avoid_ros_namespace_conventions"] = bool(q.avoid_ros_namespace_conventions)
    return out


def qos_from_dicts(profiles: list[dict], depth: int) -> QoSProfile:
    """Publisher QoS for replay: reliability/durability of the recorded offers, keep-last ``depth``."""
    reliable = all(p.get("reliability") != "best_effort" for p in profiles)
    latched = bool(profiles) and all(p.get("durability") == "transient_local" for p in profiles)
    return QoSProfile(
        history=HistoryPolicy.KEEP_LAST,
        depth=depth,
        reliability=ReliabilityPolicy.RELIABLE if reliable else ReliabilityPolicy.BEST_EFFORT,
        durability=DurabilityPolicy.TRANSIENT_LOCAL if latched else DurabilityPolicy.VOLATILE,
        liveliness=LivelinessPolicy.AUTOMATIC,
    )


def install_stop_handlers() -> threading.Event:
    """SIGINT/SIGTERM set the returned event (the node then finishes its work cleanly)."""
    stop = threading.Event()

    def _on_signal(signum, _frame):
        stop.set()

    signal.signal(signal.SIGINT, _on_signal)
    signal.signal(signal.SIGTERM, _on_signal)
    return stop


def fail(exc: Exception) -> int:
    print(f"error: {exc}", file=sys.stderr)
    return 2
