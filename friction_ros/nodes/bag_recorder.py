"""bag_recorder: record chosen topics to a rosbag2-compatible MCAP bag directory.

    bag_recorder -o bags/run_1 /joint_states /controller_state --preset abb_m19s --program plateaus
    bag_recorder --ros-args -p topics:="[/joint_states]" -p output:=bags/run_1 -p flush_interval:=0.5

Topics are subscribed as soon as a publisher appears (generic raw subscriptions: messages are stored
as received, never deserialised). The subscription is reliable unless a publisher offers best effort,
and transient-local if every publisher is. Each message is stored with log_time = receive time and
publish_time = source timestamp (ns since epoch). The publishers' offered QoS go into the channel
metadata (``offered_qos_profiles``).

Burst safety: the subscriptions keep *all* samples (``qos_depth`` 0, the default): a reliable
reader that keeps all never overwrites a sample it has not taken, so a burst backs up in the
publisher's history (RECORDED_QOS: 5000 deep) instead of being dropped here; only what a publisher
itself gives up is lost. ``qos_depth`` > 0 restores a keep-last reader of that depth.

Drops are counted per topic, exactly: the larger of the samples DDS reports lost to the
subscription (``message_lost`` event: every publisher, also when several publish on one topic)
and the gaps in the publisher's sequence numbers (``publication_sequence_number`` of each
message, counted while the topic has one publisher; catches a keep-last reader overwriting
samples, which DDS does not report). A sample lost before the first one received on a topic, or
left undelivered by a publisher that exits before the recorder took it, has no later sample to
reveal it and is not counted. Drops are logged when they happen (at most one line per topic and
diagnostics period), published in ``diagnostics`` (WARN, ``dropped`` and per-topic counts), written
into the bag as the MCAP metadata record ``friction_ros_recording`` (``messages``, ``dropped``,
``received:<topic>``, ``dropped:<topic>``) and in the final log line.

SIGINT/SIGTERM: the recorder stops subscribing, takes every message still queued, then finishes the
MCAP file (summary, statistics) and writes metadata.yaml. SIGKILL: every completed chunk is
recoverable by ``friction_ros.core.bag.read_bag``; at most the last ``flush_interval`` seconds (or
``chunk_size`` bytes, whichever comes first) are lost.

Disk full (no space left, quota exceeded or the file size limit): the recorder logs one error line
naming the disk and the bag, leaves the bag closed (MCAP summary and metadata.yaml for the messages
that reached the disk: all but those of the open chunk) and exits with code 1.
"""

from __future__ import annotations

import signal
import sys
import time

import rclpy
from rclpy.event_handler import SubscriptionEventCallbacks
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor

from friction_ros.core.bag import BagWriter, DiskFullError, run_metadata
from friction_ros.core.bag.recording import (
    RECORDING_METADATA_NAME,
    RecordingStats,
    wanted_topic,
)
from friction_ros.nodes.bag_common import (
    fail,
    message_class,
    qos_to_dict,
)
from friction_ros.nodes.bag_recorder_options import SCHEMA, build_parser, parse_cli
from friction_ros.nodes.diagnostics import DiagnosticsPublisher
from friction_ros.nodes.parameters import ParameterNode, declare_config
from friction_ros.nodes.qos import recording_qos
from friction_ros.nodes.runtime import log_events, start_process
from friction_ros.nodes.safe_subscription import BYTES, safe_subscription

#: messages taken from one topic's queue after the one the executor delivered (a bound: the timers
#: and the other topics get their turn)
DRAIN_MAX = 1000
#: wall time [s] the main loop waits after each executor round, so that messages arriving at a
#: high rate are recorded in batches (a bag's contents do not depend on it; its receive stamps are
#: taken by the middleware)
BATCH_WAIT = 0.002


