"""Chunk-by-chunk reading of MCAP bags: each chunk is decompressed, decoded and dropped.

:func:`stream_topics` hands the messages of each chunk to a callback as a small
:class:`~friction_ros.core.bag.contents.TopicData`, so reading an hour-long bag holds one chunk
(about 1 MB) at a time instead of the whole decompressed bag (:func:`~friction_ros.core.bag.reader.read_bag`).
Only well-formed files are streamed: a file without summary or message indexes, a truncated or
corrupt chunk raises :class:`NotStreamable`, and the caller reads the bag the full way, which
recovers what it can and says what was lost.
"""

from __future__ import annotations

import os
import struct
import zlib
from collections.abc import Callable, Iterable

import numpy as np

from .contents import TopicData, TopicInfo
from .errors import BagError
from .mcap_index import index_matches
from .mcap_records import RecordError
from .mcap_scan import MAGIC, McapScan
from .mcap_summary import Summary, parse_summary
from .msgdef import normalize_type
from .qos import parse_qos

_U64 = struct.Struct("<Q")
_OPHDR = struct.Struct("<BQ")


class NotStreamable(Exception):
    """The file is not a complete, indexed MCAP file: read it with ``read_bag`` instead."""


def _gather(buf: np.ndarray, pos: np.ndarray, dtype: str) -> np.ndarray:
    idx = pos[:, None] + np.arange(8)
    return np.ascontiguousarray(buf[idx]).view(dtype)[:, 0].astype(np.int64)


