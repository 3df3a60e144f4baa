"""Low-level scan of one MCAP file: schemas, channels, metadata and where each message lies.

The data section is read record by record (a linear scan); chunks are decompressed (zstd, lz4 or
none), checked against their CRC and their message records located through the message indexes
that follow them (checked against the chunk) or, when those are missing or damaged, by a scan of
the chunk's records. An intact summary (:mod:`.mcap_summary`) gives the expected message counts and
the chunk starts. Damage never stops the scan: a chunk that fails its CRC or cannot be read is
skipped, a record whose length is impossible is stepped over to the next chunk (found through the
chunk index, else by searching for a well-formed chunk record), and each is recorded as a
:class:`~.damage.Problem`. A file cut off before its summary is scanned up to the last complete
record (``truncated``, ``warnings``).
"""

from __future__ import annotations

import zlib
from pathlib import Path

import numpy as np

from .damage import Problem
from .errors import BagError, NotMcapError, TruncatedBagError, UnsupportedBagError
from .mcap_index import index_matches
from .mcap_records import (
    CHANNEL,
    CHUNK,
    COMPRESSIONS,
    DATA_END,
    FOOTER,
    HEADER,
    KNOWN_OPCODES,
    MAGIC,
    MESSAGE,
    MESSAGE_INDEX,
    METADATA,
    OPHDR,
    SCHEMA,
    U64,
    RecordError,
    read_channel,
    read_map,
    read_schema,
    read_str,
    unpack,
)
from .mcap_summary import has_footer, read_summary

#: a record of the data section holds at least its opcode and length; a chunk at least its fixed fields
_CHUNK_MIN = 8 + 8 + 8 + 4 + 4 + 8


