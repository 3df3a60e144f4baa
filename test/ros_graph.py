"""Helpers for tests that run friction_ros nodes as separate processes over real DDS."""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from pathlib import Path

import yaml

from friction_ros.cli.bringup import Bringup, NodeSpec

ROOT = Path(__file__).resolve().parents[1]


def write_params(path: Path, doc: dict) -> str:
    path.write_text(yaml.safe_dump(doc, sort_keys=False))
    return str(path)


class Graph:
    """Start node processes (context manager); stop them controllers-first on exit."""

    def __init__(self, specs: list[NodeSpec]):
        self.bringup = Bringup(specs, quiet=True)

    def __enter__(self) -> Graph:
        self.bringup.start()
        return self

    def __exit__(self, *exc) -> None:
        self.bringup.stop(grace=5.0)

    def output(self, label: str) -> str:
        return "\n".join(self.bringup.output.get(label, []))

    def assert_alive(self) -> None:
        failed = self.bringup.failed()
        assert not failed, f"nodes exited: {failed}\n" + "\n".join(
            f"--- {lbl}\n{self.output(lbl)}" for lbl, _ in failed
        )


class Listener:
    """A test-process node collecting messages from several topics (spun on its own thread)."""

    def __init__(self, name: str = "test_listener"):
        import rclpy
        from rclpy.executors import SingleThreadedExecutor

        if not rclpy.ok():
            rclpy.init()
        self.rclpy = rclpy
        self.node = rclpy.create_node(name)
        self.msgs: dict[str, list] = {}
        self.subs: dict[str, object] = {}
        self.executor = SingleThreadedExecutor()
        self.executor.add_node(self.node)
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._spin, daemon=True)

    def subscribe(self, msg_type, topic: str, qos=None) -> list:
        from friction_ros.nodes.qos import STATE_QOS

        box: list = []
        self.msgs[topic] = box
        self.subs[topic] = self.node.create_subscription(msg_type, topic, box.append, qos or STATE_QOS)
        return box

    def matched(self, topic: str) -> int:
        """Publishers matched with this listener's subscription of ``topic`` (reader side)."""
        return self.subs[topic].get_publisher_count()

    def publisher(self, msg_type, topic: str, qos=None):
        from friction_ros.nodes.qos import STATE_QOS

        return self.node.create_publisher(msg_type, topic, qos or STATE_QOS)

    def _spin(self) -> None:
        while not self._stop.is_set():
            self.executor.spin_once(timeout_sec=0.05)

    def __enter__(self) -> Listener:
        self._thread.start()
        return self

    def __exit__(self, *exc) -> None:
        self._stop.set()
        self._thread.join(timeout=2)
        self.node.destroy_node()
        self.rclpy.try_shutdown()

    def wait_for(self, predicate: Callable[[], bool], timeout: float, graph: Graph | None = None) -> bool:
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            if predicate():
                return True
            if graph is not None:
                graph.assert_alive()
            time.sleep(0.05)
        return predicate()


def stamp_s(msg) -> float:
    return msg.header.stamp.sec + msg.header.stamp.nanosec * 1e-9
