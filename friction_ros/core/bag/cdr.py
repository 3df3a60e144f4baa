"""CDR (de)serialisation of ROS 2 messages driven by parsed ``.msg`` definitions.

* :func:`decode` / :func:`encode`: one message <-> nested dict (generic, any type).
* :func:`decode_batch`: many payloads of one type -> columns ``{"dotted.field": np.ndarray}``. Messages
  with the same layout (same length, same sequence lengths and strings) are decoded together with numpy
  views on a template found by decoding one of them, so JointState-like topics decode at millions of
  messages per second; anything else falls back to the generic decoder per message.

Payloads carry the 4-byte RTPS encapsulation header: ``00 01`` little-endian CDR (XCDR1, what Fast DDS
and rosbag2 write), ``00 00`` big-endian, ``00 06``/``00 07`` plain XCDR2 (8-byte types aligned to 4).
Alignment is relative to the byte after the header; padding bytes are ignored (Fast DDS leaves them
uninitialised). Trailing bytes after the last field are ignored. The primitives (encapsulation
header, alignment, the writer :func:`encode` uses) are those of :mod:`friction_ros.core.wire.cdr`;
the fast per-message codecs of the nodes are in :mod:`friction_ros.core.wire.messages`.
"""

from __future__ import annotations

import struct
from collections.abc import Mapping

import numpy as np

from ..config import flatten
from ..wire.cdr import ORIGIN, Writer, encapsulation
from .errors import CdrError, SchemaError
from .msgdef import PRIMITIVES, STRINGS, MsgDef


class _Rec:
    """Layout of one decoded message: numeric leaves and the bytes that fix the layout."""

    __slots__ = ("numeric", "consts", "struct")

    def __init__(self) -> None:
        self.numeric: list[tuple[str, int, str, int, bool]] = []  # path, offset, dtype, count, is_array
        self.consts: list[tuple[str, object]] = []  # path, str / tuple of str (fixed within the layout)
        self.struct: list[tuple[int, int]] = []  # byte ranges [a, b) that must match the template


class _Cur:
    __slots__ = ("buf", "pos", "order", "maxalign", "rec")

    def __init__(self, buf, order: str, maxalign: int, rec: _Rec | None):
        self.buf = buf
        self.pos = ORIGIN
        self.order = order
        self.maxalign = maxalign
        self.rec = rec

    def align(self, n: int) -> None:
        a = n if n < self.maxalign else self.maxalign
        self.pos += (-(self.pos - ORIGIN)) % a

    def need(self, n: int, what: str) -> None:
        if self.pos + n > len(self.buf):
            raise CdrError(
                f"payload too short: {what} needs {n} byte(s) at offset {self.pos}, has {len(self.buf)}"
            )

    def u32(self, what: str) -> int:
        self.align(4)
        self.need(4, what)
        if self.rec is not None:
            self.rec.struct.append((self.pos, self.pos + 4))
        (v,) = struct.unpack_from(self.order + "I", self.buf, self.pos)
        self.pos += 4
        return v

    def string(self, what: str, wide: bool) -> str:
        n = self.u32(what)
        size = 2 if wide else 1
        self.need(n * size, what)
        raw = bytes(self.buf[self.pos : self.pos + n * size])
        if self.rec is not None:
            self.rec.struct.append((self.pos, self.pos + n * size))
        self.pos += n * size
        if wide:
            return raw.decode("utf-16-le" if self.order == "<" else "utf-16-be", "replace").rstrip("\0")
        return raw[:-1].decode("utf-8", "replace") if n else ""


def _header(data) -> tuple[str, int]:
    if len(data) < 4:
        raise CdrError(f"payload of {len(data)} byte(s) is shorter than the 4-byte CDR header")
    enc = encapsulation(data)
    if enc is None:
        raise CdrError(
            f"unsupported CDR encapsulation {bytes(data[:2]).hex()}: supported are 0000/0001 (CDR) and "
            "0006/0007 (plain XCDR2)"
        )
    return enc


