"""What reading a bag returns: topics with numpy columns per field, joint series, raw messages.

:func:`~friction_ros.core.bag.reader.read_bag` builds a :class:`Bag`; nothing here reads files.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import NamedTuple

import numpy as np

from .errors import BagError, SchemaError, TopicNotFoundError
from .msgdef import normalize_type


@dataclass
class TopicInfo:
    """Description of one topic of a bag (no message data)."""

    name: str
    msgtype: str
    count: int
    message_encoding: str = "cdr"
    schema_encoding: str = "ros2msg"
    schema: str = ""
    qos_profiles: list[dict] = field(default_factory=list)
    type_hash: str = ""


class JointSeries(NamedTuple):
    """One joint of a JointState topic; arrays of shape (n,), NaN where the joint/field is absent."""

    name: str
    time: np.ndarray  # s since epoch, receive time (log_time)
    stamp: np.ndarray  # s since epoch, header stamp
    position: np.ndarray  # rad (m for prismatic)
    velocity: np.ndarray  # rad/s
    effort: np.ndarray  # N*m (N)


class TopicData:
    """Messages of one topic as columns: ``data["position"]``, ``data["header.stamp.sec"]`` ...

    ``log_time``/``publish_time`` are int64 ns since the epoch, ``time`` the log time in float s.
    """

    def __init__(self, info: TopicInfo, log_time, publish_time, fields: dict[str, np.ndarray]):
        self.info = info
        self.name = info.name
        self.msgtype = info.msgtype
        self.log_time = log_time
        self.publish_time = publish_time
        self.fields = fields

    def __len__(self) -> int:
        return len(self.log_time)

    def __repr__(self) -> str:
        return f"TopicData({self.name!r}, {self.msgtype}, {len(self)} messages, fields={list(self.fields)})"

    def __contains__(self, key: str) -> bool:
        return key in self.fields

    def __getitem__(self, key: str) -> np.ndarray:
        try:
            return self.fields[key]
        except KeyError:
            raise BagError(
                f"topic {self.name} ({self.msgtype}) has no field {key!r}: fields are {', '.join(self.fields)}"
            ) from None

    @property
    def time(self) -> np.ndarray:
        """Receive (log) time in s since the epoch."""
        return self.log_time * 1e-9

    @property
    def stamp(self) -> np.ndarray:
        """``header.stamp`` in s since the epoch (BagError if the type has no header)."""
        return _stamp(self.fields, self.name, self.msgtype)

    @property
    def joint_names(self) -> list[str]:
        """Joint names seen on a JointState topic, in order of first appearance."""
        names = self._require_joint_state()["name"]
        seen: dict[str, None] = {}
        for tup in dict.fromkeys(names).keys() if len(names) else []:
            for n in tup:
                seen.setdefault(n, None)
        return list(seen)

    def _require_joint_state(self) -> dict:
        if self.msgtype != "sensor_msgs/msg/JointState":
            raise SchemaError(f"topic {self.name} is {self.msgtype}, not sensor_msgs/msg/JointState")
        return self.fields

    def joint(self, name: str) -> JointSeries:
        """Position/velocity/effort of joint ``name`` of a JointState topic, selected by name per message."""
        f = self._require_joint_state()
        n = len(self)
        names = f["name"]
        cols: dict[str, np.ndarray] = {}
        if n == 0:
            empty = np.zeros(0)
            return JointSeries(name, empty, empty, empty, empty, empty)
        # column index of the joint per message (-1 = absent); fast path when names never change
        uniq = {t: (t.index(name) if name in t else -1) for t in dict.fromkeys(names)}
        if all(v == -1 for v in uniq.values()):
            raise BagError(
                f"topic {self.name}: no joint named {name!r}: joints are {', '.join(self.joint_names)}"
            )
        if len(uniq) == 1:
            col = np.full(n, next(iter(uniq.values())), dtype=np.int64)
        else:
            col = np.fromiter((uniq[t] for t in names), dtype=np.int64, count=n)
        for key in ("position", "velocity", "effort"):
            arr = f[key]
            out = np.full(n, np.nan)
            if arr.dtype != object:
                ok = (col >= 0) & (col < arr.shape[1])
                out[ok] = arr[np.flatnonzero(ok), col[ok]]
            else:
                for i in range(n):
                    a = arr[i]
                    if 0 <= col[i] < len(a):
                        out[i] = a[col[i]]
            cols[key] = out
        return JointSeries(name, self.time, self.stamp, cols["position"], cols["velocity"], cols["effort"])


def _stamp(fields: dict, topic: str, msgtype: str) -> np.ndarray:
    if "header.stamp.sec" not in fields:
        raise BagError(f"topic {topic} ({msgtype}) has no header.stamp")
    return fields["header.stamp.sec"].astype(np.float64) + fields["header.stamp.nanosec"] * 1e-9


@dataclass
class Bag:
    """Result of :func:`read_bag`."""

    path: Path
    files: list[Path]
    info: dict[str, TopicInfo]
    topics: dict[str, TopicData]
    metadata: dict[str, dict[str, str]]
    truncated: bool = False  # not finished (no valid summary/footer); see ``cut``
    warnings: list[str] = field(default_factory=list)
    skipped: dict[str, str] = field(default_factory=dict)
    damaged: bool = False  # a part of a file failed its check (see core.bag.damage)
    lost: dict[str, int | None] = field(default_factory=dict)  # messages lost per topic, None = unknown
    cut: bool = False  # truncated inside a record: the messages of its last, incomplete chunk are lost
    span: tuple[int, int] | None = None  # log times of the first and last message [ns] (bag_info)

    @property
    def duration(self) -> float | None:
        """Seconds from the first to the last message's log time (None: not known or no message)."""
        return None if self.span is None else (self.span[1] - self.span[0]) * 1e-9

    @property
    def lost_count(self) -> int | None:
        """Messages lost to damage (0 when none, None when the number is unknown)."""
        return None if any(v is None for v in self.lost.values()) else sum(self.lost.values())

    def __getitem__(self, topic: str) -> TopicData:
        return self.topic(topic)

    def __contains__(self, topic: str) -> bool:
        return topic in self.topics

    def topic(self, name: str, msgtype: str | None = None) -> TopicData:
        """Data of topic ``name``; if ``msgtype`` is given, SchemaError unless the topic has that type."""
        if name not in self.topics:
            if name in self.skipped:
                raise SchemaError(f"{self.path}: topic {name} cannot be decoded: {self.skipped[name]}")
            raise TopicNotFoundError(
                f"{self.path}: topic {name} not found: topics are {', '.join(sorted(self.info)) or '(none)'}"
            )
        data = self.topics[name]
        if msgtype is not None and normalize_type(msgtype) != data.msgtype:
            raise SchemaError(
                f"{self.path}: topic {name} has type {data.msgtype}, expected {normalize_type(msgtype)}"
            )
        return data

    @property
    def run_metadata(self) -> dict[str, str]:
        """The ``friction_ros`` metadata record (preset, program, parameter files, package version)."""
        return self.metadata.get("friction_ros", {})

    @property
    def message_count(self) -> int:
        return sum(len(t) for t in self.topics.values())

    @property
    def start_time(self) -> int:
        times = [int(t.log_time[0]) for t in self.topics.values() if len(t)]
        return min(times) if times else 0

    @property
    def end_time(self) -> int:
        times = [int(t.log_time[-1]) for t in self.topics.values() if len(t)]
        return max(times) if times else 0


class RawMessage(NamedTuple):
    topic: str
    log_time: int  # ns
    publish_time: int  # ns
    data: bytes  # CDR with encapsulation header
