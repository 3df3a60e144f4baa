"""SQLite3 (``.db3``) rosbag2 bags read through the ``rosbags`` library into the MCAP reader's containers.

:func:`~friction_ros.core.bag.reader.read_bag` keeps its own fast MCAP reader and hands a bag whose
storage is ``sqlite3`` (``metadata.yaml`` says so, the directory holds ``*.db3`` files and no
``*.mcap``, or the path is a ``.db3``/SQLite file) to :func:`read_sqlite_bag`. ``rosbags.rosbag2.Reader``
supplies the serialized messages, their receive times and message definitions; the payloads are then
decoded by this package's vectorised CDR decoder (:func:`~friction_ros.core.bag.cdr.decode_batch`), so
the :class:`~friction_ros.core.bag.contents.Bag`, :class:`TopicData` columns and joint series are the
same as those of the same messages stored in MCAP.

Message definitions, first found wins: the definition stored in the bag (``ros2msg``, rosbag2 >= Iron),
the installed ``.msg`` files, then the ``rosbags`` Jazzy type store (standard types without a ROS
install) with ``friction_msgs`` registered from the package's ``msg_defs/friction_msgs/msg/*.msg``.
SQLite3 stores no publish time: ``publish_time`` is the receive (log) time.
"""

from __future__ import annotations

import functools
import os
from collections.abc import Iterable, Iterator
from pathlib import Path

import numpy as np

from .cdr import decode_batch
from .contents import Bag, RawMessage, TopicData, TopicInfo
from .errors import BagError, CdrError, SchemaError, UnsupportedBagError, check_wanted
from .msgdef import MsgDef, find_msg_file, load_installed, normalize_type, parse_schema

SQLITE_MAGIC = b"SQLite format 3\0"


def is_sqlite_file(path: Path) -> bool:
    """True for a ``.db3`` file or any file starting with the SQLite magic bytes."""
    if path.suffix.lower() == ".db3":
        return True
    try:
        with path.open("rb") as fh:
            return fh.read(16) == SQLITE_MAGIC
    except OSError:
        return False


def sqlite_sources(path: str | os.PathLike) -> tuple[Path, list[Path]]:
    """(bag path, what ``rosbags`` opens): the directory when it has ``metadata.yaml``, else its ``*.db3`` files."""
    p = Path(path)
    if p.is_file():
        return p, [p]
    if (p / "metadata.yaml").is_file():
        return p, [p]
    files = sorted(p.glob("*.db3"), key=lambda f: (len(f.name), f.name))
    if not files:
        raise BagError(f"{p}: directory contains no .db3 file")
    return p, files


def _msg_defs_dirs() -> list[Path]:
    """Where ``friction_msgs`` .msg files may be: the source tree's msg_defs, then the installed share."""
    dirs = [Path(__file__).resolve().parents[3] / "msg_defs" / "friction_msgs" / "msg"]
    try:
        dirs.append(find_msg_file("friction_msgs/msg/ExperimentEvent").parent)
    except SchemaError:
        pass
    return [d for d in dirs if d.is_dir()]


@functools.cache
def typestore():
    """The rosbags ROS 2 Jazzy type store with the ``friction_msgs`` types registered."""
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    store = get_typestore(Stores.ROS2_JAZZY)
    for d in _msg_defs_dirs()[:1]:
        types = {}
        for f in sorted(d.glob("*.msg")):
            types.update(get_types_from_msg(f.read_text(), f"friction_msgs/msg/{f.stem}"))
        store.register(types)
    return store


def _definitions(topic: str, msgtype: str, fmt: str, text: str) -> tuple[dict[str, MsgDef], str]:
    """({type: MsgDef}, schema text) of ``msgtype``: the bag's own, installed, or the rosbags type store's."""
    errors = []
    if fmt == "MSG" and text.strip():
        try:
            return parse_schema(text, msgtype), text
        except SchemaError as exc:
            errors.append(str(exc))
    try:
        defs = load_installed(msgtype)
        return defs, ""
    except SchemaError as exc:
        errors.append(str(exc))
    try:
        generated, _ = typestore().generate_msgdef(msgtype, ros_version=2)
        return parse_schema(generated, msgtype), generated
    except Exception as exc:  # rosbags raises its own TypesysError for unknown types
        errors.append(f"rosbags type store: {exc}")
    raise SchemaError(f"topic {topic}: no message definition of {msgtype}: {'; '.join(errors)}")


def _one_line(exc: BaseException) -> str:
    text = " ".join(str(exc).split()) or type(exc).__name__
    return text if len(text) < 300 else text[:297] + "..."


