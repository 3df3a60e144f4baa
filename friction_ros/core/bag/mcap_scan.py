"""Low-level scan of one MCAP file: schemas, channels, metadata and where each message lies.

Chunks are decompressed (zstd, lz4 or none) and their message records located; a file cut off
before its summary is scanned up to the last complete record (``truncated``, ``warnings``).
"""

from __future__ import annotations

import struct
import zlib
from pathlib import Path

import numpy as np

from .errors import BagError, NotMcapError, TruncatedBagError, UnsupportedBagError

MAGIC = b"\x89MCAP0\r\n"
_U64 = struct.Struct("<Q")
_OPHDR = struct.Struct("<BQ")


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


class McapScan:
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