class McapScan:
    """Schemas, channels, metadata, message locations and damage of one MCAP file."""

    def __init__(self, path: Path):
        self.path = path
        self.schemas: dict[int, tuple[str, str, bytes]] = {}
        self.channels: dict[int, tuple[str, int, str, dict]] = {}
        self.metadata: dict[str, dict[str, str]] = {}
        self.segments: list[bytes] = []
        self.locs: dict[int, list[tuple[int, np.ndarray]]] = {}
        self.truncated = self.cut = False  # not finished (no summary/footer); cut inside a record
        self.warnings: list[str] = []
        self.problems: list[Problem] = []
        self.expected: dict[int, int] | None = None  # messages per channel (intact summary statistics)
        self.profile = ""
        self._unsupported: list[str] = []
        self._loose: list[int] = []  # message records outside chunks
        self._chunks_seen = False
        self._last_chunk = 8  # start of the last chunk record read (resynchronisation starts after it)
        self._last_resync = 8  # where the last resynchronisation went
        self._chunk_index: dict[int, tuple[int, list[int], int, int]] = {}  # of an intact summary
        self._start_time: int | None = None  # log time of the file's first message [ns]
        try:
            data = path.read_bytes()
        except OSError as exc:
            raise BagError(f"{path}: cannot read: {exc.strerror}") from None
        self._check_magic(data)
        self._scan(data)

    def found(self) -> dict[int, int]:
        """Messages read per channel id."""
        return {c: sum(len(o) for _, o in v) for c, v in self.locs.items()}

    def _check_magic(self, data: bytes) -> None:
        p = self.path
        if not data:
            raise NotMcapError(f"{p}: file is empty (0 bytes): not an MCAP bag")
        if data[:8] == MAGIC:
            return
        if has_footer(data):  # an MCAP file whose first bytes were damaged: read what follows them
            self._problem(0, "the magic bytes at the start of the file are damaged", False)
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

    def _problem(self, offset: int | None, text: str, loses: bool = True) -> Problem:
        p = Problem(offset, text, loses)
        self.problems.append(p)
        return p

    # ------------------------------------------------------------------------------ data section
    def _scan(self, data: bytes) -> None:
        n = len(data)
        if n < 17:
            raise TruncatedBagError(f"{self.path}: MCAP header record is truncated (file has only {n} bytes)")
        summary, why = read_summary(data)
        footer = has_footer(data)
        if why:
            self._problem(n - 37, f"{why}: the file was read by a linear scan of its records", False)
        chunk_starts: list[int] = []
        if summary is not None:
            self._chunk_index = summary.chunks
            self._start_time = summary.start_time
            self.schemas.update(summary.schemas)
            self.channels.update(summary.channels)
            self.expected = summary.counts
            chunk_starts = sorted(summary.chunks)
        end = summary.data_end if summary is not None else n
        pos = self._header(data, end, footer)
        if pos is None:
            pos = self._resync(data, 8, end, chunk_starts)
            if pos is None:
                pos = end
        pending: tuple[int, dict[int, np.ndarray], int] | None = None
        orphan: Problem | None = None  # damaged part whose message indexes may follow
        finished = False
        view = memoryview(data)
        while pos < end:
            op, ln, bad = _frame(data, pos, end)
            body = pos + 9
            if op == CHUNK:
                ln, bad = self._chunk_length(data, pos, ln, bad, end)
            if bad:
                nxt = self._resync(data, pos, end, chunk_starts)
                if nxt is None and not footer:
                    if pending is not None:  # its message indexes may be cut off: read it by a scan
                        pending = (pending[0], {}, pending[2])
                    break  # a cut-off recording: reported as truncated below
                if pending is not None:
                    pending[1][-1] = np.zeros((0, 2), np.int64)  # its message indexes may be incomplete
                    self._finish_chunk(*pending)
                    pending = None
                what = (
                    "the rest was skipped" if nxt is None else f"reading resumed at the chunk at byte {nxt}"
                )
                orphan = self._problem(pos, f"{bad}: {what}")
                if op in (MESSAGE_INDEX, METADATA, SCHEMA, CHANNEL):
                    orphan.counts = {}  # no messages in this record; a skipped chunk is counted by its indexes
                if nxt is None:
                    finished = True
                    break
                pos = nxt
                continue
            if op == MESSAGE_INDEX:
                if pending is None and orphan is None:
                    orphan = self._problem(
                        pos,
                        f"message indexes at byte {pos} follow no readable chunk: the chunk before them is lost",
                    )
                self._message_index(data, body, ln, pending, orphan)
                pos = body + ln
                continue
            if pending is not None:
                self._finish_chunk(*pending)
                pending = None
            orphan = None
            if op == CHUNK:
                self._last_chunk = pos
                self._chunks_seen = True
                seg, orphan = self._chunk(view, body, ln)
                if seg is not None:
                    pending = (seg, {}, pos)
                elif not _record_follows(data, body + ln, end):  # its length is damaged too
                    nxt = self._resync(data, pos, end, chunk_starts)
                    if nxt is None:
                        finished = footer
                        break
                    pos = nxt
                    continue
            elif op == MESSAGE:
                self._unchunked(data, pos, ln)
            elif op in (SCHEMA, CHANNEL, METADATA):
                self._plain(data, op, body, body + ln)
            elif op == DATA_END or op == FOOTER:
                if summary is None or body + ln == end or op == FOOTER:
                    finished = True
                    break
                self._problem(pos, f"a misplaced data-end record at byte {pos} was skipped", False)
            elif op not in KNOWN_OPCODES and op < 0x80:
                orphan = self._unknown_record(orphan_at=pos, op=op, stop=body + ln)
            pos = body + ln
        if pending is not None:
            self._finish_chunk(*pending)
        self._add_unchunked(data, bool(chunk_starts) or self._chunks_seen)
        if summary is not None:
            finished = True
        self._close(pos, n, finished, footer)

    def _close(self, pos: int, n: int, finished: bool, footer: bool) -> None:
        if not finished:  # cut inside a record, or ended after a complete one without being closed
            self.truncated, self.cut = True, pos < n
            self.warnings.append(
                f"{self.path}: file is truncated at byte {pos} of {n} (recording was killed?): recovered "
                "all complete chunks; messages of the last, incomplete chunk are lost"
                if self.cut
                else f"{self.path}: file was not closed (no summary or footer after its last record: the "
                "recording was killed or is still running): every message in it was read"
            )
        elif not footer:
            self.truncated = True
            self.warnings.append(
                f"{self.path}: file is truncated or damaged after the data section (no valid summary/footer): "
                "all messages recovered"
            )
        if self._unsupported and not self.segments:
            raise UnsupportedBagError(f"{self.path}: {self._unsupported[0]}")
        for p in self.problems:
            if p.loses and p.counts is not None and not p.counts and self.expected is None:
                p.loses = False  # an unknown record not followed by message indexes: no chunk was lost
        self._say_when()
        known = set(self.channels)
        orphans = {c: k for c, k in self.found().items() if c not in known}
        if orphans:
            p = self._problem(None, "messages of channels whose definition was lost cannot be read")
            p.counts = orphans

    def _say_when(self) -> None:
        """Add to each lost chunk's problem when its messages were logged, in s after the file's start."""
        spans = [p for p in self.problems if p.span]
        if not spans:
            return
        start = self._start_time if self._start_time is not None else min(p.span[0] for p in spans)
        for p in spans:
            a, b = ((t - start) * 1e-9 for t in p.span)
            if 0 <= a <= b < 1e7:  # plausible (the chunk header's times are not covered by its CRC)
                p.text += f" (messages logged {a:.3f} s to {b:.3f} s after the start of the file)"

    def _header(self, data: bytes, end: int, footer: bool) -> int | None:
        op, ln = OPHDR.unpack_from(data, 8)
        if op == HEADER and 17 + ln <= end:
            try:
                self.profile, _ = read_str(data, 17, 17 + ln)
            except RecordError:
                self._problem(8, "the header record is damaged", False)
            if self.profile not in ("ros2", ""):
                self.warnings.append(
                    f"{self.path}: MCAP profile {self.profile!r} is not 'ros2': read as ros2 (cdr messages)"
                )
            return 17 + ln
        if not footer:
            raise TruncatedBagError(
                f"{self.path}: MCAP header record is truncated or missing (not a complete MCAP file)"
            )
        self._problem(8, "the header record is damaged", False)
        return None

    def _unknown_record(self, orphan_at: int, op: int, stop: int) -> Problem:
        """A record of a type the specification does not define (a damaged type byte, or zeroed bytes):
        skipped; a run of them (e.g. a zeroed block) is one problem."""
        last = self.problems[-1] if self.problems else None
        if last is not None and last.end == orphan_at:
            last.text = f"records of unknown type from byte {last.offset} to {stop} were skipped"
        else:
            last = self._problem(
                orphan_at, f"a record of unknown type 0x{op:02x} at byte {orphan_at} was skipped"
            )
            last.counts = {}
        last.end = stop
        return last

    def _chunk_length(self, data: bytes, pos: int, ln: int, bad: str, end: int) -> tuple[int, str]:
        """(length, framing problem) of the chunk record at ``pos``: when its length field disagrees with
        the lengths inside it and those end where the next record starts, the length field was damaged."""
        inner = _chunk_inner_end(data, pos, end)
        if inner is None or inner == pos + 9 + ln or not _record_follows(data, inner, end):
            return ln, bad
        self._problem(
            pos,
            f"the length of the chunk at byte {pos} is damaged: its end was found from its contents",
            False,
        )
        return inner - pos - 9, ""

    def _resync(self, data: bytes, pos: int, end: int, chunk_starts: list[int]) -> int | None:
        """Start of the next chunk after the last chunk read (a damaged length may have stepped over
        chunks before ``pos``): from the chunk index, else the next well-formed chunk record."""
        after = max(self._last_chunk, self._last_resync)  # strictly forward: the scan always ends
        nxt = self._next_chunk(data, after, end, chunk_starts)
        if nxt is not None:
            self._last_resync = nxt
        return nxt

    @staticmethod
    def _next_chunk(data: bytes, after: int, end: int, chunk_starts: list[int]) -> int | None:
        if chunk_starts:
            return next((s for s in chunk_starts if s > after), None)
        p = after
        while True:
            p = data.find(b"\x06", p + 1, end)
            if p < 0:
                return None
            if _chunk_framed(data, p, end):
                return p

    # ------------------------------------------------------------------------------ records
    def _plain(self, data: bytes, op: int, body: int, stop: int) -> None:
        try:
            if op == SCHEMA:
                sid, schema = read_schema(data, body, stop)
                self.schemas.setdefault(sid, schema)
            elif op == CHANNEL:
                cid, channel = read_channel(data, body, stop)
                self.channels.setdefault(cid, channel)
            else:
                name, p2 = read_str(data, body, stop)
                self.metadata[name], _ = read_map(data, p2, stop)
        except RecordError as exc:
            kind = {SCHEMA: "schema", CHANNEL: "channel", METADATA: "metadata"}[op]
            self._problem(body - 9, f"a damaged {kind} record at byte {body - 9} was skipped ({exc})", False)

    def _unchunked(self, data: bytes, pos: int, ln: int) -> None:
        if ln < 22:
            self._problem(pos, f"a damaged message record at byte {pos} was skipped").counts = {}
        else:
            self._loose.append(pos)

    def _add_unchunked(self, data: bytes, chunked: bool) -> None:
        """Messages outside chunks: read in a file without chunks; in a chunked file (every ROS 2 bag)
        such a record is a damaged one (a message index or chunk whose type byte changed) and skipped."""
        if not self._loose:
            return
        if chunked:
            for pos in self._loose:
                self._problem(
                    pos, f"a message record outside the chunks at byte {pos} (damaged?) was skipped", False
                )
            return
        self.segments.insert(0, data)
        self.locs = {c: [(s + 1, o) for s, o in v] for c, v in self.locs.items()}
        offs = np.array(self._loose, dtype=np.int64)
        chans = np.frombuffer(data, np.uint8)[offs + 9] | (
            np.frombuffer(data, np.uint8)[offs + 10].astype(np.int64) << 8
        )
        for ch in np.unique(chans):
            self.locs.setdefault(int(ch), []).append((0, offs[chans == ch]))

    def _message_index(self, data, body: int, ln: int, pending, orphan: Problem | None) -> None:
        try:
            ch, nbytes = unpack("<HI", data, body, body + ln)
            if nbytes % 16 or 6 + nbytes != ln:
                raise RecordError(f"{nbytes} bytes of entries in a record of {ln}")
        except RecordError:
            if pending is not None:
                pending[1][-1] = np.zeros((0, 2), np.int64)  # marks the index as damaged
            return
        entries = np.frombuffer(data, "<u8", nbytes // 8, body + 6).reshape(-1, 2).astype(np.int64)
        if pending is not None:
            pending[1][ch] = entries
        else:
            orphan.add_index(ch, len(entries))

    def _chunk(self, view: memoryview, body: int, ln: int) -> tuple[int | None, Problem | None]:
        at = body - 9
        stop = body + ln
        span = self._chunk_index[at][2:] if at in self._chunk_index else None
        try:
            t0, t1, usize, crc = unpack("<QQQI", view, body, stop)
            span = span or (t0, t1)
            comp, p = read_str(view, body + 28, stop)
            (rlen,) = unpack(U64, view, p, stop)
            if p + 8 + rlen > stop:
                raise RecordError(f"its records ({rlen} bytes) run past its end")
            raw = view[p + 8 : p + 8 + rlen]
            if comp not in COMPRESSIONS:
                self._unsupported.append(f"chunk compression {comp!r} is not supported (zstd, lz4, none)")
                raise RecordError(f"unknown compression {comp!r}")
            out = _decompress(comp, raw, usize)
        except Exception as exc:  # noqa: BLE001 - damaged fields or compressed data
            why = str(exc).strip() or type(exc).__name__
            return None, self._lost_chunk(at, f"cannot be read ({why})", span)
        if crc and zlib.crc32(out) != crc:
            return None, self._lost_chunk(at, "fails its CRC check", span)
        if not crc and len(out) != usize:
            return None, self._lost_chunk(at, "has the wrong size", span)
        if self._start_time is None or (not self._chunk_index and t0 < self._start_time):
            self._start_time = t0  # no statistics: the earliest readable chunk
        self.segments.append(out)
        return len(self.segments) - 1, None

    def _lost_chunk(self, at: int, why: str, span: tuple[int, int] | None) -> Problem:
        p = self._problem(at, f"a chunk at byte {at} {why}: skipped")
        p.span = span if span and span[0] <= span[1] else None
        return p

    def _finish_chunk(self, seg: int, index: dict[int, np.ndarray], at: int) -> None:
        buf = self.segments[seg]
        if index and index_matches(buf, index):
            if not set(index) <= set(self.channels):  # no summary: the definitions are in the chunks
                self._scan_chunk(seg, buf, definitions_only=True)
            for ch, entries in index.items():
                self.locs.setdefault(ch, []).append((seg, entries[:, 1].copy()))
            return
        if index:
            self._problem(
                at,
                f"the message index of the chunk at byte {at} is damaged: the chunk was read by a linear scan "
                "of its records",
                False,
            )
        self._scan_chunk(seg, buf)

    def _scan_chunk(self, seg: int, buf: bytes, definitions_only: bool = False) -> None:
        n = len(buf)
        pos = 0
        found: dict[int, list[int]] = {}
        while pos + 9 <= n:
            op, ln = OPHDR.unpack_from(buf, pos)
            if pos + 9 + ln > n:
                self._problem(
                    None, f"a chunk's records are damaged after {len(found)} messages: the rest was skipped"
                )
                break
            if op == MESSAGE and ln >= 22 and not definitions_only:
                found.setdefault(buf[pos + 9] | (buf[pos + 10] << 8), []).append(pos)
            elif op in (SCHEMA, CHANNEL):
                self._plain(buf, op, pos + 9, pos + 9 + ln)
            pos += 9 + ln
        for ch, offs in found.items():
            self.locs.setdefault(ch, []).append((seg, np.array(offs, dtype=np.int64)))


def _decompress(comp: str, raw, usize: int) -> bytes:
    if comp == "":
        return bytes(raw)
    if comp == "zstd":
        import zstandard

        # a damaged size field must not make the decompressor reserve gigabytes
        return zstandard.ZstdDecompressor().decompress(
            raw, max_output_size=min(usize, 256 * len(raw) + (1 << 20))
        )
    import lz4.frame

    return lz4.frame.decompress(raw)


def _frame(data: bytes, pos: int, end: int) -> tuple[int, int, str]:
    """(opcode, length, problem) of the record at ``pos``; the problem is "" when it fits before ``end``."""
    if pos + 9 > end:
        return -1, 0, f"the data ends inside a record at byte {pos}"
    op, ln = OPHDR.unpack_from(data, pos)
    return (
        op,
        ln,
        ""
        if pos + 9 + ln <= end
        else f"a record (type 0x{op:02x}) at byte {pos} runs past the end of the data",
    )


def _record_follows(data: bytes, p: int, end: int) -> bool:
    """A record of a known type that fits before ``end`` starts at ``p`` (or the data section ends there)."""
    if p == end:
        return True
    op, ln, bad = _frame(data, p, end)
    return not bad and op in KNOWN_OPCODES


def _chunk_inner_end(data: bytes, p: int, end: int) -> int | None:
    """Where the chunk record at ``p`` ends by the lengths inside it (None when they do not fit)."""
    body = p + 9
    try:
        comp, q = read_str(data, body + 28, end)
        (rlen,) = unpack(U64, data, q, end)
    except RecordError:
        return None
    stop = q + 8 + rlen
    return stop if comp in COMPRESSIONS and stop - body >= _CHUNK_MIN and stop <= end else None


def _chunk_framed(data: bytes, p: int, end: int) -> bool:
    """A chunk record starts at ``p``: its length equals the sum of its fields and it ends in the data."""
    if p + 9 + _CHUNK_MIN > end or data[p] != CHUNK:
        return False
    _, ln = OPHDR.unpack_from(data, p)
    return _chunk_inner_end(data, p, end) == p + 9 + ln
