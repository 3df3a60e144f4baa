"""joint_commands intake of drive_interface: the newest message, applied once per control period."""

from __future__ import annotations

import collections
import math
import time

from rclpy.node import Node
from sensor_msgs.msg import JointState

from friction_ros.core.can.axis import DriveAxis
from friction_ros.core.can.joint_commands import route_efforts
from friction_ros.core.wire import JointStateDecoder
from friction_ros.nodes.command_owner import CommandOwnerWatch
from friction_ros.nodes.qos import COMMAND_QOS
from friction_ros.nodes.safe_subscription import BYTES, safe_subscription


class CommandIntake:
    """``joint_commands`` (sensor_msgs/JointState effort, COMMAND_QOS) for the drives ``axes`` of
    the joints ``joints``.

    The subscription is raw (CDR bytes) and its callback only keeps the newest message and when it
    arrived; the control period applies it (:meth:`take`), so at most one message is decoded per
    period, by :class:`~friction_ros.core.wire.JointStateDecoder` (no message object; anything
    unusual goes through rclpy's deserialiser). Messages for none of the joints or with arrays
    that do not match are ignored, counted (:attr:`foreign`, :attr:`malformed`) and logged at most
    once a second per kind: the previous command stands until the watchdog.
    """

    def __init__(self, node: Node, joints: list[str], axes: list[DriveAxis]):
        self.joints, self.axes, self.logger = list(joints), axes, node.get_logger()
        self.foreign = 0  # messages for other joints only
        self.malformed = 0  # array lengths that do not match
        self._ignored_last: dict[str, float] = {}
        self._decoder = JointStateDecoder()
        self._pending: collections.deque = collections.deque(maxlen=1)
        self.owner = CommandOwnerWatch(node, self.joints)  # one command source per joint
        self.guard = safe_subscription(
            node, JointState, "joint_commands", self.on_bytes, COMMAND_QOS, decode=BYTES
        )
        self.subscription = self.guard.subscription

    def counts(self) -> dict[str, int]:
        """Diagnostics values: the messages ignored since start, by kind."""
        return {"commands_foreign": self.foreign, "commands_malformed": self.malformed}

    def on_bytes(self, data: bytes) -> None:
        """Subscription callback: keep the newest message for the period.

        A one-element deque: appending replaces an older message not applied yet, and append /
        popleft are atomic, so the loop thread (``loop_spin`` > 0) may take while the executor
        thread appends. The receive time is when the executor runs this callback: rclpy's
        EventsExecutor cannot give a callback the middleware's message info (reception stamp),
        it raises SystemError for a two-argument callback (rclpy 7.1).
        """
        self._pending.append((data, time.monotonic()))

    def take(self, now: float, lo: float) -> None:
        """Apply the newest message received since the previous period; its receive time is
        clamped to [``lo`` = previous period, ``now``] like the CAN frames."""
        if not self._pending:
            return
        data, t = self._pending.popleft()
        t = now if t > now else lo if t < lo else t
        try:
            cmd = self._decoder.decode(data)
        except Exception as exc:  # undecodable: rejected like a NaN command (zero torque) on every drive
            self.guard.report_undecodable(exc)  # counted, logged at most once a second
            self.apply((), (math.nan,) * len(self.axes), t)
            return
        conflicted = self.owner.admit(cmd.frame_id, cmd.name)
        if conflicted:  # a joint with two command sources: follow neither (command_owner policy)
            bad = {self.joints[i] for i in conflicted}
            names = cmd.name
            efforts = [0.0 if k < len(names) and names[k] in bad else e for k, e in enumerate(cmd.effort)]
            self.apply(names, efforts, t)
            return
        self.apply(cmd.name, cmd.effort, t)

    def on_message(self, msg: JointState, now: float | None = None) -> None:
        """A joint_commands message object (the node itself takes bytes)."""
        self.apply(msg.name, msg.effort, time.monotonic() if now is None else now)

    def apply(self, names, efforts, now: float) -> None:
        """Efforts to the drives (:func:`~friction_ros.core.can.joint_commands.route_efforts`)."""
        routed, kind, why = route_efforts(names, efforts, self.joints)
        for k, value in routed:
            if not self.axes[k].set_command(value, now):  # a command without effort is rejected too
                self.logger.warning(
                    f"rejected joint command effort = {value} for '{self.joints[k]}': must be a finite "
                    "number [N*m]; torque set to zero",
                    throttle_duration_sec=1.0,
                )
        if kind:
            if kind == "foreign":
                self.foreign += 1
            else:
                self.malformed += 1
            wall = time.monotonic()
            if wall - self._ignored_last.get(kind, -math.inf) >= 1.0:
                self._ignored_last[kind] = wall
                self.logger.warning(why)
