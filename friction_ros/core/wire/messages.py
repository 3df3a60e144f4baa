"""Fast CDR codecs of the messages the nodes publish and take every period (pure Python, no rclpy).

Hot-path replacements for building a message object and letting rclpy convert and serialise it
(~10 us of Python per message before the C conversion): ``Publisher.publish(bytes)`` sends the
bytes as they are, so the wire type stays the ROS type and every subscriber (rclpy, C++, rosbag2)
reads it as usual. Each encoder writes a template of its message once with :class:`~.cdr.Writer`
and compiles it (:func:`~.cdr.compile_template`) into one ``struct.Struct``: a message is then one
``pack`` (~0.2-0.5 us). Layout: XCDR1 little endian as Fast DDS writes it (see :mod:`.cdr`).

* sensor_msgs/JointState: :class:`JointStateEncoder`, :class:`JointStateDecoder` -> :class:`DecodedJointState`
* friction_msgs/ControllerState: :class:`ControllerStateEncoder`
* friction_msgs/DriveState: :class:`DriveStateEncoder`
* friction_msgs/FrictionEstimate: :class:`FrictionEstimateEncoder`
* diagnostic_msgs/DiagnosticArray: :func:`encode_diagnostic_array`
"""

from __future__ import annotations

import operator
import struct
from collections.abc import Iterable

from .cdr import CDR_LE, ORIGIN, U32, Reader, Writer, compile_template, compile_template_plan, padding

# friction_msgs/ControllerState float64 fields in message order (the order ControllerStateEncoder.pack
# expects); msg_defs/friction_msgs/msg/ControllerState.msg, checked against the generated class in tests
CONTROLLER_STATE_FLOATS = (
    "reference_position",
    "reference_velocity",
    "reference_acceleration",
    "position",
    "velocity",
    "error",
    "error_dot",
    "p_term",
    "i_term",
    "d_term",
    "velocity_feedforward",
    "inertia_feedforward",
    "friction_feedforward",
    "friction_feedback",
    "load_feedforward",
    "learned_feedforward",
    "command_unlimited",
    "command",
)
# friction_msgs/DriveState fields after header, joint_name and protocol, in message order
DRIVE_STATE_FLOATS = (
    "motor_position",
    "motor_velocity",
    "current_setpoint",
    "current_measured",
    "torque_estimate",
    "bus_voltage",
)
DRIVE_STATE_UINTS = ("axis_state", "axis_error", "fault_flags")


# ------------------------------------------------------------------------------ sensor_msgs/JointState
class DecodedJointState:
    """A decoded sensor_msgs/JointState (attribute names as the message; sequences are tuples).

    ``select_joint`` / ``select_effort`` accept it like the message. ``stamp_ns`` is the header stamp
    in integer nanoseconds.
    """

    __slots__ = ("sec", "nanosec", "stamp_ns", "frame_id", "name", "position", "velocity", "effort")

    def __init__(self, sec, nanosec, frame_id, name, position, velocity, effort):
        self.sec = sec
        self.nanosec = nanosec
        self.stamp_ns = sec * 1_000_000_000 + nanosec
        self.frame_id = frame_id
        self.name = name
        self.position = position
        self.velocity = velocity
        self.effort = effort


