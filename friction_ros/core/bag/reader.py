"""Fast MCAP / rosbag2 reader returning numpy arrays per topic and field (no rclpy, no mcap reader).

``read_bag(path)`` accepts a rosbag2 directory (``metadata.yaml`` + ``*.mcap``, or ``*.mcap`` files only)
or a single ``.mcap`` file, written by this package, ``ros2 bag record``, rosbags or any MCAP writer
using the ``ros2`` profile, with zstd/lz4/no chunk compression. Message definitions come from the
schemas embedded in the file (``ros2msg``); when a schema is empty or ``ros2idl``, the installed
``.msg`` files are used.

Recovery: a file cut off by SIGKILL/power loss has no summary; every complete chunk (and unchunked
message) before the cut is recovered, ``Bag.truncated`` is set and ``Bag.warnings`` says what was lost.

Unreadable input raises a :class:`~friction_ros.core.bag.errors.BagError` (a ``ValueError``) naming the
file and the problem: empty file, not MCAP, header truncated, unsupported storage, topic not found,
schema missing or not matching the payloads.
"""

from __future__ import annotations

import os
import struct
import zlib
from collections.abc import Iterable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import NamedTuple

import numpy as np
import yaml

from .cdr import decode_batch
from .errors import (
    BagError,
    CdrError,
    NotMcapError,
    SchemaError,
    TopicNotFoundError,
    TruncatedBagError,
    UnsupportedBagError,
)
from .msgdef import MsgDef, load_installed, normalize_type, parse_schema
from .qos import parse_qos

MAGIC = b"\x89MCAP0\r\n"
_U64 = struct.Struct("<Q")
_OPHDR = struct.Struct("<BQ")


# ------------------------------------------------------------------------------------------ results
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
    truncated: bool = False
    warnings: list[str] = field(default_factory=list)
    skipped: dict[str, str] = field(default_factory=dict)

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


# ------------------------------------------------------------------------------------------ file scan
def _read_str(buf, pos: int) -> tuple[str, int]:
    (n,) = struct.unpack_from("<I", buf, pos)
    return bytes(buf[pos + 4 : pos + 4 + n]).decode("utf-8", "replace"), pos + 4 + n


def _read_map(buf, pos: int) -> tuple[dict[str, str], int]:
    (total,) = struct.unpack_from("<I", buf, pos)
    end = pos + 4 + total
    pos += 4
    out = {}
    while pos < end:
        k, pos = _read_str(buf, pos)
        v, pos = _read_str(buf, pos)
        out[k] = v
    return out, end


