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
"""

from __future__ import annotations

import os
import time
from pathlib import Path

import yaml
from mcap.writer import CompressionType
from mcap.writer import Writer as _McapWriter

from ..validation import check_choice, check_int, check_real
from .errors import BagError
from .msgdef import schema_text, type_hash
from .qos import dump_qos, normalize_qos

RUN_METADATA_NAME = "friction_ros"
COMPRESSIONS = {"zstd": CompressionType.ZSTD, "lz4": CompressionType.LZ4, "none": CompressionType.NONE}


def package_version() -> str:
    try:
        from importlib.metadata import version

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
            for old in [*self.path.glob("*.mcap"), self.path / "metadata.yaml"]:
                if old.is_file():
                    old.unlink()
        self.path.mkdir(parents=True, exist_ok=True)
        self.file_path = self.path / f"{self.path.name}_0.mcap"
        self._stream = _DirectStream(self.file_path)
        self._w = _McapWriter(
            self._stream,
            chunk_size=self.chunk_size,
            compression=COMPRESSIONS[compression],
        )
        self._w.start(profile="ros2", library="friction_ros " + package_version())
        self._schemas: dict[str, int] = {}
        self._topics: dict[str, dict] = {}
        self._start = None
        self._end = None
        self._count = 0
        self._last_flush = time.monotonic()
        self._closed = False
        if metadata:
            self._w.add_metadata(RUN_METADATA_NAME, {str(k): str(v) for k, v in metadata.items()})
        self._w.flush()

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
            text = msgdef if msgdef is not None else schema_text(msgtype)
            self._schemas[msgtype] = self._w.register_schema(msgtype, "ros2msg", text.encode())
        qos = [normalize_qos(q) for q in (qos_profiles or [])]
        thash = type_description_hash if type_description_hash is not None else type_hash(msgtype)
        meta = {"offered_qos_profiles": dump_qos(qos), "topic_type_hash": thash}
        cid = self._w.register_channel(topic, "cdr", self._schemas[msgtype], meta)
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
        self._w.add_message(
            t["id"], log_time, data, log_time if publish_time is None else publish_time, t["seq"] & 0xFFFFFFFF
        )
        self._count += 1
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
        self._w.flush()
        self._last_flush = time.monotonic()

    def add_metadata(self, name: str, data: dict[str, str]) -> None:
        """Write an extra MCAP metadata record (``rosbag2`` is reserved)."""
        if name == "rosbag2":
            raise BagError("metadata record name 'rosbag2' is reserved for the rosbag2 bag information")
        self._w.add_metadata(name, {str(k): str(v) for k, v in data.items()})

    # ------------------------------------------------------------------ closing
    def bag_info(self) -> dict:
        """The ``rosbag2_bagfile_information`` mapping (metadata.yaml version 9)."""
        start = self._start or 0
        duration = (self._end - self._start) if self._start is not None else 0
        return {
            "version": 9,
            "storage_identifier": "mcap",
            "duration": {"nanoseconds": duration},
            "starting_time": {"nanoseconds_since_epoch": start},
            "message_count": self._count,
            "topics_with_message_count": [
                {
                    "topic_metadata": {
                        "name": name,
                        "type": t["type"],
                        "serialization_format": "cdr",
                        "offered_qos_profiles": t["qos"],
                        "type_description_hash": t["hash"],
                    },
                    "message_count": t["count"],
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
                    "message_count": self._count,
                }
            ],
            "custom_data": None,
            "ros_distro": self.ros_distro,
        }

    def close(self) -> None:
        """Finish the MCAP file (summary, statistics, indexes) and write metadata.yaml."""
        if self._closed:
            return
        info = self.bag_info()
        self._w.add_metadata("rosbag2", {"serialized_metadata": yaml.safe_dump(info, sort_keys=False)})
        self._w.finish()
        self._stream.close()
        self._closed = True
        text = yaml.safe_dump({"rosbag2_bagfile_information": info}, sort_keys=False)
        tmp = self.path / "metadata.yaml.tmp"
        tmp.write_text(text)
        tmp.replace(self.path / "metadata.yaml")

    def __enter__(self) -> BagWriter:
        return self

    def __exit__(self, *exc) -> None:
        self.close()
