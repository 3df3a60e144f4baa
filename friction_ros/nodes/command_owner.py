"""One owner per joint command: a watch of the publishers of a command topic.

Policy (README "Safety"): a joint follows one command source. Two publishers on a joint's
``joint_commands`` (two controllers, a controller and a replayed bag, a test publisher) are a
fault: the drive interface and the plant simulator stop following commands and hold zero torque
until one publisher is left; a controller that sees another publisher on the topic it commands
keeps running but reports it. The fault is logged (ERROR) when it starts, naming the publishers,
and (INFO) when it clears; diagnostics show it meanwhile.

The watch polls the ROS graph (``get_publishers_info_by_topic``) every ``period`` seconds: no
per-message cost.
"""

from __future__ import annotations

import time

from rclpy.node import Node


class CommandOwnerWatch:
    """See the module docstring; ``conflict`` is True while the topic has more than one publisher."""

    def __init__(self, node: Node, topic: str, *, period: float = 0.2, role: str = "follows"):
        """``role``: ``follows`` (a drive or plant: commands are refused during a conflict) or
        ``commands`` (a controller: reported only)."""
        self.node = node
        self.topic = node.resolve_topic_name(topic)
        self.role = role
        self.conflict = False
        self.publishers: list[str] = []
        self.conflicts = 0  # how many times a conflict started
        self._since, self._logged = 0.0, False
        self.timer = node.create_timer(period, self.check)

    def check(self) -> bool:
        """Poll the graph now; returns ``conflict``. The ERROR is logged once the publishers' node
        names are discovered (DDS announces an endpoint before its node's name), at most 1 s late."""
        infos = self.node.get_publishers_info_by_topic(self.topic)
        names = sorted(f"{i.node_namespace.rstrip('/')}/{i.node_name}" for i in infos)
        conflict = len(infos) > 1
        log = self.node.get_logger()
        now = time.monotonic()
        if conflict and not self.conflict:
            self.conflicts += 1
            self._since, self._logged = now, False
        if conflict and not self._logged:
            known = not any("_UNKNOWN_" in n for n in names)
            if known or now - self._since >= 1.0:
                self._logged = True
                what = (
                    "refusing to follow two sources: zero torque until one publisher is left"
                    if self.role == "follows"
                    else "the joints get two commands: stop one of the controllers"
                )
                log.error(f"{len(infos)} publishers on {self.topic} ({', '.join(names)}): {what}")
        elif self.conflict and not conflict:
            log.info(f"one publisher on {self.topic} again ({', '.join(names) or 'none'}): cleared")
        self.conflict, self.publishers = conflict, names
        return conflict

    def status(self) -> str:
        """'' or the diagnostics text of the conflict."""
        if not self.conflict:
            return ""
        return f"{len(self.publishers)} publishers on {self.topic}: {', '.join(self.publishers)}"