class _FileScan:
    """Schemas, channels, metadata and message locations of one MCAP file."""

    def __init__(self, path: Path):
        self.path = path
        self.schemas: dict[int, tuple[str, str, bytes]] = {}
        self.channels: dict[int, tuple[str, int, str, dict]] = {}
        self.metadata: dict[str, dict[str, str]] = {}
        self.segments: list[bytes] = []
        self.locs: dict[int, list[tuple[int, np.ndarray]]] = {}
        self.truncated = False
        self.warnings: list[str] = []
        self.stats_count: int | None = None
        try:
            data = path.read_bytes()
        except OSError as exc:
            raise BagError(f"{path}: cannot read: {exc.strerror}") from None
        self._check_magic(data)
        self._scan(data)

    def _check_magic(self, data: bytes) -> None:
        p = self.path
        if not data:
            raise NotMcapError(f"{p}: file is empty (0 bytes): not an MCAP bag")
        if data[:8] == MAGIC:
            return
        if len(data) < 8 and MAGIC.startswith(data):
            raise TruncatedBagError(f"{p}: file is truncated inside the MCAP magic bytes ({len(data)} bytes)")
        if data[:16] == b"SQLite format 3\0":
            raise UnsupportedBagError(
                f"{p}: sqlite3 (.db3) rosbag2 storage is not supported: record with MCAP"
            )
        if data[:4] == b"\x28\xb5\x2f\xfd":
            raise UnsupportedBagError(
                f"{p}: file is zstd-compressed as a whole (rosbag2 file compression): decompress it first "
                "(zstd -d); MCAP chunk compression is supported"
            )
        raise NotMcapError(f"{p}: not an MCAP file: starts with {data[:8]!r}, expected {MAGIC!r}")

    def _scan(self, data: bytes) -> None:
        n = len(data)
        if n < 17:
            raise TruncatedBagError(f"{self.path}: MCAP header record is truncated (file has only {n} bytes)")
        op, ln = _OPHDR.unpack_from(data, 8)
        if op != 0x01 or 17 + ln > n:
            raise TruncatedBagError(
                f"{self.path}: MCAP header record is truncated or missing (not a complete MCAP file)"
            )
        self.profile, _ = _read_str(data, 17)
        if self.profile not in ("ros2", ""):
            raise UnsupportedBagError(f"{self.path}: MCAP profile {self.profile!r} is not 'ros2'")
        footer_ok = n >= 8 + 37 and data[-8:] == MAGIC and data[-37] == 0x02
        use_index = False
        if footer_ok:
            (summary_start,) = _U64.unpack_from(data, n - 37 + 9)
            if 0 < summary_start < n - 37:
                self._scan_summary(data, summary_start, n - 37)
                use_index = bool(self.channels)
        pos = 17 + ln
        pending: tuple[int, dict[int, np.ndarray]] | None = None
        finished = False
        view = memoryview(data)
        while True:
            if pos + 9 > n:
                break
            op, ln = _OPHDR.unpack_from(data, pos)
            body = pos + 9
            if body + ln > n:
                break
            if op == 0x07 and pending is not None:
                (ch,) = struct.unpack_from("<H", data, body)
                (nbytes,) = struct.unpack_from("<I", data, body + 2)
                entries = np.frombuffer(data, "<u8", nbytes // 8, body + 6).reshape(-1, 2)
                pending[1][ch] = entries[:, 1].astype(np.int64)
            else:
                if pending is not None:
                    self._finish_chunk(*pending, use_index)
                    pending = None
                if op == 0x06:
                    seg = self._chunk(view, body, ln)
                    if seg is not None:
                        pending = (seg, {})
                elif op == 0x03:
                    self._schema(data, body)
                elif op == 0x04:
                    self._channel(data, body)
                elif op == 0x05:
                    if not self.segments or self.segments[0] is not data:
                        self.segments.insert(0, data)
                        self.locs = {c: [(s + 1, o) for s, o in v] for c, v in self.locs.items()}
                    (ch,) = struct.unpack_from("<H", data, body)
                    self.locs.setdefault(ch, []).append((0, np.array([pos], dtype=np.int64)))
                elif op == 0x0C:
                    name, p2 = _read_str(data, body)
                    self.metadata[name], _ = _read_map(data, p2)
                elif op in (0x0F, 0x02):
                    finished = True
                    break
            pos = body + ln
        if pending is not None:
            self._finish_chunk(*pending, use_index and finished)
        if not finished:
            self.truncated = True
            self.warnings.append(
                f"{self.path}: file is truncated at byte {pos} of {n} (recording was killed?): recovered "
                "all complete chunks; messages of the last, incomplete chunk are lost"
            )
        elif not footer_ok:
            self.truncated = True
            self.warnings.append(
                f"{self.path}: file is truncated after the data section (summary/footer missing): all "
                "messages recovered"
            )

    def _scan_summary(self, data: bytes, start: int, end: int) -> None:
        pos = start
        while pos + 9 <= end:
            op, ln = _OPHDR.unpack_from(data, pos)
            body = pos + 9
            if op == 0x03:
                self._schema(data, body)
            elif op == 0x04:
                self._channel(data, body)
            elif op == 0x0B:
                (self.stats_count,) = _U64.unpack_from(data, body)
            pos = body + ln

    def _schema(self, buf, pos: int) -> None:
        (sid,) = struct.unpack_from("<H", buf, pos)
        name, pos = _read_str(buf, pos + 2)
        enc, pos = _read_str(buf, pos)
        (ln,) = struct.unpack_from("<I", buf, pos)
        self.schemas[sid] = (name, enc, bytes(buf[pos + 4 : pos + 4 + ln]))

    def _channel(self, buf, pos: int) -> None:
        cid, sid = struct.unpack_from("<HH", buf, pos)
        topic, pos = _read_str(buf, pos + 4)
        enc, pos = _read_str(buf, pos)
        meta, _ = _read_map(buf, pos)
        self.channels[cid] = (topic, sid, enc, meta)

    def _chunk(self, view: memoryview, body: int, ln: int) -> int | None:
        _, _, usize, crc = struct.unpack_from("<QQQI", view, body)
        comp, p = _read_str(view, body + 28)
        (rlen,) = _U64.unpack_from(view, p)
        raw = view[p + 8 : p + 8 + rlen]
        try:
            if comp == "":
                out = bytes(raw)
            elif comp == "zstd":
                import zstandard

                out = zstandard.ZstdDecompressor().decompress(raw, max_output_size=usize)
            elif comp == "lz4":
                import lz4.frame

                out = lz4.frame.decompress(raw)
            else:
                raise UnsupportedBagError(
                    f"{self.path}: chunk compression {comp!r} is not supported (zstd, lz4, none)"
                )
        except UnsupportedBagError:
            raise
        except Exception as exc:  # noqa: BLE001 - corrupt compressed data
            self.warnings.append(f"{self.path}: skipped a corrupt chunk at byte {body - 9}: {exc}")
            return None
        if len(out) != usize or (crc and zlib.crc32(out) != crc):
            self.warnings.append(f"{self.path}: skipped a chunk with bad size/CRC at byte {body - 9}")
            return None
        self.segments.append(out)
        return len(self.segments) - 1

    def _finish_chunk(self, seg: int, index: dict[int, np.ndarray], use_index: bool) -> None:
        if use_index and index:
            for ch, offs in index.items():
                self.locs.setdefault(ch, []).append((seg, offs))
            return
        buf = self.segments[seg]
        n = len(buf)
        pos = 0
        found: dict[int, list[int]] = {}
        while pos + 9 <= n:
            op, ln = _OPHDR.unpack_from(buf, pos)
            if pos + 9 + ln > n:
                break
            if op == 0x05:
                found.setdefault(buf[pos + 9] | (buf[pos + 10] << 8), []).append(pos)
            elif op == 0x03:
                self._schema(buf, pos + 9)
            elif op == 0x04:
                self._channel(buf, pos + 9)
            pos += 9 + ln
        for ch, offs in found.items():
            self.locs.setdefault(ch, []).append((seg, np.array(offs, dtype=np.int64)))


def _gather(big: np.ndarray, pos: np.ndarray, width: int, dtype: str) -> np.ndarray:
    return np.ascontiguousarray(np.lib.stride_tricks.sliding_window_view(big, width)[pos]).view(dtype)[:, 0]


# ------------------------------------------------------------------------------------------ bag files
def bag_files(path: str | os.PathLike) -> tuple[Path, list[Path]]:
    """(bag path, MCAP files) of a rosbag2 directory or a single ``.mcap`` file."""
    p = Path(path)
    if not p.exists():
        raise BagError(f"{p}: no such bag file or directory")
    if p.is_file():
        return p, [p]
    meta = p / "metadata.yaml"
    files: list[Path] = []
    if meta.is_file():
        try:
            info = yaml.safe_load(meta.read_text())["rosbag2_bagfile_information"]
            storage = info.get("storage_identifier", "")
            if storage and storage != "mcap":
                raise UnsupportedBagError(
                    f"{p}: storage {storage!r} is not supported: only MCAP bags can be read"
                )
            if info.get("compression_mode") == "file":
                raise UnsupportedBagError(
                    f"{p}: bag uses rosbag2 file compression ({info.get('compression_format')}): decompress the "
                    "files first; MCAP chunk compression is supported"
                )
            files = [p / f for f in info.get("relative_file_paths", [])]
        except (yaml.YAMLError, KeyError, TypeError, AttributeError):
            files = []
        files = [f for f in files if f.is_file()]
    if not files:
        files = sorted(p.glob("*.mcap"), key=lambda f: (len(f.name), f.name))
    if not files:
        if any(p.glob("*.db3")):
            raise UnsupportedBagError(f"{p}: sqlite3 (.db3) rosbag2 storage is not supported: only MCAP")
        raise NotMcapError(f"{p}: directory contains no .mcap file")
    return p, files


def _definitions(topic: str, name: str, enc: str, text: bytes) -> dict[str, MsgDef]:
    if enc == "ros2msg" and text.strip():
        try:
            return parse_schema(text.decode("utf-8", "replace"), name)
        except SchemaError as exc:
            try:
                return load_installed(name)
            except SchemaError:
                raise SchemaError(f"topic {topic}: schema {name} cannot be parsed: {exc}") from None
    try:
        return load_installed(name)
    except SchemaError as exc:
        why = "is empty" if not text.strip() else f"has encoding {enc!r} (only ros2msg is parsed)"
        raise SchemaError(f"topic {topic}: schema of {name} {why} and {exc}") from None


class _Loaded:
    """All files of a bag scanned: per topic (info, list of (big buffer, record offsets))."""

    def __init__(self, path: str | os.PathLike, topics: Iterable[str] | None):
        self.path, self.files = bag_files(path)
        want = None if topics is None else list(topics)
        self.info: dict[str, TopicInfo] = {}
        self.defs: dict[str, tuple[str, str, bytes]] = {}
        self.parts: dict[str, list[tuple[np.ndarray, np.ndarray]]] = {}
        self.metadata: dict[str, dict[str, str]] = {}
        self.warnings: list[str] = []
        self.skipped: dict[str, str] = {}
        self.truncated = False
        for f in self.files:
            scan = _FileScan(f)
            self.truncated |= scan.truncated
            self.warnings += scan.warnings
            self.metadata.update(scan.metadata)
            big = (
                np.concatenate([np.frombuffer(s, np.uint8) for s in scan.segments])
                if scan.segments
                else np.zeros(0, np.uint8)
            )
            base = np.cumsum([0] + [len(s) for s in scan.segments])
            for cid, (topic, sid, enc, meta) in scan.channels.items():
                locs = scan.locs.get(cid, [])
                count = sum(len(o) for _, o in locs)
                schema = scan.schemas.get(sid)
                if topic not in self.info:
                    name = (
                        normalize_type(schema[0])
                        if schema and "/" in schema[0]
                        else (schema[0] if schema else "")
                    )
                    try:
                        qos = parse_qos(meta.get("offered_qos_profiles", ""))
                    except BagError as exc:
                        qos = []
                        self.warnings.append(f"{f}: topic {topic}: {exc}")
                    self.info[topic] = TopicInfo(
                        topic,
                        name,
                        0,
                        enc,
                        schema[1] if schema else "",
                        schema[2].decode("utf-8", "replace") if schema else "",
                        qos,
                        meta.get("topic_type_hash", ""),
                    )
                self.info[topic].count += count
                if want is not None and topic not in want:
                    continue
                if schema is None:
                    self.skipped[topic] = f"channel references schema id {sid}, which is not in {f.name}"
                    continue
                if enc != "cdr":
                    self.skipped[topic] = f"message encoding {enc!r} is not cdr"
                    continue
                self.defs[topic] = schema
                if locs:
                    offs = np.concatenate([base[s] + o for s, o in locs])
                    self.parts.setdefault(topic, []).append((big, offs))
            if scan.stats_count is not None and not scan.truncated:
                got = sum(len(o) for v in scan.locs.values() for _, o in v)
                if got != scan.stats_count:
                    self.warnings.append(
                        f"{f}: found {got} messages, the summary statistics say {scan.stats_count}"
                    )
        if want is not None:
            for t in want:
                if t in self.skipped:
                    raise SchemaError(f"{self.path}: topic {t} cannot be decoded: {self.skipped[t]}")
                if t not in self.info:
                    raise TopicNotFoundError(
                        f"{self.path}: topic {t} not found: topics are {', '.join(sorted(self.info)) or '(none)'}"
                    )

    def records(self, topic: str):
        """(big, log_time, publish_time, data_start, data_len) sorted by log time, per file part."""
        for big, offs in self.parts.get(topic, []):
            ln = _gather(big, offs + 1, 8, "<u8").astype(np.int64)
            log = _gather(big, offs + 15, 8, "<u8").astype(np.int64)
            pub = _gather(big, offs + 23, 8, "<u8").astype(np.int64)
            start = offs + 31
            dlen = ln - 22
            if len(log) > 1 and np.any(np.diff(log) < 0):
                order = np.argsort(log, kind="stable")
                log, pub, start, dlen = log[order], pub[order], start[order], dlen[order]
            yield big, log, pub, start, dlen


def _concat_columns(parts: list[dict[str, np.ndarray]]) -> dict[str, np.ndarray]:
    if len(parts) == 1:
        return parts[0]
    keys = list(dict.fromkeys(k for p in parts for k in p))
    out = {}
    for k in keys:
        arrs = [p[k] for p in parts if k in p]
        try:
            if any(a.dtype == object for a in arrs) or len({a.shape[1:] for a in arrs}) > 1:
                raise ValueError
            out[k] = np.concatenate(arrs)
        except ValueError:
            obj = np.empty(sum(len(a) for a in arrs), dtype=object)
            i = 0
            for a in arrs:
                for row in a:
                    obj[i] = row
                    i += 1
            out[k] = obj
    return out


# ------------------------------------------------------------------------------------------ public API
def read_bag(path: str | os.PathLike, topics: Iterable[str] | str | None = None) -> Bag:
    """Read a bag into numpy columns per topic and field.

    ``topics``: names to read (default all); a missing requested topic raises TopicNotFoundError, an
    undecodable requested topic SchemaError. Undecodable topics not requested by name are listed in
    ``Bag.skipped``. Messages of each topic are in log-time order.
    """
    if isinstance(topics, str):
        topics = [topics]
    ld = _Loaded(path, topics)
    out: dict[str, TopicData] = {}
    for topic, info in ld.info.items():
        if topic in ld.skipped or (topics is not None and topic not in topics):
            continue
        if topic not in ld.defs:
            continue
        name, enc, text = ld.defs[topic]
        try:
            defs = _definitions(topic, name, enc, text)
            root = normalize_type(name)
            cols, logs, pubs = [], [], []
            for big, log, pub, start, dlen in ld.records(topic):
                cols.append(decode_batch(defs, root, big, start, dlen))
                logs.append(log)
                pubs.append(pub)
        except (SchemaError, CdrError) as exc:
            if topics is not None:
                raise type(exc)(f"{ld.path}: topic {topic} ({name}): {exc}") from None
            ld.skipped[topic] = str(exc)
            continue
        if not logs:
            logs, pubs, cols = [np.zeros(0, np.int64)], [np.zeros(0, np.int64)], [{}]
        log = np.concatenate(logs)
        pub = np.concatenate(pubs)
        fields = _concat_columns(cols)
        if len(logs) > 1 and np.any(np.diff(log) < 0):
            order = np.argsort(log, kind="stable")
            log, pub = log[order], pub[order]
            fields = {k: v[order] for k, v in fields.items()}
        out[topic] = TopicData(info, log, pub, fields)
    for t, why in ld.skipped.items():
        ld.warnings.append(f"{ld.path}: topic {t} skipped: {why}")
    return Bag(ld.path, ld.files, ld.info, out, ld.metadata, ld.truncated, ld.warnings, ld.skipped)


def read_joint_states(path: str | os.PathLike, joint: str, topic: str = "/joint_states") -> JointSeries:
    """Shortcut: ``read_bag(path, [topic])[topic].joint(joint)``."""
    return read_bag(path, [topic]).topic(topic, "sensor_msgs/msg/JointState").joint(joint)


def bag_info(path: str | os.PathLike) -> Bag:
    """Topics, types, counts, QoS and metadata of a bag without decoding payloads (``Bag.topics`` empty)."""
    ld = _Loaded(path, [])
    return Bag(ld.path, ld.files, ld.info, {}, ld.metadata, ld.truncated, ld.warnings, ld.skipped)


def iter_messages(path: str | os.PathLike, topics: Iterable[str] | None = None) -> Iterator[RawMessage]:
    """Raw serialized messages of all (or the given) topics in log-time order (for replay)."""
    ld = _Loaded(path, topics)
    rows = []
    for topic in ld.defs:
        for big, log, pub, start, dlen in ld.records(topic):
            for i in range(len(log)):
                s = int(start[i])
                rows.append((int(log[i]), topic, int(pub[i]), big, s, s + int(dlen[i])))
    rows.sort(key=lambda r: r[0])
    for log, topic, pub, big, a, b in rows:
        yield RawMessage(topic, log, pub, big[a:b].tobytes())
