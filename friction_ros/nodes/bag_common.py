"""rclpy helpers shared by bag_recorder and bag_player: message classes, QoS conversion, stop handling."""

from __future__ import annotations

import importlib
import signal
import sys
import threading

from rclpy.duration import Duration
from rclpy.qos import DurabilityPolicy, HistoryPolicy, LivelinessPolicy, QoSProfile, ReliabilityPolicy

from friction_ros.core.bag import BagError, make_qos
from friction_ros.core.bag.msgdef import split_type


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
