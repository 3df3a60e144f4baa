"""Byte layouts of the MCAP records this package reads (schema, channel, metadata, strings, maps).

Every parser reads from a buffer that may be damaged: a length that runs past the buffer raises
:class:`RecordError` (never ``struct.error`` or ``IndexError``), so the scanner can say which record
is damaged and go on.
"""

from __future__ import annotations

import struct

MAGIC = b"\x89MCAP0\r\n"
U64 = struct.Struct("<Q")
OPHDR = struct.Struct("<BQ")

HEADER, FOOTER, SCHEMA, CHANNEL, MESSAGE, CHUNK, MESSAGE_INDEX = 0x01, 0x02, 0x03, 0x04, 0x05, 0x06, 0x07
CHUNK_INDEX, ATTACHMENT, ATTACHMENT_INDEX, STATISTICS, METADATA = 0x08, 0x09, 0x0A, 0x0B, 0x0C
METADATA_INDEX, SUMMARY_OFFSET, DATA_END = 0x0D, 0x0E, 0x0F
#: opcodes the MCAP specification defines; 0x80-0xFF are private records (skipped), the rest unknown
KNOWN_OPCODES = frozenset(range(0x01, 0x10))
#: chunk compressions of the MCAP specification
COMPRESSIONS = ("", "zstd", "lz4")


class RecordError(ValueError):
    """A record's fields run past its end: the record is damaged."""


def unpack(fmt: struct.Struct | str, buf, pos: int, end: int | None = None) -> tuple:
    """``struct.unpack_from`` that raises RecordError when the fields run past ``end`` (or the buffer)."""
    s = fmt if isinstance(fmt, struct.Struct) else struct.Struct(fmt)
    limit = len(buf) if end is None else min(end, len(buf))
    if pos < 0 or pos + s.size > limit:
        raise RecordError(f"fields at byte {pos} run past the end of the record")
    return s.unpack_from(buf, pos)


def read_bytes(buf, pos: int, end: int | None = None) -> tuple[bytes, int]:
    """A uint32-length-prefixed byte string and the position after it."""
    (n,) = unpack("<I", buf, pos, end)
    limit = len(buf) if end is None else min(end, len(buf))
    if pos + 4 + n > limit:
        raise RecordError(f"a string of {n} bytes at byte {pos} runs past the end of the record")
    return bytes(buf[pos + 4 : pos + 4 + n]), pos + 4 + n


def read_str(buf, pos: int, end: int | None = None) -> tuple[str, int]:
    raw, pos = read_bytes(buf, pos, end)
    return raw.decode("utf-8", "replace"), pos


def read_map(buf, pos: int, end: int | None = None) -> tuple[dict[str, str], int]:
    """A uint32-byte-length-prefixed map of strings and the position after it."""
    (total,) = unpack("<I", buf, pos, end)
    stop = pos + 4 + total
    limit = len(buf) if end is None else min(end, len(buf))
    if stop > limit:
        raise RecordError(f"a map of {total} bytes at byte {pos} runs past the end of the record")
    pos += 4
    out = {}
    while pos < stop:
        k, pos = read_str(buf, pos, stop)
        v, pos = read_str(buf, pos, stop)
        out[k] = v
    return out, stop


def read_schema(buf, pos: int, end: int) -> tuple[int, tuple[str, str, bytes]]:
    """(schema id, (name, encoding, definition bytes)) of a schema record body."""
    (sid,) = unpack("<H", buf, pos, end)
    name, pos = read_str(buf, pos + 2, end)
    enc, pos = read_str(buf, pos, end)
    text, _ = read_bytes(buf, pos, end)
    return sid, (name, enc, text)


def read_channel(buf, pos: int, end: int) -> tuple[int, tuple[str, int, str, dict]]:
    """(channel id, (topic, schema id, message encoding, metadata)) of a channel record body."""
    cid, sid = unpack("<HH", buf, pos, end)
    topic, pos = read_str(buf, pos + 4, end)
    enc, pos = read_str(buf, pos, end)
    meta, _ = read_map(buf, pos, end)
    return cid, (topic, sid, enc, meta)


def read_id_counts(buf, pos: int, end: int) -> tuple[dict[int, int], int]:
    """A uint32-byte-length-prefixed map uint16 -> uint64 (statistics, chunk index) and the position after it."""
    (total,) = unpack("<I", buf, pos, end)
    stop = pos + 4 + total
    if total % 10 or stop > end:
        raise RecordError(f"a map of {total} bytes at byte {pos} does not fit the record")
    out = {}
    for p in range(pos + 4, stop, 10):
        k, v = unpack("<HQ", buf, p, stop)
        out[k] = v
    return out, stop
