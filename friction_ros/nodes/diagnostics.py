"""``diagnostics`` publisher of a node and the diagnostic status levels."""

from __future__ import annotations

from typing import Any

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rclpy.node import Node

from friction_ros.nodes.qos import STATE_QOS


class DiagnosticsPublisher:
    """Publish one ``diagnostic_msgs/DiagnosticArray`` status for a node on ``diagnostics``."""

    def __init__(self, node: Node, name: str, hardware_id: str = ""):
        self.node = node
        self.name = name
        self.hardware_id = hardware_id
        self.pub = node.create_publisher(DiagnosticArray, "diagnostics", STATE_QOS)

    def publish(self, level: int, message: str, values: dict[str, Any]) -> DiagnosticStatus:
        status = DiagnosticStatus(
            level=level if isinstance(level, bytes) else bytes([level]),
            name=f"{self.node.get_namespace().rstrip('/')}/{self.name}",
            message=message,
            hardware_id=self.hardware_id,
            values=[KeyValue(key=k, value=_fmt(v)) for k, v in values.items()],
        )
        msg = DiagnosticArray(status=[status])
        msg.header.stamp = self.node.get_clock().now().to_msg()
        self.pub.publish(msg)
        return status


def _fmt(v: Any) -> str:
    if isinstance(v, float):
        return f"{v:.6g}"
    return str(v)


OK = DiagnosticStatus.OK
WARN = DiagnosticStatus.WARN
ERROR = DiagnosticStatus.ERROR
STALE = DiagnosticStatus.STALE
