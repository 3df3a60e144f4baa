"""bag_player: replay a bag onto its topics with the recorded timing (or a rate factor).

    bag_player bags/run_1 --rate 2.0 --topics /joint_states --remap /joint_states=/replay/joint_states
    bag_player --ros-args -p bag:=bags/run_1 -p publish_clock:=true -p loop:=true

Messages are published as recorded (serialized bytes, no re-encoding) in log-time order; message k is
sent at ``start + (log_time[k] - log_time[0]) / rate`` on the monotonic clock. Publisher QoS follow
the recorded ``offered_qos_profiles`` (reliability, durability) with keep-last ``qos_depth``.
``publish_clock`` publishes ``/clock`` (rosgraph_msgs/Clock) with the bag time, at
``clock_frequency`` Hz of wall time (0: one /clock message before every replayed message), so nodes
with ``use_sim_time:=true`` run on bag time. Reads bags of this package and of ``ros2 bag record``.
"""

from __future__ import annotations

import argparse
import sys
import time

import rclpy
from rosgraph_msgs.msg import Clock

from friction_ros.core.bag import BagError, bag_info, iter_messages
from friction_ros.core.config import Field, Schema
from friction_ros.nodes.bag_common import (
    fail,
    message_class,
    qos_from_dicts,
)
from friction_ros.nodes.parameters import ParameterNode, declare_config
from friction_ros.nodes.runtime import start_process

SCHEMA = Schema(
    "bag_player",
    [
        Field("bag", "", "bag directory or .mcap file to replay (required)", read_only=True),
        Field("rate", 1.0, "replay speed factor (2.0 = twice as fast)", lo=1e-3, hi=1e3, read_only=True),
        Field("loop", False, "start again at the end until stopped", read_only=True),
        Field("topics", [], "topics to replay (empty = all)", kind=str, read_only=True),
        Field(
            "remap", [], "topic remappings 'from:=to' applied to replayed topics", kind=str, read_only=True
        ),
        Field("publish_clock", False, "publish /clock with the bag time", read_only=True),
        Field(
            "clock_frequency",
            100.0,
            "/clock rate of wall time, 0 = before every message",
            lo=0.0,
            hi=10000.0,
            unit="Hz",
            read_only=True,
        ),
        Field("qos_depth", 1000, "keep-last depth of the replay publishers", lo=1, hi=100000, read_only=True),
        Field(
            "start_delay",
            0.0,
            "wait before the first message (discovery)",
            lo=0.0,
            hi=3600.0,
            unit="s",
            read_only=True,
        ),
        Field(
            "wait_for_subscribers",
            0,
            "wait until every replay topic has this many subscribers",
            lo=0,
            hi=1000,
            read_only=True,
        ),
        Field(
            "wait_timeout",
            10.0,
            "longest wait for subscribers; then play anyway",
            lo=0.0,
            hi=3600.0,
            unit="s",
            read_only=True,
        ),
    ],
)


def parse_remaps(items: list[str]) -> dict[str, str]:
    """``["/from:=/to", "/a=/b"]`` -> ``{"/from": "/to", "/a": "/b"}`` (``=`` for the command line, where
    rcl would take ``:=`` for a node remapping)."""
    out = {}
    for item in items:
        sep = ":=" if ":=" in item else "="
        a, _, b = (s.strip() for s in item.partition(sep))
        if sep not in item or not a or not b:
            raise ValueError(f"remap = {item!r} must be of the form /from:=/to (or /from=/to)")
        out[a if a.startswith("/") else "/" + a] = b if b.startswith("/") else "/" + b
    return out