def _decode_struct(defs: Mapping[str, MsgDef], tname: str, cur: _Cur, path: str) -> dict:
    try:
        md = defs[tname]
    except KeyError:
        raise SchemaError(f"definition of {tname} is missing from the schema") from None
    out: dict = {}
    if not md.fields:  # empty struct: one dummy uint8
        cur.need(1, f"{tname} (empty)")
        cur.pos += 1
        return out
    rec = cur.rec
    for f in md.fields:
        p = f"{path}{f.name}"
        if f.type in PRIMITIVES:
            dt, size = PRIMITIVES[f.type]
            if f.array is None:
                cur.align(size)
                cur.need(size, p)
                v = np.frombuffer(cur.buf, cur.order + dt, 1, cur.pos)[0].item()
                if rec is not None:
                    rec.numeric.append((p, cur.pos, cur.order + dt, 1, False))
                cur.pos += size
                out[f.name] = v
                continue
            n = f.length if f.array == "fixed" else cur.u32(f"length of {p}")
            if n:
                cur.align(size)
            cur.need(n * size, p)
            arr = np.frombuffer(cur.buf, cur.order + dt, n, cur.pos).copy()
            if rec is not None:
                rec.numeric.append((p, cur.pos, cur.order + dt, n, True))
            cur.pos += n * size
            out[f.name] = arr
        elif f.type in STRINGS:
            wide = f.type == "wstring"
            if f.array is None:
                out[f.name] = cur.string(p, wide)
                if rec is not None:
                    rec.consts.append((p, out[f.name]))
                continue
            n = f.length if f.array == "fixed" else cur.u32(f"length of {p}")
            out[f.name] = tuple(cur.string(p, wide) for _ in range(n))
            if rec is not None:
                rec.consts.append((p, out[f.name]))
        else:
            if f.array is None:
                out[f.name] = _decode_struct(defs, f.type, cur, p + ".")
            else:
                n = f.length if f.array == "fixed" else cur.u32(f"length of {p}")
                out[f.name] = [_decode_struct(defs, f.type, cur, p + ".") for _ in range(n)]
    return out


def decode(defs: Mapping[str, MsgDef], tname: str, data) -> dict:
    """Decode one CDR payload of type ``tname`` into a nested dict (arrays as numpy arrays)."""
    order, maxalign = _header(data)
    return _decode_struct(defs, tname, _Cur(data, order, maxalign, None), "")


def _vectorizable(defs: Mapping[str, MsgDef], tname: str) -> bool:
    for f in defs[tname].fields:
        if f.is_complex and (f.array is not None or not _vectorizable(defs, f.type)):
            return False
    return bool(defs[tname].fields)


class _Columns:
    """Collects per-group values and assembles one column per field in message order."""

    def __init__(self, n: int):
        self.n = n
        self.parts: dict[str, list[tuple[np.ndarray, object, bool]]] = {}

    def add(self, path: str, idx: np.ndarray, value, const: bool) -> None:
        self.parts.setdefault(path, []).append((idx, value, const))

    def finish(self) -> dict[str, np.ndarray]:
        cols: dict[str, np.ndarray] = {}
        for path, parts in self.parts.items():
            numeric = all(not c and isinstance(v, np.ndarray) for _, v, c in parts)
            shapes = {v.shape[1:] for _, v, c in parts} if numeric else set()
            if numeric and len(shapes) == 1:
                dtype = np.result_type(*[v.dtype for _, v, _ in parts])
                col = np.empty((self.n, *shapes.pop()), dtype=dtype.newbyteorder("="))
                for idx, v, _ in parts:
                    col[idx] = v
            else:
                col = np.empty(self.n, dtype=object)
                for idx, v, c in parts:
                    if c:
                        one = np.empty(1, dtype=object)
                        one[0] = v
                        col[idx] = one
                    else:
                        for j, i in enumerate(idx):
                            col[i] = v[j]
            cols[path] = col
        return cols


