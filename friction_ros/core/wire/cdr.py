"""CDR primitives shared by every codec of the package (pure Python, no rclpy).

What ROS 2 middlewares put on the wire and rosbag2 stores: a 4-byte RTPS encapsulation header
(``00 01``: little-endian plain CDR, XCDR1), then the fields in message order, each aligned to its
size (at most 8) relative to the byte after the header, zero padding. Strings are a uint32 length
including the terminating NUL, the UTF-8 bytes and the NUL; sequences a uint32 count and the
elements. builtin_interfaces/Time is int32 sec + uint32 nanosec; std_msgs/Header is a Time and the
frame_id string.

* :class:`Writer`: builds a message (or a template of one) field by field.
* :func:`compile_template`: turns a template with variable slots into one ``struct.Struct`` and the
  constant byte chunks between the slots, so a fast encoder packs a whole message with one call.
* :func:`encapsulation`: byte order and maximum alignment of a payload from its header.
"""

from __future__ import annotations

import struct
from collections.abc import Iterable, Sequence

CDR_LE = b"\x00\x01\x00\x00"  # RTPS encapsulation: little-endian plain CDR (XCDR1), no options
# encapsulation kind (second header byte) -> (struct byte order, maximum alignment)
ENCAPSULATIONS = {0: (">", 8), 1: ("<", 8), 6: (">", 4), 7: ("<", 4)}
ORIGIN = 4  # alignment origin: the byte after the encapsulation header
U32 = struct.Struct("<I")
TIME = struct.Struct("<iI")  # builtin_interfaces/Time: sec, nanosec


def padding(offset: int, align: int) -> int:
    """Bytes of padding before a field of alignment ``align`` at ``offset`` (from the origin)."""
    return -offset % align


def string_bytes(text: str) -> bytes:
    """A CDR string without its length: UTF-8 and the terminating NUL."""
    return text.encode() + b"\0"


def encapsulation(data) -> tuple[str, int] | None:
    """(byte order, maximum alignment) of a payload's encapsulation header; None if unsupported."""
    if len(data) < 4 or data[0] != 0:
        return None
    return ENCAPSULATIONS.get(data[1])


class Writer:
    """Little-endian XCDR1 writer: the message grows in ``buf`` (header included).

    Every ``put``-like method aligns first and returns the offset of what it wrote, so a template
    can be written once with placeholder values and the offsets of the variable fields kept.
    """

    __slots__ = ("buf",)

    def __init__(self) -> None:
        self.buf = bytearray(CDR_LE)

    def align(self, n: int) -> None:
        self.buf += bytes(padding(len(self.buf) - ORIGIN, n))

    def put(self, fmt: str, *values) -> int:
        """Pack values of one primitive type (aligned to its size); return their offset."""
        st = struct.Struct("<" + fmt)
        self.align(struct.calcsize("<" + fmt[-1]))
        off = len(self.buf)
        self.buf += st.pack(*values)
        return off

    def u32(self, value: int) -> int:
        self.align(4)
        off = len(self.buf)
        self.buf += U32.pack(value)
        return off

    def raw(self, data: bytes) -> None:
        self.buf += data

    def string(self, text: str) -> int:
        raw = string_bytes(text)
        buf = self.buf
        off = len(buf) + (-(len(buf) - ORIGIN) % 4)
        buf += bytes(off - len(buf))
        buf += U32.pack(len(raw))
        buf += raw
        return off

    def strings(self, texts: Sequence[str]) -> int:
        """sequence<string>: count, then each string."""
        off = self.u32(len(texts))
        for t in texts:
            self.string(t)
        return off

    def float64s(self, values: Sequence[float]) -> int:
        """sequence<float64>: count, then the doubles (aligned to 8 only when there are any);
        returns the offset of the first double."""
        self.u32(len(values))
        if values:
            self.align(8)
        off = len(self.buf)
        self.buf += struct.pack(f"<{len(values)}d", *values)
        return off

    def time(self, sec: int = 0, nanosec: int = 0) -> int:
        """builtin_interfaces/Time; returns its offset."""
        self.align(4)
        off = len(self.buf)
        self.buf += TIME.pack(sec, nanosec)
        return off

    def header(self, sec: int = 0, nanosec: int = 0, frame_id: str = "") -> int:
        """std_msgs/Header; returns the offset of its stamp."""
        off = self.time(sec, nanosec)
        self.string(frame_id)
        return off

    def bytes(self) -> bytes:
        return bytes(self.buf)


