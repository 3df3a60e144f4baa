"""Wait for the first joint state of a run: a CLI that starts nodes fails fast, naming the cause, when
no joint_states arrive (no drive_interface running, another ROS_DOMAIN_ID, a wrong namespace).

One small rclpy node in its own context (no signal handlers: the CLI keeps its own) with a
best-effort subscription (it matches reliable and best-effort publishers) that takes raw bytes,
decodes nothing and is destroyed as soon as the first message came.
"""

from __future__ import annotations

import os
import threading


class FirstStateWatch:
    """``poll(timeout)`` waits up to ``timeout`` s for the first message on ``topic`` (True once one came).

    The node spins in a daemon thread of its own, so that the caller's loop (and its wall-time limit)
    never waits inside rclpy: ``poll`` and ``close`` return within their bounds whatever DDS does.
    """

    def __init__(self, topic: str):
        import rclpy
        from rclpy.executors import SingleThreadedExecutor
        from rclpy.qos import QoSProfile, ReliabilityPolicy
        from rclpy.signals import SignalHandlerOptions
        from sensor_msgs.msg import JointState

        self.topic = topic
        self._seen = threading.Event()
        self._done = threading.Event()
        self._context = rclpy.Context()
        rclpy.init(args=[], context=self._context, signal_handler_options=SignalHandlerOptions.NO)
        self._node = rclpy.create_node(
            "friction_experiment_state_watch",
            context=self._context,
            start_parameter_services=False,
            enable_rosout=False,
        )
        qos = QoSProfile(depth=1, reliability=ReliabilityPolicy.BEST_EFFORT)
        self._node.create_subscription(JointState, topic, self._on_state, qos, raw=True)
        self._executor = SingleThreadedExecutor(context=self._context)
        self._executor.add_node(self._node)
        self._thread = threading.Thread(target=self._spin, name="state_watch", daemon=True)
        self._thread.start()

    @property
    def seen(self) -> bool:
        return self._seen.is_set()

    def _on_state(self, _raw: bytes) -> None:
        self._seen.set()

    def _spin(self) -> None:
        try:
            while not (self._done.is_set() or self._seen.is_set()):
                self._executor.spin_once(timeout_sec=0.05)
        except Exception:  # the context was shut down under it: nothing more to watch
            pass

    def poll(self, timeout: float) -> bool:
        """Wait up to ``timeout`` s (or until a message came); True once the first state arrived."""
        return self._seen.wait(timeout)

    def close(self, grace: float = 2.0) -> None:
        """Stop the spin thread and destroy the node; a thread still inside rclpy after ``grace`` s is
        left to the process's exit (it is a daemon) rather than waited for."""
        if self._node is None or self._done.is_set():
            return  # closed, or its thread is stuck and was left (one wait only)
        self._done.set()
        self._thread.join(grace)
        if self._thread.is_alive():
            return
        self._executor.remove_node(self._node)
        self._node.destroy_node()
        self._node = None
        self._executor.shutdown(timeout_sec=grace)
        self._context.try_shutdown()


def no_state_reason(topic: str, seconds: float, simulated: bool) -> str:
    """The one line of a run whose joint states never came within ``seconds``."""
    if simulated:
        return (
            f"no joint_states received on {topic} within {seconds:g} s: the plant_simulator did not "
            "publish (see its output above)"
        )
    domain = os.environ.get("ROS_DOMAIN_ID", "") or "0 (not set)"
    return (
        f"no joint_states received on {topic} within {seconds:g} s: is the drive_interface running "
        f"(with the same --namespace), and is ROS_DOMAIN_ID the same in its shell (here: {domain})?"
    )
