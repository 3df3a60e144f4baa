"""Fast MCAP / rosbag2 reader returning numpy arrays per topic and field (no rclpy, no mcap reader).

``read_bag(path)`` accepts a rosbag2 directory (``metadata.yaml`` + ``*.mcap``, or ``*.mcap`` files only)
or a single ``.mcap`` file, written by this package, ``ros2 bag record``, rosbags or any MCAP writer
using the ``ros2`` profile, with zstd/lz4/no chunk compression. SQLite3 storage (``metadata.yaml``
saying ``sqlite3``, a directory of ``*.db3`` files, or a ``.db3`` file) is read through the
``rosbags`` library by :mod:`~friction_ros.core.bag.rosbags_reader` into the same containers
(also by ``bag_info`` and ``iter_messages``). Message definitions come from the
schemas embedded in the file (``ros2msg``); when a schema is empty or ``ros2idl``, the installed
``.msg`` files are used.

Recovery: a file cut off by SIGKILL/power loss has no summary; every complete chunk (and unchunked
message) before the cut is recovered, ``Bag.truncated`` is set and ``Bag.warnings`` says what was lost.
A damaged file (a chunk failing its CRC, a corrupt record, index or summary: see
:mod:`~friction_ros.core.bag.damage`) is read past the damage: ``Bag.damaged`` is set, ``Bag.lost``
holds the messages lost per topic (None where the number is unknown) and ``Bag.warnings`` starts with
a line saying so.

Unreadable input raises a :class:`~friction_ros.core.bag.errors.BagError` (a ``ValueError``) naming the
file and the problem: empty file, not MCAP, header truncated, unsupported storage, topic not found,
schema missing or not matching the payloads.
"""

from __future__ import annotations

import os
from collections.abc import Iterable, Iterator
from pathlib import Path

import numpy as np

from friction_ros.core.yaml_files import load_yaml

from .cdr import decode_batch
from .contents import Bag, JointSeries, RawMessage, TopicData, TopicInfo
from .damage import channel_loss, describe_loss, merge_loss
from .errors import (
    BagError,
    CdrError,
    NotMcapError,
    SchemaError,
    UnsupportedBagError,
    check_wanted,
)
from .mcap_scan import McapScan
from .msgdef import MsgDef, load_installed, normalize_type, parse_schema
from .qos import parse_qos


def _gather(big: np.ndarray, pos: np.ndarray, width: int, dtype: str) -> np.ndarray:
    return np.ascontiguousarray(np.lib.stride_tricks.sliding_window_view(big, width)[pos]).view(dtype)[:, 0]


# ------------------------------------------------------------------------------------------ bag files
def storage_of(path: str | os.PathLike) -> str:
    """``"sqlite3"`` for SQLite3 rosbag2 storage (metadata, ``*.db3`` files only, a .db3/SQLite file), else ``"mcap"``."""
    from .rosbags_reader import is_sqlite_file

    p = Path(path)
    if p.is_file():
        return "sqlite3" if is_sqlite_file(p) else "mcap"
    if not p.is_dir():
        return "mcap"
    meta = p / "metadata.yaml"
    if meta.is_file():
        try:
            storage = load_yaml(meta, "bag metadata")["rosbag2_bagfile_information"].get("storage_identifier")
        except (ValueError, KeyError, TypeError, AttributeError):
            storage = None
        if storage:
            return "sqlite3" if storage == "sqlite3" else "mcap"
    if not any(p.glob("*.mcap")) and any(p.glob("*.db3")):
        return "sqlite3"
    return "mcap"