def compile_template(buf: bytes, slots: Iterable[tuple[int, str]]) -> tuple[struct.Struct, tuple[bytes, ...]]:
    """One ``struct.Struct`` for a template with variable ``slots`` (offset, struct format).

    The format is ``<`` + alternating ``Ns`` (a constant chunk of the template) and the slot formats,
    adjacent slots merged; returns it and the chunks in order, so
    ``st.pack(chunk0, *slot0_values, chunk1, ...)`` rebuilds the template with new values.
    The chunk before the first slot includes the encapsulation header.
    """
    st, plan = compile_template_plan(buf, slots)
    return st, tuple(p for p in plan if isinstance(p, bytes))


def compile_template_plan(
    buf: bytes, slots: Iterable[tuple[int, str]]
) -> tuple[struct.Struct, list[bytes | int]]:
    """:func:`compile_template` with the pack arguments in order: a constant chunk (bytes) or the
    number of values of a slot, for a caller that packs values of several slots from one sequence."""
    fmt = ["<"]
    plan: list[bytes | int] = []
    pos = 0
    for off, f in sorted(slots):
        if off < pos:
            raise ValueError(f"overlapping slots at offset {off}")
        if off > pos:
            plan.append(bytes(buf[pos:off]))
            fmt.append(f"{off - pos}s")
        fmt.append(f)
        slot = struct.Struct("<" + f)
        plan.append(len(slot.unpack(bytes(slot.size))))
        pos = off + slot.size
    if pos < len(buf):
        plan.append(bytes(buf[pos:]))
        fmt.append(f"{len(buf) - pos}s")
    st = struct.Struct("".join(fmt))
    if st.size != len(buf):
        raise ValueError("slots do not tile the template")
    return st, plan


class WireDecodeError(ValueError):
    """A CDR payload that does not decode (too short, an unknown encapsulation, a bad length)."""


class Reader:
    """Sequential reader of a CDR payload, the inverse of :class:`Writer` for any encapsulation of
    :data:`ENCAPSULATIONS` (a field of size s is aligned to min(s, maximum alignment) from
    :data:`ORIGIN`; an empty sequence adds no padding). Malformed input raises :class:`WireDecodeError`."""

    def __init__(self, data) -> None:
        if len(data) < 4:
            raise WireDecodeError(f"payload of {len(data)} byte(s) is shorter than the 4-byte CDR header")
        enc = encapsulation(data)
        if enc is None:
            raise WireDecodeError(
                f"unsupported CDR encapsulation {bytes(data[:2]).hex()}: supported are 0000/0001 (CDR) and "
                "0006/0007 (plain XCDR2)"
            )
        self.data = bytes(data)
        self.order, self.max_align = enc
        self.pos = ORIGIN

    def get(self, fmt: str, align: int) -> tuple:
        """Unpack ``fmt`` (struct format without byte order) aligned to ``align`` bytes."""
        self.pos += padding(self.pos - ORIGIN, min(align, self.max_align))
        st = struct.Struct(self.order + fmt)
        if self.pos + st.size > len(self.data):
            raise WireDecodeError(
                f"payload too short: {st.size} byte(s) needed at offset {self.pos}, has {len(self.data)}"
            )
        values = st.unpack_from(self.data, self.pos)
        self.pos += st.size
        return values

    def u32(self) -> int:
        return self.get("I", 4)[0]

    def string(self) -> str:
        n = self.u32()
        raw = self.get(f"{n}s", 1)[0] if n else b""
        return raw[:-1].decode("utf-8", "replace")

    def strings(self) -> tuple[str, ...]:
        return tuple(self.string() for _ in range(self.u32()))

    def float64s(self) -> tuple[float, ...]:
        n = self.u32()
        return self.get(f"{n}d", 8) if n else ()
