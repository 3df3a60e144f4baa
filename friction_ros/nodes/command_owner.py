"""One owner per joint command (policy in README "Safety"), for the nodes that follow commands
(plant_simulator, drive_interface) and the ones that send them (compensating_controller).

Sources are told apart by ``header.frame_id`` (:mod:`friction_ros.core.command_sources`; the project's
command publishers set it to their node's name, :func:`command_source`). A follower applies zero
torque to a joint commanded by two sources until one has been alone for 0.5 s; a controller that sees
another source command one of its joints on the topic it publishes reports it (log and diagnostics).
Each conflict is logged (ERROR) when it starts, naming the sources, and (INFO) when it clears.
"""

from __future__ import annotations

import time

from rclpy.node import Node
from sensor_msgs.msg import JointState

from friction_ros.core.command_sources import CommandSources
from friction_ros.core.wire import JointStateDecoder
from friction_ros.nodes.qos import COMMAND_QOS
from friction_ros.nodes.safe_subscription import BYTES, safe_subscription


def command_source(node: Node) -> str:
    """The ``header.frame_id`` a node puts on the commands it publishes: its fully qualified name."""
    return node.get_fully_qualified_name()


class CommandOwnerWatch:
    """See the module docstring. ``role``: ``follows`` (zero torque on a conflicted joint) or
    ``commands`` (a controller: it reads its own output topic to see other sources, but only while
    the graph shows another publisher there: no message of its own comes back in the normal case)."""

    def __init__(self, node: Node, joints, *, role: str = "follows", topic: str = "joint_commands"):
        self.node = node
        self.role = role
        self.topic = node.resolve_topic_name(topic)
        self.sources = CommandSources(joints)
        self._index = {j: i for i, j in enumerate(self.sources.joints)}
        self.conflicts = 0  # how many conflicts started
        self._decoder = JointStateDecoder()
        self._echo = None  # the controller's subscription to its own output, while others publish there
        node.create_timer(0.2, self._expire)

    @property
    def conflict(self) -> bool:
        return any(self.sources.in_conflict(i) for i in range(len(self.sources.joints)))

    def admit(self, source: str, names) -> set[int]:
        """A command from ``source`` naming joints ``names`` (the follower's joints among them count);
        returns the indices of the follower's joints in conflict (their torque must be zero)."""
        idx = [self._index[n] for n in names if n in self._index]
        out = self.sources.admit(source, idx, time.monotonic())
        self._log()
        return out

    def status(self) -> str:
        """'' or the diagnostics text of the conflicts."""
        s = self.sources
        parts = [f"{j} from {', '.join(s.sources(i))}" for i, j in enumerate(s.joints) if s.in_conflict(i)]
        return f"two command sources on {self.topic}: " + "; ".join(parts) if parts else ""

    def _on_own_topic(self, data: bytes) -> None:
        msg = self._decoder.decode(data)
        self.admit(msg.frame_id, msg.name)

    def _expire(self) -> None:
        if self.role == "commands":
            self._watch_others()
        self.sources.expire(time.monotonic())
        self._log()

    def _watch_others(self) -> None:
        others = self.node.count_publishers(self.topic) > 1
        if others and self._echo is None:
            self._echo = safe_subscription(
                self.node, JointState, self.topic, self._on_own_topic, COMMAND_QOS, decode=BYTES
            )
        elif not others and self._echo is not None and not self.conflict:
            self.node.destroy_subscription(self._echo.subscription)
            self._echo = None

    def _log(self) -> None:
        s, log = self.sources, self.node.get_logger()
        what = (
            "following neither: zero torque until one source is left"
            if self.role == "follows"
            else "the joint gets two commands: stop one of the controllers"
        )
        for joint, names in s.started:
            self.conflicts += 1
            log.error(
                f"{joint}: commanded by {len(names)} sources on {self.topic} ({', '.join(names)}): {what}"
            )
        for joint, name in s.cleared:
            log.info(f"{joint}: one command source on {self.topic} again ({name or 'none'}): cleared")
        s.started.clear()
        s.cleared.clear()
