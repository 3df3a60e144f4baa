"""rosbag2-compatible MCAP writer (no rclpy).

Output is a rosbag2 directory as ``ros2 bag record -s mcap`` makes it::

    <name>/<name>_0.mcap      profile "ros2"; schemas "pkg/msg/Type" (ros2msg, full definition incl. deps);
                              channels "cdr" with offered_qos_profiles (v9 strings) + topic_type_hash;
                              zstd chunks with message indexes; summary with statistics;
                              metadata records "friction_ros" (run info, written first) and "rosbag2"
    <name>/metadata.yaml      version 9, written by close()

Crash safety (loss bound after SIGKILL)
---------------------------------------
Messages are buffered in the open chunk; a chunk is completed, compressed and handed to the OS (unbuffered
file, so it survives the death of the process) when it exceeds ``chunk_size`` bytes *or* when
``flush_interval`` seconds have passed since the last completed chunk (checked on every ``write`` and by
``poll()``, which a node calls from a timer). After SIGKILL the reader recovers every message of completed
chunks, so at most the messages of the last ``min(flush_interval, time to fill chunk_size)`` seconds
(plus the time between two ``poll()`` calls) are lost. ``flush_interval=0`` completes a chunk per write
(no loss, poor compression). SIGINT/SIGTERM handlers should call ``close()``: nothing is lost.

Disk full
---------
A write that fails with ENOSPC, EDQUOT or EFBIG (:mod:`.disk_space`) closes the bag at once: the
space reserve kept next to it is freed, the MCAP file is cut back to the last complete write and
finished with a summary of what is on disk (:mod:`.mcap_close`), metadata.yaml is written for those
messages, and :class:`~.errors.DiskFullError` says in one line which disk filled and how many
messages the bag kept. Messages of the open chunk (at most ``flush_interval``) are not in it.
"""

from __future__ import annotations

import os
import time
from importlib.metadata import version
from pathlib import Path

import yaml
from mcap.data_stream import RecordBuilder
from mcap.records import Channel, Header, Schema
from mcap.writer import CompressionType
from mcap.writer import Writer as _McapWriter

from ..validation import check_choice, check_int, check_real
from .disk_space import CHUNK_INDEX_BYTES, DISK_FULL, SpaceReserve, advice, describe, reserve_size
from .errors import BagError, DiskFullError
from .mcap_close import finish_cut_short
from .mcap_records import MAGIC
from .msgdef import schema_text, type_hash
from .qos import dump_qos, normalize_qos

RUN_METADATA_NAME = "friction_ros"
RESERVE_NAME = ".space_reserve"  # kept in the bag directory while writing (see disk_space)
COMPRESSIONS = {"zstd": CompressionType.ZSTD, "lz4": CompressionType.LZ4, "none": CompressionType.NONE}


def package_version() -> str:
    try:
        return version("friction_ros")
    except Exception:  # noqa: BLE001 - not installed as a distribution
        return "unknown"


def run_metadata(
    preset: str = "",
    program: str = "",
    parameter_files: list[str] | tuple[str, ...] = (),
    **extra,
) -> dict[str, str]:
    """Run information for the ``friction_ros`` MCAP metadata record (all values strings).

    Parameter files are embedded by content (key ``parameter_file:<path>``) so the bag is self-contained.
    """
    md = {
        "package_version": package_version(),
        "preset": str(preset),
        "program": str(program),
        "host": os.uname().nodename,
        "created": time.strftime("%Y-%m-%dT%H:%M:%S%z"),
        "parameter_files": ",".join(str(p) for p in parameter_files),
    }
    for p in parameter_files:
        try:
            md[f"parameter_file:{p}"] = Path(p).read_text()
        except OSError as exc:
            raise BagError(f"parameter file {p!r} cannot be read: {exc.strerror}") from None
    for k, v in extra.items():
        md[str(k)] = v if isinstance(v, str) else yaml.safe_dump(v, default_flow_style=True).strip()
    return md