class _Sqlite:
    """Connections and raw messages of every source of a SQLite3 bag (all read in one pass)."""

    def __init__(self, path: str | os.PathLike, topics: Iterable[str] | None, payloads: bool = True):
        from rosbags.rosbag2 import Reader

        self.path, self.sources = sqlite_sources(path)
        want = None if topics is None else list(topics)
        self.info: dict[str, TopicInfo] = {}
        self.defs: dict[str, tuple[str, str]] = {}  # topic -> (format, text)
        self.rows: dict[str, list[tuple[int, bytes]]] = {}
        self.metadata: dict[str, dict[str, str]] = {}
        self.skipped: dict[str, str] = {}
        self.span: tuple[int, int] | None = None  # first and last log time [ns]
        for src in self.sources:
            try:
                with Reader(src) as reader:
                    if reader.compression_mode == "file":
                        raise UnsupportedBagError(
                            f"{src}: bag uses rosbag2 file compression: decompress the files first"
                        )
                    custom = getattr(reader.storage.metadata, "custom", None)
                    if custom:
                        self.metadata.setdefault("rosbag2_custom_data", {}).update(
                            {str(k): str(v) for k, v in custom.items()}
                        )
                    if reader.message_count:
                        first, last = int(reader.start_time), int(reader.end_time) - 1
                        if self.span is not None:
                            first, last = min(first, self.span[0]), max(last, self.span[1])
                        self.span = (first, last)
                    conns = []
                    for c in reader.connections:
                        name = normalize_type(c.msgtype)
                        enc = getattr(c.ext, "serialization_format", "cdr")
                        fmt = c.msgdef.format.name
                        if c.topic not in self.info:
                            self.info[c.topic] = TopicInfo(
                                c.topic,
                                name,
                                0,
                                enc,
                                {"MSG": "ros2msg", "IDL": "ros2idl"}.get(fmt, ""),
                                c.msgdef.data,
                                [],
                                c.digest or "",
                            )
                        self.info[c.topic].count += int(c.msgcount)
                        if want is not None and c.topic not in want:
                            continue
                        if enc != "cdr":
                            self.skipped[c.topic] = f"message encoding {enc!r} is not cdr"
                            continue
                        if c.topic not in self.defs or (fmt == "MSG" and self.defs[c.topic][0] != "MSG"):
                            self.defs[c.topic] = (fmt, c.msgdef.data)
                        conns.append(c)
                    for t in self.defs:
                        self.rows.setdefault(t, [])
                    if payloads and conns:
                        for c, stamp, raw in reader.messages(connections=conns):
                            self.rows[c.topic].append((int(stamp), bytes(raw)))
            except BagError:
                raise
            except FileNotFoundError as exc:
                raise BagError(f"{src}: cannot read the sqlite3 bag: {_one_line(exc)}") from None
            except Exception as exc:  # rosbags ReaderError, apsw errors on a damaged database ...
                raise BagError(f"{src}: cannot read the sqlite3 bag: {_one_line(exc)}") from None
        check_wanted(self.path, want, self.skipped, self.info)

    def columns(self, topic: str) -> tuple[np.ndarray, dict[str, np.ndarray]]:
        """(log times [ns] sorted, decoded columns) of ``topic``."""
        rows = sorted(self.rows.get(topic, []), key=lambda r: r[0])
        log = np.fromiter((r[0] for r in rows), dtype=np.int64, count=len(rows))
        if not rows:
            return log, {}
        info = self.info[topic]
        fmt, text = self.defs[topic]
        defs, schema = _definitions(topic, info.msgtype, fmt, text)
        if schema and not info.schema:
            info.schema, info.schema_encoding = schema, "ros2msg"
        lengths = np.fromiter((len(r[1]) for r in rows), dtype=np.int64, count=len(rows))
        starts = np.concatenate([[0], np.cumsum(lengths)[:-1]]).astype(np.int64)
        big = np.frombuffer(b"".join(r[1] for r in rows), np.uint8)
        return log, decode_batch(defs, info.msgtype, big, starts, lengths)


def read_sqlite_bag(path: str | os.PathLike, topics: Iterable[str] | str | None = None) -> Bag:
    """:func:`~friction_ros.core.bag.reader.read_bag` for SQLite3 storage (same arguments, same result)."""
    if isinstance(topics, str):
        topics = [topics]
    want = None if topics is None else list(topics)
    sq = _Sqlite(path, want)
    out: dict[str, TopicData] = {}
    warnings: list[str] = []
    for topic, info in sq.info.items():
        if topic in sq.skipped or topic not in sq.defs:
            continue
        try:
            log, fields = sq.columns(topic)
        except (SchemaError, CdrError) as exc:
            if want is not None:
                raise type(exc)(f"{sq.path}: topic {topic} ({info.msgtype}): {exc}") from None
            sq.skipped[topic] = str(exc)
            continue
        out[topic] = TopicData(info, log, log.copy(), fields)
    for t, why in sq.skipped.items():
        warnings.append(f"{sq.path}: topic {t} skipped: {why}")
    files = [f for s in sq.sources for f in ([s] if s.is_file() else sorted(s.glob("*.db3")))]
    return Bag(sq.path, files, sq.info, out, sq.metadata, False, warnings, sq.skipped)


def sqlite_bag_info(path: str | os.PathLike) -> Bag:
    """Topics, types and counts of a SQLite3 bag without reading payloads (``Bag.topics`` empty)."""
    sq = _Sqlite(path, [], payloads=False)
    files = [f for s in sq.sources for f in ([s] if s.is_file() else sorted(s.glob("*.db3")))]
    return Bag(sq.path, files, sq.info, {}, sq.metadata, False, [], sq.skipped, span=sq.span)


def iter_sqlite_messages(
    path: str | os.PathLike, topics: Iterable[str] | None = None
) -> Iterator[RawMessage]:
    """Raw serialized messages of a SQLite3 bag in log-time order (publish time = log time)."""
    sq = _Sqlite(path, topics)
    rows = sorted(
        ((stamp, topic, raw) for topic, rs in sq.rows.items() for stamp, raw in rs), key=lambda r: r[0]
    )
    for stamp, topic, raw in rows:
        yield RawMessage(topic, stamp, stamp, raw)