def bag_files(path: str | os.PathLike) -> tuple[Path, list[Path]]:
    """(bag path, storage files) of a rosbag2 directory or a single ``.mcap``/``.db3`` file."""
    p = Path(path)
    if not p.exists():
        raise BagError(f"{p}: no such bag file or directory")
    if p.is_file():
        return p, [p]
    if storage_of(p) == "sqlite3":
        files = sorted(p.glob("*.db3"), key=lambda f: (len(f.name), f.name))
        if not files:
            raise BagError(f"{p}: sqlite3 bag directory contains no .db3 file")
        return p, files
    meta = p / "metadata.yaml"
    files: list[Path] = []
    if meta.is_file():
        try:
            info = load_yaml(meta, "bag metadata")["rosbag2_bagfile_information"]
            storage = info.get("storage_identifier", "")
            if storage and storage != "mcap":
                raise UnsupportedBagError(
                    f"{p}: storage {storage!r} is not supported: MCAP and sqlite3 bags can be read"
                )
            if info.get("compression_mode") == "file":
                raise UnsupportedBagError(
                    f"{p}: bag uses rosbag2 file compression ({info.get('compression_format')}): decompress the "
                    "files first; MCAP chunk compression is supported"
                )
            files = [p / f for f in info.get("relative_file_paths", [])]
        except UnsupportedBagError:
            raise
        except (ValueError, KeyError, TypeError, AttributeError):
            files = []
        files = [f for f in files if f.is_file()]
    if not files:
        files = sorted(p.glob("*.mcap"), key=lambda f: (len(f.name), f.name))
    if not files:
        raise NotMcapError(f"{p}: directory contains no .mcap file (and no .db3 file)")
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


def _topic_of(scan: McapScan, channel: int | None) -> str:
    if channel is None:
        return "topics unknown"
    return scan.channels[channel][0] if channel in scan.channels else f"channel {channel}"


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
        self.cut = False
        self.damaged = False
        self.lost: dict[str, int | None] = {}
        for f in self.files:
            scan = McapScan(f)
            self.truncated |= scan.truncated
            self.cut |= scan.cut
            self._damage(f, scan)
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
        check_wanted(self.path, want, self.skipped, self.info)

    def _damage(self, f: Path, scan: McapScan) -> None:
        """Damage of one file: a warning saying how many messages (per topic) were lost, then each problem."""
        found = {c: k for c, k in scan.found().items() if c in scan.channels}
        loss = channel_loss(scan.problems, scan.expected, found)
        if not scan.problems and not loss:
            extra = {c: k for c, k in found.items() if scan.expected and k > scan.expected.get(c, 0)}
            if extra:
                self.warnings.append(f"{f}: found more messages than the summary statistics say")
            return
        lost = {_topic_of(scan, c): k for c, k in loss.items()}
        self.damaged = True
        self.lost = merge_loss(self.lost, lost)
        self.warnings.append(f"{f}: file is damaged: {describe_loss(lost)}")
        if loss and not scan.problems:
            self.warnings.append(f"{f}: fewer messages than its summary statistics say")
        self.warnings += [f"{f}: {p.text}" for p in scan.problems]

    def bag(self, topics: dict[str, TopicData]) -> Bag:
        return Bag(
            self.path, self.files, self.info, topics, self.metadata, self.truncated, self.warnings,
            self.skipped, self.damaged, self.lost, cut=self.cut,
        )  # fmt: skip

    def span(self) -> tuple[int, int] | None:
        """Log times of the first and last message of every topic read [ns] (None: no message)."""
        lo, hi = None, None
        for parts in self.parts.values():
            for big, offs in parts:
                log = _gather(big, offs + 15, 8, "<u8").astype(np.int64)
                if len(log):
                    lo = int(log.min()) if lo is None else min(lo, int(log.min()))
                    hi = int(log.max()) if hi is None else max(hi, int(log.max()))
        return None if lo is None else (lo, hi)

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
    if storage_of(path) == "sqlite3":
        from .rosbags_reader import read_sqlite_bag

        return read_sqlite_bag(path, topics)
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
    return ld.bag(out)


def read_joint_states(path: str | os.PathLike, joint: str, topic: str = "/joint_states") -> JointSeries:
    """Shortcut: ``read_bag(path, [topic])[topic].joint(joint)``."""
    return read_bag(path, [topic]).topic(topic, "sensor_msgs/msg/JointState").joint(joint)


def bag_info(path: str | os.PathLike) -> Bag:
    """Topics, types, counts, QoS and metadata of a bag without decoding payloads (``Bag.topics`` empty)."""
    if storage_of(path) == "sqlite3":
        from .rosbags_reader import sqlite_bag_info

        return sqlite_bag_info(path)
    ld = _Loaded(path, None)
    bag = ld.bag({})
    bag.span = ld.span()
    return bag


def iter_messages(path: str | os.PathLike, topics: Iterable[str] | None = None) -> Iterator[RawMessage]:
    """Raw serialized messages of all (or the given) topics in log-time order (for replay)."""
    if storage_of(path) == "sqlite3":
        from .rosbags_reader import iter_sqlite_messages

        yield from iter_sqlite_messages(path, topics)
        return
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
