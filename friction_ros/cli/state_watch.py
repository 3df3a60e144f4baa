"""Wait for the first joint state of a run: a CLI that starts nodes fails fast, naming the cause, when
no joint_states arrive (no drive_interface running, another ROS_DOMAIN_ID, a wrong namespace).

One small rclpy node in its own context (no signal handlers: the CLI keeps its own) with a
best-effort subscription (it matches reliable and best-effort publishers) that takes raw bytes,
decodes nothing and is destroyed as soon as the first message came.
"""

from __future__ import annotations

import os


class FirstStateWatch:
    """``poll(timeout)`` spins until the first message on ``topic`` (True once one came)."""

    def __init__(self, topic: str):
        import rclpy
        from rclpy.executors import SingleThreadedExecutor
        from rclpy.qos import QoSProfile, ReliabilityPolicy
        from rclpy.signals import SignalHandlerOptions
        from sensor_msgs.msg import JointState

        self.topic = topic
        self.seen = False
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

    def _on_state(self, _raw: bytes) -> None:
        self.seen = True

    def poll(self, timeout: float) -> bool:
        """Spin up to ``timeout`` s (or until a message came); True once the first state arrived."""
        if not self.seen and self._node is not None:
            self._executor.spin_once(timeout_sec=timeout)
        if self.seen:
            self.close()
        return self.seen

    def close(self) -> None:
        if self._node is None:
            return
        self._executor.remove_node(self._node)
        self._node.destroy_node()
        self._node = None
        self._executor.shutdown()
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