def decode_batch(
    defs: Mapping[str, MsgDef], tname: str, buf: np.ndarray, starts: np.ndarray, lengths: np.ndarray
) -> dict[str, np.ndarray]:
    """Decode payloads ``buf[starts[i] : starts[i] + lengths[i]]`` of type ``tname`` into columns.

    Numeric scalars -> shape (n,); numeric arrays of one length throughout -> (n, k), otherwise an object
    array of 1-D arrays; strings -> object array of str; string arrays -> object array of tuples; arrays of
    nested messages -> object array of lists of dicts. Nested fields are dotted (``header.stamp.sec``).
    """
    n = len(starts)
    cols = _Columns(n)
    if n == 0:
        return {}
    starts = np.asarray(starts, dtype=np.int64)
    lengths = np.asarray(lengths, dtype=np.int64)
    if not _vectorizable(defs, tname):
        for i in range(n):
            s = int(starts[i])
            _add_generic(cols, defs, tname, buf[s : s + int(lengths[i])], i)
        return cols.finish()
    templates = 0
    for length in np.unique(lengths):
        gidx = np.flatnonzero(lengths == length)
        # rows = payloads of this length; a sliding-window view avoids an (n, length) index matrix
        mat = np.lib.stride_tricks.sliding_window_view(buf, int(length))[starts[gidx]]
        remaining = np.arange(len(gidx))
        while len(remaining):
            r0 = remaining[0]
            if templates > 256:  # pathological variety: decode the rest one by one
                for r in remaining:
                    _add_generic(cols, defs, tname, mat[r], int(gidx[r]))
                break
            templates += 1
            row = mat[r0]
            order, maxalign = _header(row)
            rec = _Rec()
            _decode_struct(defs, tname, _Cur(row, order, maxalign, rec), "")
            sub = mat if len(remaining) == len(mat) else mat[remaining]
            ok = np.ones(len(sub), dtype=bool)
            for a, b in _merge_ranges([(0, 2), *rec.struct]):
                ok &= (sub[:, a:b] == row[a:b]).all(axis=1)
            if ok.all():
                members, block = remaining, sub
            else:
                members, block = remaining[ok], sub[ok]
            for path, off, dt, count, is_array in rec.numeric:
                width = np.dtype(dt).itemsize * count
                vals = np.ascontiguousarray(block[:, off : off + width]).view(dt)
                cols.add(path, gidx[members], vals if is_array else vals[:, 0], False)
            for path, value in rec.consts:
                cols.add(path, gidx[members], value, True)
            remaining = remaining[~ok]
    return cols.finish()


def _merge_ranges(ranges: list[tuple[int, int]]) -> list[tuple[int, int]]:
    out: list[list[int]] = []
    for a, b in sorted(r for r in ranges if r[1] > r[0]):
        if out and a <= out[-1][1]:
            out[-1][1] = max(out[-1][1], b)
        else:
            out.append([a, b])
    return [(a, b) for a, b in out]


def _add_generic(cols: _Columns, defs, tname: str, data, i: int) -> None:
    flat = flatten(decode(defs, tname, data), keep_none=True)
    idx = np.array([i])
    for path, v in flat.items():
        if isinstance(v, np.ndarray):
            cols.add(path, idx, v[None, ...], False)
        elif isinstance(v, (bool, int, float)):
            cols.add(path, idx, np.array([v]), False)
        else:
            cols.add(path, idx, v, True)


# ----------------------------------------------------------------------------------------- encoding
def _encode_struct(defs: Mapping[str, MsgDef], tname: str, value: Mapping, out: Writer, path: str) -> None:
    md = defs[tname]
    if not md.fields:
        out.buf += b"\0"
        return
    for f in md.fields:
        p = f"{path}{f.name}"
        v = value.get(f.name) if isinstance(value, Mapping) else getattr(value, f.name, None)
        if f.type in PRIMITIVES:
            dt, size = PRIMITIVES[f.type]
            if f.array is None:
                out.align(size)
                out.buf += np.asarray(0 if v is None else v, dtype="<" + dt).tobytes()
                continue
            arr = np.asarray([] if v is None else v, dtype="<" + dt).ravel()
            if f.array == "fixed":
                if len(arr) != f.length:
                    raise CdrError(f"{p}: fixed array needs {f.length} element(s), got {len(arr)}")
            else:
                out.u32(len(arr))
            if len(arr):
                out.align(size)
            out.buf += arr.tobytes()
        elif f.type in STRINGS:
            items = [v or ""] if f.array is None else list(v or [])
            if f.array == "seq":
                out.u32(len(items))
            for s in items:
                if f.type == "wstring":
                    raw = str(s).encode("utf-16-le") + b"\0\0"
                    out.u32(len(raw) // 2)
                    out.buf += raw
                else:
                    out.string(str(s))
        else:
            if f.array is None:
                _encode_struct(defs, f.type, v or {}, out, p + ".")
            else:
                items = list(v or [])
                if f.array == "seq":
                    out.u32(len(items))
                for item in items:
                    _encode_struct(defs, f.type, item, out, p + ".")


def encode(defs: Mapping[str, MsgDef], tname: str, value: Mapping) -> bytes:
    """Encode a (nested) dict or object with attributes as little-endian CDR with header; missing fields = 0/''."""
    out = Writer()
    _encode_struct(defs, tname, value, out, "")
    return bytes(out.buf)
