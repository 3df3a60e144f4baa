"""The bag recorder's bookkeeping without ROS: which topics to record, the QoS to subscribe with,
messages received and dropped per topic, and the reports of them.

Drops per topic are the larger of the samples the middleware reports lost to the subscription
(``lost``, its ``message_lost`` total) and the gaps in the publisher's sequence numbers (``gaps``,
counted while the topic has one publisher: numbers of several publishers interleave; a lower
number means the publisher was replaced and its numbers start again). The report goes into the
bag as the metadata record :data:`RECORDING_METADATA_NAME`.
"""

from __future__ import annotations

from collections.abc import Callable

from friction_ros.core.joint_channel import OK, WARN

IGNORED_TOPICS = ("/rosout", "/parameter_events")  # not recorded by ``all_topics``
RECORDING_METADATA_NAME = "friction_ros_recording"
SEQ_UNSUPPORTED = 1 << 63  # rmw reports RMW_MESSAGE_INFO_SEQUENCE_NUMBER_UNSUPPORTED (UINT64_MAX)


def wanted_topic(name: str, wanted, all_topics: bool) -> bool:
    """Whether topic ``name`` is to be recorded: one of ``wanted`` (absolute names), or with
    ``all_topics`` any but :data:`IGNORED_TOPICS`."""
    return name not in IGNORED_TOPICS if all_topics else name in wanted


def subscription_qos(offered, depth: int) -> dict:
    """The recording subscription's QoS from the publishers' offered ``(best_effort,
    transient_local)`` pairs: reliable unless one offers best effort, transient-local if every one
    (at least one) is; ``depth`` 0 keeps all, > 0 keep-last of that depth."""
    offered = list(offered)
    return {
        "keep_all": depth <= 0,
        "depth": depth if depth > 0 else 1,
        "reliable": not any(best_effort for best_effort, _ in offered),
        "transient_local": bool(offered) and all(latched for _, latched in offered),
    }


class TopicStats:
    """Received and dropped messages of one recorded topic (see the module docstring)."""

    __slots__ = ("received", "lost", "gaps", "last_seq", "several", "reported")

    def __init__(self, several: bool = False):
        self.received = 0
        self.lost = 0  # middleware message_lost total of the subscription
        self.gaps = 0  # missing publisher sequence numbers
        self.last_seq: int | None = None
        self.several = several  # several publishers: sequence numbers interleave, gaps not counted
        self.reported = 0  # dropped count of the last log line

    @property
    def dropped(self) -> int:
        return max(self.lost, self.gaps)

    def publishers(self, count: int) -> None:
        """The topic has ``count`` publishers now (discovery)."""
        several = count > 1
        if self.several and not several:
            self.last_seq = None  # one publisher again: its numbers are consecutive from here on
        self.several = several

    def receive(self, seq: int | None, several_now: Callable[[], bool]) -> None:
        """One message received, ``seq`` its publication sequence number (None: not given);
        ``several_now()`` tells whether a second publisher appeared (asked on a gap only)."""
        self.received += 1
        if seq is None or seq >= SEQ_UNSUPPORTED or self.several:
            return
        last = self.last_seq
        self.last_seq = seq
        if last is not None and seq != last + 1:
            if several_now():  # a second publisher appeared since the last discovery
                self.several = True
            elif seq > last + 1:
                self.gaps += seq - last - 1
            # a lower number: the publisher was replaced, its numbers start again


class RecordingStats:
    """Every recorded topic's :class:`TopicStats`, their totals and reports."""

    def __init__(self):
        self.topics: dict[str, TopicStats] = {}

    def add(self, name: str, publishers: int) -> TopicStats:
        st = self.topics[name] = TopicStats(several=publishers > 1)
        return st

    @property
    def message_count(self) -> int:
        return sum(st.received for st in self.topics.values())

    @property
    def dropped(self) -> int:
        return sum(st.dropped for st in self.topics.values())

    def new_drops(self) -> list[tuple[int, str]]:
        """Log events for the drops since the last call (one line per topic)."""
        events = []
        for name, st in self.topics.items():
            if st.dropped > st.reported:
                events.append(
                    (
                        WARN,
                        f"dropped {st.dropped - st.reported} message(s) on {name} "
                        f"({st.dropped} dropped, {st.received} recorded so far)",
                    )
                )
                st.reported = st.dropped
        return events

    def diagnostics(self) -> tuple[int, str, dict]:
        """``(level, text, values)``: WARN when anything was dropped; totals and per-topic counts."""
        values: dict = {"messages": self.message_count, "dropped": self.dropped, "topics": len(self.topics)}
        for name, st in self.topics.items():
            values[f"{name} received"] = st.received
            values[f"{name} dropped"] = st.dropped
        level = WARN if self.dropped else OK
        return level, f"{self.message_count} messages recorded, {self.dropped} dropped", values

    def record(self) -> dict:
        """The bag's :data:`RECORDING_METADATA_NAME` record."""
        record = {"messages": self.message_count, "dropped": self.dropped}
        for name, st in self.topics.items():
            record[f"received:{name}"] = st.received
            record[f"dropped:{name}"] = st.dropped
        return record

    def summary(self, path) -> str:
        """The final line: messages, topics, drops (per topic when any)."""
        text = f"wrote {self.message_count} messages on {len(self.topics)} topic(s) to {path}"
        drops = {n: st.dropped for n, st in self.topics.items() if st.dropped}
        if drops:
            per = ", ".join(f"{n}: {d}" for n, d in drops.items())
            return f"{text}; DROPPED {sum(drops.values())} message(s) ({per})"
        return f"{text}; 0 dropped"