class BagPlayer(ParameterNode):
    """Replays a bag; call :meth:`play` (blocking) after construction."""

    def __init__(self, overrides: dict | None = None, **kwargs):
        super().__init__("bag_player", **kwargs)
        p = self.p = declare_config(self, SCHEMA, overrides=overrides)
        if not p["bag"]:
            raise ValueError("parameter bag is empty: give the bag directory or .mcap file to replay")
        remap = parse_remaps(p["remap"])
        info = bag_info(p["bag"])
        for w in info.warnings:
            self.get_logger().warning(w)
        wanted = [t if t.startswith("/") else "/" + t for t in p["topics"]] or list(info.info)
        missing = [t for t in wanted if t not in info.info]
        if missing:
            raise BagError(
                f"{info.path}: topic(s) {', '.join(missing)} not in the bag: topics are {', '.join(info.info)}"
            )
        self.messages = list(iter_messages(p["bag"], wanted))
        self.pubs = {}
        for t in wanted:
            ti = info.info[t]
            cls = message_class(ti.msgtype)
            self.pubs[t] = self.create_publisher(
                cls, remap.get(t, t), qos_from_dicts(ti.qos_profiles, p["qos_depth"])
            )
        self.clock_pub = self.create_publisher(Clock, "/clock", 10) if p["publish_clock"] else None
        self.published = 0
        self.get_logger().info(
            f"replaying {len(self.messages)} messages of {len(wanted)} topic(s) from {info.path} at rate {p['rate']:g}"
        )

    def _send_clock(self, bag_ns: int) -> None:
        msg = Clock()
        msg.clock.sec, msg.clock.nanosec = divmod(int(bag_ns), 1_000_000_000)
        self.clock_pub.publish(msg)

    def wait_for_subscribers(self, stop) -> None:
        n, end = self.p["wait_for_subscribers"], time.monotonic() + self.p["wait_timeout"]
        while n and not stop.is_set() and time.monotonic() < end:
            if all(pub.get_subscription_count() >= n for pub in self.pubs.values()):
                break
            time.sleep(0.01)
        if self.p["start_delay"]:
            stop.wait(self.p["start_delay"])

    def play(self, stop) -> int:
        """Publish every message with the recorded timing; returns the number of messages published."""
        if not self.messages:
            return 0
        rate = self.p["rate"]
        clock_period = 1.0 / self.p["clock_frequency"] if self.p["clock_frequency"] > 0 else 0.0
        first = self.messages[0].log_time
        while not stop.is_set():
            t0 = time.monotonic()
            next_clock = t0
            for m in self.messages:
                target = t0 + (m.log_time - first) * 1e-9 / rate
                while True:
                    now = time.monotonic()
                    if self.clock_pub is not None and clock_period and now >= next_clock:
                        self._send_clock(first + (now - t0) * rate * 1e9)
                        next_clock += clock_period
                    if now >= target or stop.is_set():
                        break
                    wake = (
                        min(target, next_clock) if (self.clock_pub is not None and clock_period) else target
                    )
                    time.sleep(max(0.0, min(wake - now, 0.05)))
                if stop.is_set():
                    break
                if self.clock_pub is not None and not clock_period:
                    self._send_clock(m.log_time)
                self.pubs[m.topic].publish(m.data)
                self.published += 1
            if not self.p["loop"]:
                break
        return self.published


def build_parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(
        allow_abbrev=False, prog="bag_player", description="Replay a bag (ROS parameters via --ros-args)."
    )
    ap.add_argument("bag", nargs="?", help="bag directory or .mcap file")
    ap.add_argument("-r", "--rate", type=float)
    ap.add_argument("-l", "--loop", action="store_true", default=None)
    ap.add_argument("--topics", nargs="+")
    ap.add_argument("--remap", nargs="+", help="/from=/to")
    ap.add_argument("--clock", dest="publish_clock", action="store_true", default=None, help="publish /clock")
    ap.add_argument("--clock-frequency", dest="clock_frequency", type=float, help="Hz, 0 = per message")
    ap.add_argument("--qos-depth", dest="qos_depth", type=int)
    ap.add_argument("--start-delay", dest="start_delay", type=float, help="s")
    ap.add_argument("--wait-for-subscribers", dest="wait_for_subscribers", type=int)
    ap.add_argument("--wait-timeout", dest="wait_timeout", type=float, help="s")
    return ap


def _parse_cli(argv: list[str]) -> dict:
    return {k: v for k, v in vars(build_parser().parse_args(argv)).items() if v is not None}


def main(argv: list[str] | None = None) -> int:
    argv = list(sys.argv if argv is None else argv)
    stop = start_process(argv, about=sys.modules[__name__], parser=build_parser())
    if stop is None:
        return 2
    node = None
    try:
        node = BagPlayer(overrides=_parse_cli(rclpy.utilities.remove_ros_args(argv)[1:]))
        node.wait_for_subscribers(stop)
        n = node.play(stop)
        node.get_logger().info(f"published {n} messages")
        time.sleep(0.2)  # let reliable writers deliver the tail before the participant goes away
    except (ValueError, OSError) as exc:
        return fail(exc)
    finally:
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()
    return 0


if __name__ == "__main__":
    sys.exit(main())