class JointStateEncoder:
    """Serialise sensor_msgs/JointState for fixed joint names to CDR bytes in one ``struct.pack``.

    ``fields`` are the sequences that carry one value per joint (the others are empty);
    ``pack(sec, nanosec, *values)`` takes their values in message order (position, velocity, effort).
    """

    FIELDS = ("position", "velocity", "effort")

    def __init__(self, names: Iterable[str], fields: Iterable[str] = FIELDS, frame_id: str = ""):
        self.names = tuple(names)
        wanted = set(fields)
        self.fields = tuple(f for f in self.FIELDS if f in wanted)
        n = self.n = len(self.names)
        w = Writer()
        slots = [(w.header(0, 0, frame_id), "iI")]
        w.strings(self.names)
        for f in self.FIELDS:
            count = n if f in self.fields else 0
            off = w.float64s([0.0] * count)
            if count:
                slots.append((off, f"{count}d"))
        self._struct, chunks = compile_template(w.buf, slots)
        self._chunks = chunks[1:]  # chunks[0] is the encapsulation header, passed as CDR_LE
        self._all1 = n == 1 and len(self.fields) == 3
        self.size = self._struct.size

    def pack(self, sec: int, nanosec: int, *values: float) -> bytes:
        """CDR bytes of the message with stamp (sec, nanosec) and ``values`` (n per field, in order)."""
        c = self._chunks
        if len(c) == 1:  # one field (commands: effort only)
            return self._struct.pack(CDR_LE, sec, nanosec, c[0], *values)
        if self._all1:  # one joint, all fields (joint states)
            p, v, e = values
            return self._struct.pack(CDR_LE, sec, nanosec, c[0], p, c[1], v, c[2], e)
        n = self.n
        args: list = [CDR_LE, sec, nanosec]
        for i, ch in enumerate(c):
            args.append(ch)
            args.extend(values[i * n : (i + 1) * n])
        return self._struct.pack(*args)

    def pack_ns(self, stamp_ns: int, *values: float) -> bytes:
        sec, nanosec = divmod(stamp_ns, 1_000_000_000)
        return self.pack(sec, nanosec, *values)


class JointStateDecoder:
    """CDR bytes of sensor_msgs/JointState (a ``raw=True`` subscription) -> :class:`DecodedJointState`.

    The layout of the last message (string lengths and contents, sequence lengths) is compiled into
    one ``struct.Struct``; a message with the same layout is decoded with one ``unpack_from`` and one
    comparison of its length/name fields (~1 us instead of ~17 us for rclpy's deserialisation into
    a message object). Anything else (big endian, XCDR2) is decoded by the sequential
    :class:`~friction_ros.core.wire.cdr.Reader`, which raises ``ValueError`` on malformed input.
    """

    def __init__(self):
        self._struct: struct.Struct | None = None
        self._check = None  # itemgetter of the length/name fields
        self._consts: tuple = ()
        self._frame_id = ""
        self._names: tuple[str, ...] = ()
        self._slices = ((0, 0), (0, 0), (0, 0))

    def decode(self, data: bytes) -> DecodedJointState:
        st = self._struct
        if st is not None and data[:2] == b"\x00\x01" and len(data) >= st.size:
            v = st.unpack_from(data)
            if self._check(v) == self._consts:
                (a0, b0), (a1, b1), (a2, b2) = self._slices
                return DecodedJointState(
                    v[0], v[1], self._frame_id, self._names, v[a0:b0], v[a1:b1], v[a2:b2]
                )
        return self._compile(data)

    def _compile(self, data: bytes) -> DecodedJointState:
        if data[:2] != b"\x00\x01":
            return self._fallback(data)
        fmt = ["<4xiI"]
        items: list[str] = []  # kind of each unpacked item after sec/nanosec: c(onst) or d(ouble run)
        consts: list = []
        pos = 8  # offset from the alignment origin (the stamp is 0..8)

        def skip(align: int) -> None:
            nonlocal pos
            k = padding(pos, align)
            if k:
                fmt.append(f"{k}x")
                pos += k

        def u32() -> int:
            nonlocal pos
            skip(4)
            (x,) = U32.unpack_from(data, ORIGIN + pos)
            fmt.append("I")
            items.append("c")
            consts.append(x)
            pos += 4
            return x

        def string() -> str:
            nonlocal pos
            n = u32()
            raw = bytes(data[ORIGIN + pos : ORIGIN + pos + n])
            if len(raw) != n or n > 4096:
                raise struct.error("bad string")
            fmt.append(f"{n}s")
            items.append("c")
            consts.append(raw)
            pos += n
            return raw[:-1].decode() if n else ""

        try:
            frame_id = string()
            count = u32()
            if count > 4096:
                raise struct.error("too many names")
            names = tuple(string() for _ in range(count))
            runs = []
            for _ in range(3):
                count = u32()
                if count > 65536:
                    raise struct.error("sequence too long")
                if count:
                    skip(8)
                    fmt.append(f"{count}d")
                    items.extend("d" * count)
                    pos += 8 * count
                runs.append(count)
            st = struct.Struct("".join(fmt))
            if st.size > len(data):
                raise struct.error("payload too short")
            v = st.unpack_from(data)
        except (struct.error, UnicodeDecodeError):
            return self._fallback(data)
        const_idx = [2 + i for i, k in enumerate(items) if k == "c"]
        slices = []
        # runs of doubles appear in field order; their start indices in the unpacked tuple
        starts = [2 + i for i, k in enumerate(items) if k == "d" and (i == 0 or items[i - 1] != "d")]
        it = iter(starts)
        for count in runs:
            if count:
                a = next(it)
                slices.append((a, a + count))
            else:
                slices.append((0, 0))
        self._struct = st
        self._check = operator.itemgetter(*const_idx)
        self._consts = self._check(v)
        self._frame_id = frame_id
        self._names = names
        self._slices = tuple(slices)
        (a0, b0), (a1, b1), (a2, b2) = self._slices
        return DecodedJointState(v[0], v[1], frame_id, names, v[a0:b0], v[a1:b1], v[a2:b2])

    @staticmethod
    def _fallback(data: bytes) -> DecodedJointState:
        r = Reader(data)
        sec, nanosec = r.get("iI", 4)
        frame_id = r.string()
        return DecodedJointState(
            sec, nanosec, frame_id, r.strings(), r.float64s(), r.float64s(), r.float64s()
        )