class BagRecorder(ParameterNode):
    """Records topics into a :class:`~friction_ros.core.bag.BagWriter` bag."""

    TAKES_MESSAGE_INFO = True  # receive stamps: an executor that gives callbacks the message info

    def __init__(self, overrides: dict | None = None, **kwargs):
        super().__init__("bag_recorder", **kwargs)
        p = self.p = declare_config(self, SCHEMA, overrides=overrides)
        if not p["topics"] and not p["all_topics"]:
            raise ValueError("no topics to record: give topics (positional or -p topics:=[...]) or --all")
        out = p["output"] or time.strftime("run_%Y%m%d_%H%M%S")
        meta = run_metadata(p["preset"], p["program"], p["parameter_files"], topics=p["topics"])
        self.writer = BagWriter(
            out,
            chunk_size=p["chunk_size"],
            flush_interval=p["flush_interval"],
            compression=p["compression"],
            metadata=meta,
            overwrite=p["overwrite"],
        )
        self.wanted = [t if t.startswith("/") else "/" + t for t in p["topics"]]
        self.subs: dict[str, object] = {}
        self.recording = RecordingStats()
        self.stats = self.recording.topics  # per topic: core.bag.recording.TopicStats
        self.closed = False
        self.failed = ""  # the disk-full line, once writing stopped
        self.create_timer(p["discovery_period"], self.discover)
        poll = min(max(p["flush_interval"] / 4.0, 0.005), 0.1)
        self.create_timer(poll, self._poll)
        self.diag = DiagnosticsPublisher(self, "bag_recorder", str(self.writer.path))
        self.create_timer(p["diagnostics_period"], self.report)
        self.started = time.monotonic()
        self.discover()
        depth = f"keep-last {p['qos_depth']}" if p["qos_depth"] > 0 else "keep-all"
        self.get_logger().info(
            f"recording to {self.writer.path} (chunk {p['chunk_size']} B, flush {p['flush_interval']:g} s, "
            f"{p['compression']}, {depth}); topics: {', '.join(self.wanted) or 'all'}"
        )

    def discover(self) -> None:
        """Subscribe to wanted topics that have a publisher now; note topics with several publishers."""
        if self.closed:
            return
        for name, st in self.stats.items():
            st.publishers(self.count_publishers(name))
        for name, types in self.get_topic_names_and_types():
            if name in self.subs or not wanted_topic(name, self.wanted, self.p["all_topics"]):
                continue
            if len(types) != 1:
                self.get_logger().warning(f"topic {name} has several types {types}: not recorded")
                self.subs[name] = None
                continue
            msgtype = types[0]
            try:
                cls = message_class(msgtype)
                pubs = self.get_publishers_info_by_topic(name)
                offered = [qos_to_dict(i.qos_profile) for i in pubs]
                self.writer.add_topic(name, msgtype, qos_profiles=offered)
            except ValueError as exc:
                self.get_logger().error(f"topic {name} not recorded: {exc}")
                self.subs[name] = None
                continue
            qos = recording_qos(pubs, self.p["qos_depth"])
            st = self.recording.add(name, len(pubs))

            def lost(info, st=st) -> None:
                st.lost = int(info.total_count)

            self.subs[name] = safe_subscription(
                self,
                cls,
                name,
                lambda data, info, topic=name: self._on_message(topic, data, info),
                qos,
                decode=BYTES,
                event_callbacks=SubscriptionEventCallbacks(message_lost=lost),
            ).subscription
            self.get_logger().info(f"recording {name} [{msgtype}]")

    def _on_message(self, topic: str, data: bytes, info) -> None:
        """Record one message, then everything else already queued on its topic: one executor
        wake-up per batch instead of one per message (the executor's wait-set round costs about
        200 us a message in Python, several times the writing; see ``BATCH_WAIT``)."""
        self._record(topic, data, info)
        self._take_queued(topic, DRAIN_MAX)

    def _take_queued(self, topic: str, limit: int | None) -> None:
        """Record what is queued on ``topic``'s subscription (at most ``limit`` messages; None: all)."""
        sub = self.subs.get(topic)
        n = 0
        while sub is not None and not self.closed and (limit is None or n < limit):
            with sub.handle:
                taken = sub.handle.take_message(sub.msg_type, True)
            if taken is None:
                return
            self._record(topic, *taken)
            n += 1

    def _record(self, topic: str, data: bytes, info) -> None:
        if self.closed:
            return
        recv = int(info.get("received_timestamp") or 0) or time.time_ns()
        sent = int(info.get("source_timestamp") or 0) or recv
        try:
            self.writer.write(topic, data, recv, sent)
        except DiskFullError as exc:
            self._disk_full(exc)
            return
        self.stats[topic].receive(
            info.get("publication_sequence_number"), lambda: self.count_publishers(topic) > 1
        )

    def _poll(self) -> None:
        """Complete a chunk that waited ``flush_interval`` (timer)."""
        if self.closed:
            return
        try:
            self.writer.poll()
        except DiskFullError as exc:
            self._disk_full(exc)

    def _disk_full(self, exc: DiskFullError) -> None:
        """Stop recording: the writer closed the bag; one error line, the process exits with code 1."""
        self.closed = True
        self.failed = str(exc)
        self.get_logger().error(self.failed)

    @property
    def message_count(self) -> int:
        return self.recording.message_count

    @property
    def dropped(self) -> int:
        return self.recording.dropped

    def expired(self) -> bool:
        d = self.p["max_duration"]
        return d > 0 and time.monotonic() - self.started >= d

    def report(self) -> None:
        """Log new drops (one line per topic) and publish the diagnostics status."""
        if self.closed:
            return
        log_events(self.get_logger(), self.recording.new_drops())
        self.diag.publish(*self.recording.diagnostics())

    def summary(self) -> str:
        """The final line: messages, topics, drops (per topic when any)."""
        return self.recording.summary(self.writer.path)

    def on_shutdown(self) -> None:
        """Composed with other nodes: take what is queued on every topic, then finish the bag."""
        for topic in list(self.subs):
            self._take_queued(topic, None)
        self.close()

    def close(self) -> None:
        if not self.closed:
            self.closed = True
            try:
                self.writer.add_metadata(RECORDING_METADATA_NAME, self.recording.record())
                self.writer.close()
            except DiskFullError as exc:
                self._disk_full(exc)
                return
            log = self.get_logger().warning if self.dropped else self.get_logger().info
            log(self.summary())