class _DirectStream:
    """Write-through file: every record the MCAP writer emits goes straight to the OS (survives SIGKILL)."""

    def __init__(self, path: Path):
        self._f = open(path, "wb", buffering=0)  # noqa: SIM115
        self._pos = 0

    def write(self, data) -> int:
        view = memoryview(data)
        while len(view):
            n = self._f.write(view)
            view = view[n:]
        self._pos += len(data)
        return len(data)

    def tell(self) -> int:
        return self._pos

    def flush(self) -> None:
        pass

    def close(self) -> None:
        self._f.close()


class BagWriter:
    """Write a rosbag2 MCAP bag directory. Use as a context manager or call ``close()``.

    Parameters: ``chunk_size`` [bytes, uncompressed] and ``flush_interval`` [s] set the SIGKILL loss bound
    (see module doc); ``compression`` zstd | lz4 | none; ``metadata`` goes into the ``friction_ros``
    metadata record (see :func:`run_metadata`); ``overwrite`` allows an existing non-empty directory.
    """

    def __init__(
        self,
        path: str | os.PathLike,
        *,
        chunk_size: int = 1024 * 1024,
        flush_interval: float = 1.0,
        compression: str = "zstd",
        metadata: dict[str, str] | None = None,
        overwrite: bool = False,
        ros_distro: str = "jazzy",
    ):
        self.chunk_size = check_int("chunk_size", chunk_size, 1024, 1 << 30)
        self.flush_interval = check_real("flush_interval", flush_interval, 0.0, 3600.0, unit="s")
        check_choice("compression", compression, COMPRESSIONS)
        self.compression = compression
        self.ros_distro = ros_distro
        self.path = Path(path)
        if self.path.suffix == ".mcap":
            raise BagError(f"bag path {str(self.path)!r} must be a directory name, not a .mcap file")
        if self.path.exists():
            if not self.path.is_dir():
                raise BagError(f"bag path {str(self.path)!r} exists and is not a directory")
            if any(self.path.iterdir()) and not overwrite:
                raise BagError(f"bag directory {str(self.path)!r} already exists and is not empty")
            for old in [*self.path.glob("*.mcap"), self.path / "metadata.yaml", self.path / RESERVE_NAME]:
                if old.is_file():
                    old.unlink()
        self.path.mkdir(parents=True, exist_ok=True)
        self.file_path = self.path / f"{self.path.name}_0.mcap"
        self._schemas: dict[str, int] = {}
        self._topics: dict[str, dict] = {}
        self._start = None
        self._end = None
        self._count = 0
        self._last_flush = time.monotonic()
        self._closed = False
        self._records: list = []  # Schema and Channel records, repeated in a cut-short file's summary
        self._summary_bytes = 0  # their size plus the chunk indexes so far (sizes the space reserve)
        self._good = 0  # end of the last complete write: where a cut-short file is cut back to
        self._reserve = None
        library = "friction_ros " + package_version()
        head = RecordBuilder()
        Header("ros2", library).write(head)
        self._head = MAGIC + head.end()  # what start() writes
        self._stream = _DirectStream(self.file_path)
        self._w = _McapWriter(self._stream, chunk_size=self.chunk_size, compression=COMPRESSIONS[compression])
        self._call(self._reserve_space)
        self._call(self._w.start, "ros2", library)
        if metadata:
            self._call(self._w.add_metadata, RUN_METADATA_NAME, {str(k): str(v) for k, v in metadata.items()})
        self._call(self._w.flush)

    # ------------------------------------------------------------------ disk full
    def _reserve_space(self) -> None:
        size = reserve_size(self._summary_bytes)
        if self._reserve is None:
            self._reserve = SpaceReserve(self.path / RESERVE_NAME, size)
        else:
            self._reserve.grow(size)

    def _call(self, fn, *args) -> None:
        """Run one write of the MCAP writer; a full disk closes the bag (DiskFullError)."""
        try:
            fn(*args)
            pos = self._stream.tell()
            if pos != self._good:  # a write completed (a chunk and its indexes, a metadata record)
                self._good = pos
                self._summary_bytes += CHUNK_INDEX_BYTES
                if self._reserve.size < reserve_size(self._summary_bytes):
                    self._reserve_space()
        except OSError as exc:
            if exc.errno not in DISK_FULL:
                raise
            self._cut_short(exc)

    def _cut_short(self, exc: OSError) -> None:
        """Close the bag with what reached the disk, then raise DiskFullError (see the module doc)."""
        where = describe(exc, self.path)
        self._closed = True
        try:
            self._stream.close()
        except OSError:
            pass
        if self._reserve is not None:
            self._reserve.release()
        schemas = [r for r in self._records if isinstance(r, Schema)]
        channels = [r for r in self._records if isinstance(r, Channel)]
        try:
            found = finish_cut_short(self.file_path, self._good, self._head, schemas, channels, DISK_FULL)
        except OSError as again:
            raise DiskFullError(
                f"disk full: {where} while writing bag {self.path}; the bag could not be finished "
                f"({again.strerror}): {advice(exc)}, then read it with 'friction-bag recover'",
                0,
                self._count,
                where,
                advice(exc),
            ) from None
        by_id = {c.id: c.topic for c in channels}
        counts = {by_id[c]: n for c, n in found.counts().items() if c in by_id}
        kept = sum(counts.values())
        note = ""
        try:
            self._write_yaml(self._info(counts, kept, *found.span() if kept else (None, None)))
        except OSError as again:
            if again.errno not in DISK_FULL:
                raise
            note = " (no room left for its metadata.yaml)"
        raise DiskFullError(
            f"disk full: {where} while writing bag {self.path}: the bag is closed with the {kept} "
            f"messages written before{note}, {self._count - kept} not written; {advice(exc)}",
            kept,
            self._count - kept,
            where,
            advice(exc),
        ) from None

    # ------------------------------------------------------------------ topics and messages
    def add_topic(
        self,
        topic: str,
        msgtype: str,
        *,
        qos_profiles: list[dict] | None = None,
        msgdef: str | None = None,
        type_description_hash: str | None = None,
    ) -> None:
        """Register ``topic`` of ``msgtype`` (``pkg/msg/Type``). The definition is read from the installed
        ``.msg`` files unless ``msgdef`` (full concatenated text) is given."""
        if topic in self._topics:
            if self._topics[topic]["type"] != msgtype:
                raise BagError(
                    f"topic {topic} already registered as {self._topics[topic]['type']}, not {msgtype}"
                )
            return
        if msgtype not in self._schemas:
            text = (msgdef if msgdef is not None else schema_text(msgtype)).encode()
            self._schemas[msgtype] = sid = self._w.register_schema(msgtype, "ros2msg", text)
            self._records.append(Schema(id=sid, data=text, encoding="ros2msg", name=msgtype))
            self._summary_bytes += len(text) + len(msgtype) + 32
        qos = [normalize_qos(q) for q in (qos_profiles or [])]
        thash = type_description_hash if type_description_hash is not None else type_hash(msgtype)
        meta = {"offered_qos_profiles": dump_qos(qos), "topic_type_hash": thash}
        cid = self._w.register_channel(topic, "cdr", self._schemas[msgtype], meta)
        sid = self._schemas[msgtype]
        self._records.append(
            Channel(id=cid, topic=topic, message_encoding="cdr", schema_id=sid, metadata=meta)
        )
        self._summary_bytes += len(topic) + sum(len(k) + len(v) for k, v in meta.items()) + 1024
        self._topics[topic] = {"id": cid, "type": msgtype, "qos": qos, "hash": thash, "count": 0, "seq": 0}

    @property
    def topics(self) -> dict[str, str]:
        return {t: v["type"] for t, v in self._topics.items()}

    @property
    def message_count(self) -> int:
        return self._count

    def write(self, topic: str, data: bytes, log_time: int, publish_time: int | None = None) -> None:
        """Append one serialized CDR message; times in ns since the epoch (log = receive time)."""
        if self._closed:
            raise BagError(f"bag {self.path} is closed")
        try:
            t = self._topics[topic]
        except KeyError:
            raise BagError(f"topic {topic} was not registered with add_topic()") from None
        t["seq"] += 1
        t["count"] += 1
        self._count += 1
        self._call(
            self._w.add_message,
            t["id"],
            log_time,
            data,
            log_time if publish_time is None else publish_time,
            t["seq"] & 0xFFFFFFFF,
        )
        if self._start is None or log_time < self._start:
            self._start = log_time
        if self._end is None or log_time > self._end:
            self._end = log_time
        self.poll()

    def poll(self) -> None:
        """Complete the open chunk if ``flush_interval`` has elapsed (call periodically when idle)."""
        if not self._closed and time.monotonic() - self._last_flush >= self.flush_interval:
            self.flush()

    def flush(self) -> None:
        """Complete the open chunk now and hand it to the OS."""
        self._call(self._w.flush)
        self._last_flush = time.monotonic()

    def add_metadata(self, name: str, data: dict[str, str]) -> None:
        """Write an extra MCAP metadata record (``rosbag2`` is reserved)."""
        if name == "rosbag2":
            raise BagError("metadata record name 'rosbag2' is reserved for the rosbag2 bag information")
        self._call(self._w.add_metadata, name, {str(k): str(v) for k, v in data.items()})

    # ------------------------------------------------------------------ closing
    def bag_info(self) -> dict:
        """The ``rosbag2_bagfile_information`` mapping (metadata.yaml version 9)."""
        counts = {name: t["count"] for name, t in self._topics.items()}
        return self._info(counts, self._count, self._start, self._end)

    def _info(self, counts: dict[str, int], total: int, first: int | None, last: int | None) -> dict:
        """metadata.yaml of ``total`` messages, ``counts`` per topic, log times ``first`` to ``last``."""
        start = first or 0
        duration = (last - first) if first is not None else 0
        return {
            "version": 9,
            "storage_identifier": "mcap",
            "duration": {"nanoseconds": duration},
            "starting_time": {"nanoseconds_since_epoch": start},
            "message_count": total,
            "topics_with_message_count": [
                {
                    "topic_metadata": {
                        "name": name,
                        "type": t["type"],
                        "serialization_format": "cdr",
                        "offered_qos_profiles": t["qos"],
                        "type_description_hash": t["hash"],
                    },
                    "message_count": counts.get(name, 0),
                }
                for name, t in self._topics.items()
            ],
            "compression_format": "",
            "compression_mode": "",
            "relative_file_paths": [self.file_path.name],
            "files": [
                {
                    "path": self.file_path.name,
                    "starting_time": {"nanoseconds_since_epoch": start},
                    "duration": {"nanoseconds": duration},
                    "message_count": total,
                }
            ],
            "custom_data": None,
            "ros_distro": self.ros_distro,
        }

    def close(self) -> None:
        """Finish the MCAP file (summary, statistics, indexes) and write metadata.yaml."""
        if self._closed:
            return
        self._call(self._w.flush)  # the last chunk first: a disk that fills after it keeps it
        info = self.bag_info()
        self._call(
            self._w.add_metadata, "rosbag2", {"serialized_metadata": yaml.safe_dump(info, sort_keys=False)}
        )
        self._call(self._w.finish)
        self._stream.close()
        self._closed = True
        self._reserve.release()  # room for metadata.yaml on a disk that filled just now
        try:
            self._write_yaml(info)
        except OSError as exc:
            if exc.errno not in DISK_FULL:
                raise
            raise DiskFullError(
                f"disk full: {describe(exc, self.path)} while writing bag {self.path}: the MCAP file is "
                f"complete ({self._count} messages) but metadata.yaml could not be written",
                self._count,
                0,
                describe(exc, self.path),
                advice(exc),
            ) from None

    def _write_yaml(self, info: dict) -> None:
        text = yaml.safe_dump({"rosbag2_bagfile_information": info}, sort_keys=False)
        tmp = self.path / "metadata.yaml.tmp"
        try:
            tmp.write_text(text)
            tmp.replace(self.path / "metadata.yaml")
        finally:
            tmp.unlink(missing_ok=True)

    def __enter__(self) -> BagWriter:
        return self

    def __exit__(self, *exc) -> None:
        self.close()