# ------------------------------------------------------------------------------ friction_msgs
def _stamped_layout(strings: Iterable[str], tail: Iterable[str]) -> tuple[struct.Struct, bytes]:
    """Struct ``<4s iI Ns <tail...>`` and the constant chunk N of a message that is a std_msgs/Header
    (empty frame_id), the ``strings`` and then fixed-size fields ``tail`` (struct formats, in order)."""
    w = Writer()
    slots = [(w.header(), "iI")]
    for text in strings:
        w.string(text)
    for f in tail:
        zeros = struct.unpack("<" + f, bytes(struct.calcsize("<" + f)))
        slots.append((w.put(f, *zeros), f))
    st, chunks = compile_template(w.buf, slots)
    if len(chunks) != 2 or chunks[0] != CDR_LE:
        raise AssertionError("unexpected layout")
    return st, chunks[1]


class ControllerStateEncoder:
    """friction_msgs/ControllerState -> CDR bytes with one ``struct.pack`` (published as bytes).

    The layout is fixed by the joint name and the mode string: header stamp, empty frame_id,
    joint_name, mode, the float64 fields in message order (:data:`CONTROLLER_STATE_FLOATS`), saturated.
    """

    def __init__(self, joint: str):
        self.joint = joint
        self._by_mode: dict[str, tuple[struct.Struct, bytes]] = {}

    def _layout(self, mode: str) -> tuple[struct.Struct, bytes]:
        layout = _stamped_layout((self.joint, mode), (f"{len(CONTROLLER_STATE_FLOATS)}d", "?"))
        self._by_mode[mode] = layout
        return layout

    def pack(self, sec: int, nanosec: int, mode: str, values, saturated: bool) -> bytes:
        st, mid = self._by_mode.get(mode) or self._layout(mode)
        return st.pack(CDR_LE, sec, nanosec, mid, *values, bool(saturated))