class _Scan(McapScan):
    """McapScan's record parsers over a file read sequentially (no whole-file buffer)."""

    def __init__(self, path):  # noqa: D107 - the parent's __init__ reads the whole file: not called
        self.path = path
        self.schemas, self.channels, self.metadata = {}, {}, {}
        self.segments, self.locs, self.warnings, self.problems = [], {}, [], []
        self.truncated = False
        self.expected = None
        self.profile = ""
        self._unsupported, self._loose = [], []
        self._chunks_seen = False
        self._last_chunk = self._last_resync = 8
        self._chunk_index = {}
        self._start_time = None

    def _summary(self, summary: bytes, start: int) -> None:
        """Schemas and channels of an intact summary section (``start``: its offset in the file)."""
        out = Summary(data_end=start)
        parse_summary(summary, 0, len(summary), out, base=start)
        self.schemas.update(out.schemas)
        self.channels.update(out.channels)

    def chunks(self):
        """Yield (decompressed chunk as uint8 array, {channel id: record offsets}) in file order."""
        with open(self.path, "rb") as f:
            size = os.fstat(f.fileno()).st_size
            if f.read(8) != MAGIC:
                raise NotStreamable("damaged magic bytes")
            if size < 8 + 37 + 17:
                raise NotStreamable("too short")
            f.seek(size - 37)
            foot = f.read(37)
            (start,) = _U64.unpack_from(foot, 9)
            if foot[-8:] != MAGIC or foot[0] != 0x02 or not 0 < start < size - 37:
                raise NotStreamable("no summary")
            f.seek(start)
            summary = f.read(size - 37 - start)
            (crc,) = struct.unpack_from("<I", foot, 25)  # over the summary and the footer up to the CRC
            if crc and zlib.crc32(summary + foot[:25]) != crc:
                raise NotStreamable("the summary fails its CRC check")
            try:
                self._summary(summary, start)
            except RecordError as exc:
                raise NotStreamable(f"damaged summary ({exc})") from None
            if not self.channels:
                raise NotStreamable("no channels in the summary")
            f.seek(8)
            op, ln = _OPHDR.unpack(f.read(9))
            f.seek(ln, os.SEEK_CUR)
            pending = None
            while True:
                head = f.read(9)
                if len(head) < 9:
                    raise NotStreamable("truncated")
                op, ln = _OPHDR.unpack(head)
                if op == 0x07 and pending is not None:
                    body = f.read(ln)
                    (ch,) = struct.unpack_from("<H", body, 0)
                    (nbytes,) = struct.unpack_from("<I", body, 2)
                    if len(body) < 6 + nbytes or nbytes % 16:
                        raise NotStreamable("damaged message index")
                    pending[1][ch] = np.frombuffer(body, "<u8", nbytes // 8, 6).reshape(-1, 2)
                    continue
                if pending is not None:
                    if not pending[1]:
                        raise NotStreamable("chunk without message index")
                    if not index_matches(pending[0].tobytes(), pending[1]):
                        raise NotStreamable("a message index does not match its chunk")
                    yield pending[0], {c: e[:, 1].astype(np.int64) for c, e in pending[1].items()}
                    pending = None
                if op in (0x0F, 0x02):
                    return
                if op == 0x05:
                    raise NotStreamable("message outside a chunk")
                if op == 0x06:
                    body = f.read(ln)
                    if len(body) < ln:
                        raise NotStreamable("truncated chunk")
                    seg, _problem = self._chunk(memoryview(body), 0, ln)
                    if seg is None:
                        raise NotStreamable("corrupt chunk")
                    buf = np.frombuffer(self.segments[seg], np.uint8)
                    self.segments[seg] = b""
                    pending = (buf, {})
                else:
                    f.seek(ln, os.SEEK_CUR)


def _topic_info(scan: _Scan, cid: int) -> tuple[TopicInfo, tuple]:
    topic, sid, enc, meta = scan.channels[cid]
    schema = scan.schemas.get(sid)
    if schema is None or enc != "cdr":
        raise NotStreamable(f"topic {topic}: no schema or not cdr")
    name = normalize_type(schema[0]) if "/" in schema[0] else schema[0]
    try:
        qos = parse_qos(meta.get("offered_qos_profiles", ""))
    except BagError:
        qos = []
    info = TopicInfo(topic, name, 0, enc, schema[1], schema[2].decode("utf-8", "replace"), qos)
    return info, schema


def stream_topics(
    files: Iterable, wanted: dict[str, Callable[[TopicData], None]]
) -> tuple[set[str], list[str]]:
    """Call ``wanted[topic](data)`` for each chunk's messages of every wanted topic, file by file.

    Returns (all topics of the bag, warnings). Messages within one chunk are in log-time order; chunks
    in file order (the caller sorts when it needs to). NotStreamable when a file is not a complete,
    indexed MCAP file (nothing can be assumed about what was already delivered: start over).
    """
    from .cdr import decode_batch
    from .reader import _definitions

    topics: set[str] = set()
    warnings: list[str] = []
    for path in files:
        scan = _Scan(path)
        decoders: dict[int, tuple] = {}
        for buf, locs in scan.chunks():
            if not decoders:
                for cid, (topic, *_rest) in scan.channels.items():
                    if topic in wanted:
                        info, (name, enc, text) = _topic_info(scan, cid)
                        defs = _definitions(topic, name, enc, text)
                        decoders[cid] = (info, defs, normalize_type(name))
                if not decoders:
                    break
            for cid, offs in locs.items():
                if cid not in decoders or not len(offs):
                    continue
                info, defs, root = decoders[cid]
                if np.any(offs + 31 > buf.size):
                    raise NotStreamable("message index points outside its chunk")
                ln = _gather(buf, offs + 1, "<u8")
                log = _gather(buf, offs + 15, "<u8")
                pub = _gather(buf, offs + 23, "<u8")
                order = np.argsort(log, kind="stable")
                start, dlen = (offs + 31)[order], (ln - 22)[order]
                fields = decode_batch(defs, root, buf, start, dlen)
                wanted[info.name](TopicData(info, log[order], pub[order], fields))
        topics |= {c[0] for c in scan.channels.values()}
        warnings += scan.warnings
    return topics, warnings
