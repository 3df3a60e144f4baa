"""The footer and summary section of an MCAP file, used only when they are intact.

The summary repeats the schemas and channels, holds the statistics (messages per channel) and the
chunk index (where every chunk starts). Reading takes the messages from the data section in every
case; the summary tells how many messages the file should hold (so a damaged chunk's loss can be
counted) and where the next chunk starts after a damaged record. A footer or summary that fails
its CRC, points outside the file or does not parse is ignored (the file is then read by a linear
scan of its records) and the reason is returned.
"""

from __future__ import annotations

import zlib
from dataclasses import dataclass, field

from .mcap_records import (
    CHANNEL,
    CHUNK_INDEX,
    FOOTER,
    MAGIC,
    OPHDR,
    SCHEMA,
    STATISTICS,
    RecordError,
    read_channel,
    read_id_counts,
    read_schema,
    read_str,
    unpack,
)

#: footer record (opcode, length, summary start, summary offset start, CRC) + closing magic
FOOTER_SIZE = 9 + 20 + 8


@dataclass
class Summary:
    """What an intact summary says about the file."""

    data_end: int  # first byte after the data section (summary start, or the footer without summary)
    schemas: dict[int, tuple[str, str, bytes]] = field(default_factory=dict)
    channels: dict[int, tuple[str, int, str, dict]] = field(default_factory=dict)
    counts: dict[int, int] | None = None  # messages per channel id (statistics record)
    total: int | None = None  # message count of the statistics record
    start_time: int | None = None  # log time of the first message [ns] (statistics record)
    #: chunk start -> (length, channel ids, log time of its first and of its last message [ns])
    chunks: dict[int, tuple[int, list[int], int, int]] = field(default_factory=dict)


def has_footer(data: bytes) -> bool:
    """The file ends with a footer record and the closing magic (it was finished, maybe damaged since)."""
    n = len(data)
    return n >= 8 + 9 + FOOTER_SIZE and data[-8:] == MAGIC and data[-FOOTER_SIZE] == FOOTER


def read_summary(data: bytes) -> tuple[Summary | None, str | None]:
    """(summary, None) when footer and summary are intact; (None, why) when they are damaged;
    (None, None) when the file has no footer (a recording cut off: the caller reports truncation)."""
    if not has_footer(data):
        return None, None
    n = len(data)
    foot = n - FOOTER_SIZE
    _, ln = OPHDR.unpack_from(data, foot)
    start, offsets_start, crc = unpack("<QQI", data, foot + 9)
    if ln != 20:
        return None, f"the footer record at byte {foot} is damaged (length {ln}, expected 20)"
    if start and not 8 < start <= foot:
        return None, f"the footer points to a summary at byte {start}, outside the file"
    if crc and zlib.crc32(data[start or foot : n - 12]) != crc:
        return None, "the summary section or footer fails its CRC check"
    if offsets_start and not start <= offsets_start <= foot:
        return None, f"the footer points to summary offsets at byte {offsets_start}, outside the summary"
    out = Summary(data_end=start or foot)
    if not start:
        return out, None
    try:
        parse_summary(data, start, offsets_start or foot, out)
    except RecordError as exc:
        return None, f"the summary section is damaged ({exc})"
    if out.counts is not None and out.total is not None and sum(out.counts.values()) != out.total:
        return None, "the summary statistics disagree with themselves (per-channel counts vs total)"
    return out, None


def parse_summary(data: bytes, pos: int, end: int, out: Summary, base: int = 0) -> None:
    """The summary records in ``data[pos:end]`` into ``out``. ``base``: the file offset of ``data[0]``
    (a summary section read on its own has ``base`` = its start in the file: byte numbers in errors
    and the chunk index's bound ``out.data_end`` are the file's)."""
    while pos < end:
        op, ln = unpack(OPHDR, data, pos, end)
        body = pos + 9
        stop = body + ln
        if stop > end:
            raise RecordError(f"record at byte {base + pos} runs past the summary's end")
        if op == SCHEMA:
            sid, schema = read_schema(data, body, stop)
            out.schemas[sid] = schema
        elif op == CHANNEL:
            cid, channel = read_channel(data, body, stop)
            out.channels[cid] = channel
        elif op == STATISTICS:
            (out.total,) = unpack("<Q", data, body, stop)
            (out.start_time,) = unpack("<Q", data, body + 26, stop)
            out.counts, _ = read_id_counts(data, body + 42, stop)
        elif op == CHUNK_INDEX:
            t0, t1, cstart, clen = unpack("<QQQQ", data, body, stop)
            channels, p = read_id_counts(data, body + 32, stop)
            _, p = read_str(data, p + 8, stop)  # message index length, compression
            unpack("<QQ", data, p, stop)  # compressed and uncompressed size
            if not 8 < cstart or cstart + clen > out.data_end:
                raise RecordError(f"chunk index points to byte {cstart}, outside the data section")
            out.chunks[cstart] = (clen, sorted(channels), t0, t1)
        pos = stop