class DriveStateEncoder:
    """friction_msgs/DriveState for one joint and protocol -> CDR bytes with one ``struct.pack``.

    ``pack(sec, nanosec, *values)``: the 6 float64 (:data:`DRIVE_STATE_FLOATS`), the 3 uint32
    (:data:`DRIVE_STATE_UINTS`) and ``enabled``, in message order.
    """

    def __init__(self, joint: str, protocol: str):
        self.joint, self.protocol = joint, protocol
        self._struct, self._mid = _stamped_layout(
            (joint, protocol), (f"{len(DRIVE_STATE_FLOATS)}d", f"{len(DRIVE_STATE_UINTS)}I", "?")
        )
        self.size = self._struct.size

    def pack(self, sec: int, nanosec: int, *values) -> bytes:
        return self._struct.pack(CDR_LE, sec, nanosec, self._mid, *values)


class FrictionEstimateEncoder:
    """friction_msgs/FrictionEstimate of one joint -> CDR bytes with one ``struct.pack``.

    The layout is fixed by the model string, the number of states, the coefficient names and
    whether standard deviations are sent; one compiled layout per such key (a model change
    compiles a new one). ``pack(sec, nanosec, model, friction_torque, model_torque, velocity,
    state, names, coefficients, std, excitation_ok, converged)``; ``std`` empty or one per name.
    """

    def __init__(self, joint: str):
        self.joint = joint
        self._layouts: dict[tuple, tuple[struct.Struct, list]] = {}

    def _layout(self, key: tuple) -> tuple[struct.Struct, list]:
        model, n_state, names, n_std = key
        w = Writer()
        slots = [(w.header(), "iI")]
        w.string(self.joint)
        w.string(model)
        slots.append((w.put("3d", 0.0, 0.0, 0.0), "3d"))
        sequences = [w.float64s([0.0] * n_state)]
        w.strings(names)
        sequences += [w.float64s([0.0] * len(names)), w.float64s([0.0] * n_std)]
        slots += [(off, f"{n}d") for off, n in zip(sequences, (n_state, len(names), n_std)) if n]
        slots.append((w.put("2?", False, False), "2?"))
        self._layouts[key] = compile_template_plan(w.buf, slots)
        return self._layouts[key]

    def pack(
        self, sec, nanosec, model, friction_torque, model_torque, velocity, state, names, coefficients, std,
        excitation_ok, converged,
    ) -> bytes:  # fmt: skip
        if len(coefficients) != len(names) or (len(std) and len(std) != len(names)):
            raise ValueError(
                f"{len(names)} coefficient names, {len(coefficients)} values, {len(std)} std: must agree"
            )
        key = (model, len(state), tuple(names), len(std))
        st, plan = self._layouts.get(key) or self._layout(key)
        values = (
            sec, nanosec, friction_torque, model_torque, velocity, *state, *coefficients, *std,
            bool(excitation_ok), bool(converged),
        )  # fmt: skip
        args, i = [], 0
        for item in plan:
            if isinstance(item, int):
                args.extend(values[i : i + item])
                i += item
            else:
                args.append(item)
        return st.pack(*args)


# ------------------------------------------------------------------------------ diagnostic_msgs
def encode_diagnostic_array(
    sec: int, nanosec: int, statuses: Iterable[tuple[int, str, str, str, Iterable[tuple[str, str]]]]
) -> bytes:
    """diagnostic_msgs/DiagnosticArray -> CDR bytes: header (empty frame_id), then per status
    ``(level, name, message, hardware_id, [(key, value), ...])``. A node's status once per
    diagnostics period: ~20 us for 7 statuses of 25 values, where message objects took ~0.9 ms."""
    statuses = list(statuses)
    w = Writer()
    w.header(sec, nanosec)
    w.u32(len(statuses))
    for level, name, message, hardware_id, values in statuses:
        w.raw(bytes((level,)))  # byte: no alignment
        w.string(name)
        w.string(message)
        w.string(hardware_id)
        values = list(values)
        w.u32(len(values))
        for key, value in values:
            w.string(key)
            w.string(value)
    return w.bytes()