def main(argv: list[str] | None = None) -> int:
    argv = list(sys.argv if argv is None else argv)
    stop = start_process(argv, about=sys.modules[__name__], parser=build_parser())
    if stop is None:
        return 2
    cli = parse_cli(rclpy.utilities.remove_ros_args(argv)[1:])
    signal.signal(signal.SIGXFSZ, signal.SIG_IGN)  # a file size limit: EFBIG, handled as disk full
    node = None
    try:
        node = BagRecorder(overrides=cli)
    except DiskFullError as exc:
        print(f"error: {exc}", file=sys.stderr)
        rclpy.try_shutdown()
        return 1
    except (ValueError, OSError) as exc:
        if node is not None:
            node.close()
            node.destroy_node()
        rclpy.try_shutdown()
        return fail(exc)
    executor = SingleThreadedExecutor()
    executor.add_node(node)
    try:
        while not stop.is_set() and rclpy.ok() and not node.expired() and not node.failed:
            executor.spin_once(timeout_sec=0.05)
            time.sleep(BATCH_WAIT)
        # Drain: take everything already delivered to our subscriptions before closing the file.
        idle_since = time.monotonic()
        last = node.message_count
        deadline = time.monotonic() + 3.0
        while time.monotonic() < deadline and time.monotonic() - idle_since < 0.15:
            executor.spin_once(timeout_sec=0.01)
            if node.message_count != last:
                last, idle_since = node.message_count, time.monotonic()
    except ExternalShutdownException:
        pass
    finally:
        node.close()
        executor.remove_node(node)
        node.destroy_node()
        rclpy.try_shutdown()
    return 1 if node.failed else 0


if __name__ == "__main__":
    sys.exit(main())
