"""Finishing an MCAP file whose writing failed (disk full): summary and footer for what is on disk.

When a write fails part-way, the file ends in a partial record and the writer's own bookkeeping
counts messages that never reached the disk. :func:`finish_cut_short` instead trusts only the file:
it cuts it back to ``good`` (the end of the last write that completed: a record boundary), walks its
records (header fields only, chunk bodies are skipped, so a large file costs a few reads per chunk)
and appends what the MCAP specification puts after the data section, built from what it found:

    DataEnd | Schema* Channel* Statistics ChunkIndex* MetadataIndex* | SummaryOffset* | Footer | magic

(statistics and chunk indexes from the chunk records and the message index records after them;
schemas and channels from the caller, who registered them). If even that does not fit (no space
freed), the last chunk is dropped and the tail tried again, down to no chunk at all, so the file
always ends as a complete MCAP file. Reference: MCAP specification, https://mcap.dev/spec.
"""

from __future__ import annotations

import os
import struct
import zlib
from dataclasses import dataclass, field

from mcap.data_stream import RecordBuilder
from mcap.records import (
    Channel,
    ChunkIndex,
    DataEnd,
    Footer,
    MetadataIndex,
    Schema,
    Statistics,
    SummaryOffset,
)

from .mcap_records import CHUNK, MAGIC, MESSAGE_INDEX, METADATA, OPHDR

_CHUNK_HEAD = struct.Struct("<QQQII")  # start time, end time, uncompressed size, crc, compression length
_MSG_INDEX_HEAD = struct.Struct("<HI")  # channel id, records length (16 bytes per message)


@dataclass
class Found:
    """What a walk of the data section found: chunk indexes, messages per channel, metadata records."""

    chunks: list[ChunkIndex] = field(default_factory=list)
    chunk_counts: list[dict[int, int]] = field(default_factory=list)  # messages per channel, per chunk
    metadata: list[MetadataIndex] = field(default_factory=list)

    def counts(self) -> dict[int, int]:
        out: dict[int, int] = {}
        for c in self.chunk_counts:
            for k, n in c.items():
                out[k] = out.get(k, 0) + n
        return out

    def span(self) -> tuple[int, int]:
        """(first, last) message log time [ns]; (0, 0) without messages."""
        if not self.chunks:
            return 0, 0
        return min(c.message_start_time for c in self.chunks), max(c.message_end_time for c in self.chunks)


def walk(fd: int, start: int, end: int) -> Found:
    """Records of the data section in [start, end) (a record boundary): chunks and their indexes."""
    found = Found()
    pos = start
    while pos + OPHDR.size <= end:
        op, length = OPHDR.unpack(os.pread(fd, OPHDR.size, pos))
        body = pos + OPHDR.size
        if body + length > end:
            break
        if op == CHUNK:
            head = os.pread(fd, _CHUNK_HEAD.size, body)
            t0, t1, usize, _crc, n = _CHUNK_HEAD.unpack(head)
            comp = os.pread(fd, n, body + _CHUNK_HEAD.size).decode()
            (records,) = struct.unpack("<Q", os.pread(fd, 8, body + _CHUNK_HEAD.size + n))
            found.chunks.append(
                ChunkIndex(
                    message_start_time=t0,
                    message_end_time=t1,
                    chunk_start_offset=pos,
                    chunk_length=OPHDR.size + length,
                    message_index_offsets={},
                    message_index_length=0,
                    compression=comp,
                    compressed_size=records,
                    uncompressed_size=usize,
                )
            )
            found.chunk_counts.append({})
        elif op == MESSAGE_INDEX and found.chunks:
            channel, n = _MSG_INDEX_HEAD.unpack(os.pread(fd, _MSG_INDEX_HEAD.size, body))
            found.chunks[-1].message_index_offsets[channel] = pos
            found.chunks[-1].message_index_length += OPHDR.size + length
            found.chunk_counts[-1][channel] = found.chunk_counts[-1].get(channel, 0) + n // 16
        elif op == METADATA:
            (n,) = struct.unpack("<I", os.pread(fd, 4, body))
            name = os.pread(fd, n, body + 4).decode("utf-8", "replace")
            found.metadata.append(MetadataIndex(offset=pos, length=OPHDR.size + length, name=name))
        pos = body + length
    return found


def tail(found: Found, summary_start: int, schemas: list[Schema], channels: list[Channel]) -> bytes:
    """DataEnd, summary, summary offsets, footer and magic for a data section ending at ``summary_start``
    minus the DataEnd record (the layout ``mcap.writer.Writer.finish`` writes)."""
    b = RecordBuilder()
    DataEnd(0).write(b)  # 0: the data section CRC is not given (allowed by the specification)
    head = b.end()
    start = summary_start + len(head)
    s = RecordBuilder()
    counts = found.counts()
    t0, t1 = found.span()
    stats = Statistics(
        message_count=sum(counts.values()),
        schema_count=len(schemas),
        channel_count=len(channels),
        attachment_count=0,
        metadata_count=len(found.metadata),
        chunk_count=len(found.chunks),
        message_start_time=t0,
        message_end_time=t1,
        channel_message_counts=counts,
    )
    offsets = []
    for opcode, records in (
        (0x03, schemas),
        (0x04, channels),
        (0x0B, [stats]),
        (0x08, found.chunks),
        (0x0D, found.metadata),
    ):
        g = s.count
        for r in records:
            r.write(s)
        offsets.append(SummaryOffset(group_opcode=opcode, group_start=start + g, group_length=s.count - g))
    offset_start = start + s.count
    for o in offsets:
        o.write(s)
    summary = s.end()
    crc = zlib.crc32(summary)
    crc = zlib.crc32(struct.pack("<BQQQ", 0x02, 8 + 8 + 4, start, offset_start), crc)
    f = RecordBuilder()
    Footer(summary_start=start, summary_offset_start=offset_start, summary_crc=crc).write(f)
    return head + summary + f.end() + MAGIC


def finish_cut_short(
    path, good: int, head: bytes, schemas: list[Schema], channels: list[Channel], retry: tuple[int, ...]
) -> Found:
    """Cut the file at ``path`` back to ``good`` and append the summary (see the module docstring).

    ``head`` is the magic and header record (rewritten when not even they reached the disk). An
    OSError whose errno is in ``retry`` (disk full) drops the last chunk and tries again; returns
    what the finished file holds.
    """
    fd = os.open(path, os.O_RDWR)
    try:
        if good < len(head):
            os.ftruncate(fd, 0)
            _pwrite_all(fd, head, 0)
            good = len(head)
        found = walk(fd, len(head), good)
        while True:
            os.ftruncate(fd, good)
            try:
                _pwrite_all(fd, tail(found, good, schemas, channels), good)
                return found
            except OSError as exc:
                if exc.errno not in retry or not found.chunks:
                    raise
            good = found.chunks[-1].chunk_start_offset  # no room even for the summary: drop a chunk
            found.chunks.pop()
            found.chunk_counts.pop()
            found.metadata = [m for m in found.metadata if m.offset < good]
    finally:
        os.close(fd)


def _pwrite_all(fd: int, data: bytes, pos: int) -> None:
    view = memoryview(data)
    while len(view):
        n = os.pwrite(fd, view, pos)
        view, pos = view[n:], pos + n
