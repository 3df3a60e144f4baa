"""friction_ros.core.wire: the one CDR module of the package, checked against rclpy's serialiser.

Every fast encoder must write the bytes ``rclpy.serialization.serialize_message`` writes (XCDR1
little endian), and the decoder must read them back, whatever the joint count, name lengths
(alignment) and empty fields. Two differences are not part of the message and are tolerated by
:func:`assert_wire`: Fast DDS leaves padding bytes uninitialised (they hold whatever was in its
buffer; ours are zeros), and its buffer is sized with worst-case alignment, so after an empty
float64 sequence it carries up to 8 bytes past the end of the message per empty sequence (readers
ignore trailing bytes). Deserialising ours to exactly the message shows the differing bytes are
padding and that nothing is missing.
"""

from __future__ import annotations

import itertools
import math
import struct

import pytest
from builtin_interfaces.msg import Time
from friction_msgs.msg import ControllerState, DriveState, FrictionEstimate
from rclpy.serialization import deserialize_message, serialize_message
from sensor_msgs.msg import JointState
from std_msgs.msg import Header

from friction_ros.core.wire import (
    CDR_LE,
    CONTROLLER_STATE_FLOATS,
    DRIVE_STATE_FLOATS,
    DRIVE_STATE_UINTS,
    ControllerStateEncoder,
    DriveStateEncoder,
    FrictionEstimateEncoder,
    JointStateDecoder,
    JointStateEncoder,
    Writer,
    compile_template,
)

NAMES = ["", "a", "bb", "ccc", "dddd", "eeeee", "ffffff", "ggggggg", "hhhhhhhh", "élbow"]


def _joint_state(names, fields, values, frame_id="", sec=12, nanosec=345):
    m = JointState()
    m.header.stamp.sec, m.header.stamp.nanosec = sec, nanosec
    m.header.frame_id = frame_id
    m.name = list(names)
    for i, f in enumerate(fields):
        setattr(m, f, values[i * len(names) : (i + 1) * len(names)])
    return m


def assert_wire(data: bytes, msg) -> None:
    """``data`` is rclpy's serialisation of ``msg``, byte for byte, padding written as zeros."""
    ref = serialize_message(msg)
    assert 0 <= len(ref) - len(data) <= 24 and len(ref) % 4 == len(data) % 4, (len(data), len(ref))
    diff = [i for i, (a, b) in enumerate(zip(data, ref[: len(data)], strict=True)) if a != b]
    assert all(data[i] == 0 for i in diff), f"bytes differ at {diff}: {data.hex()} != {ref.hex()}"
    assert deserialize_message(data, type(msg)) == msg  # so the differing bytes are padding


# ---------------------------------------------------------------------------------------- primitives
@pytest.mark.parametrize("frame_id", ["", "a", "abc", "abcd", "abcdefgh"])
def test_writer_primitives_match_rclpy(frame_id):
    w = Writer()
    assert w.time(-5, 999_999_999) == 4
    assert_wire(w.bytes(), Time(sec=-5, nanosec=999_999_999))
    w = Writer()
    assert w.header(7, 8, frame_id) == 4
    h = Header(frame_id=frame_id)
    h.stamp.sec, h.stamp.nanosec = 7, 8
    assert_wire(w.bytes(), h)


@pytest.mark.parametrize("names", [[], ["a"], ["abc", "d"], NAMES])
@pytest.mark.parametrize("frame_id", ["", "xy", "abcdefg"])
def test_writer_builds_a_joint_state_like_rclpy(names, frame_id):
    n = len(names)
    pos, vel = [0.25 * i for i in range(n)], [-1.0 * i for i in range(n)]
    w = Writer()
    w.header(3, 4, frame_id)
    w.strings(names)
    w.float64s(pos)
    w.float64s(vel)
    w.float64s([])
    m = _joint_state(names, ("position", "velocity"), pos + vel, frame_id, 3, 4)
    assert_wire(w.bytes(), m)


def test_compile_template_rebuilds_the_template_and_rejects_bad_slots():
    w = Writer()
    stamp = w.header(0, 0, "f")
    off = w.put("2d", 0.0, 0.0)
    st, chunks = compile_template(w.buf, [(stamp, "iI"), (off, "2d")])
    assert chunks[0] == CDR_LE and st.size == len(w.buf)
    assert st.pack(chunks[0], 0, 0, chunks[1], 0.0, 0.0) == w.bytes()
    with pytest.raises(ValueError):
        compile_template(w.buf, [(stamp, "iI"), (stamp + 4, "d")])  # overlaps the stamp
    with pytest.raises(ValueError):
        compile_template(w.buf, [(off, "3d")])  # runs past the end


# ---------------------------------------------------------------------------------- JointState
@pytest.mark.parametrize("n", [0, 1, 2, 3, 5, 8])
@pytest.mark.parametrize("shift", [0, 1, 2, 3])
def test_joint_state_encoder_is_byte_identical_to_rclpy(n, shift):
    """Joint counts, name lengths at every alignment, every subset of the value fields."""
    names = [NAMES[(i + shift) % len(NAMES)] + str(i) * shift for i in range(n)]
    frame_id = "f" * shift
    for k in range(4):
        for fields in itertools.combinations(JointStateEncoder.FIELDS, k):
            enc = JointStateEncoder(names, fields, frame_id)
            values = [0.5 + i for i in range(n * len(fields))]
            data = enc.pack(1_700_000_000, 999_999_999, *values)
            expected = _joint_state(names, fields, values, frame_id, 1_700_000_000, 999_999_999)
            assert_wire(data, expected), (names, fields, frame_id)
            assert len(data) == enc.size
            assert enc.pack_ns(1_700_000_000_999_999_999, *values) == data


def test_joint_state_encoder_keeps_special_floats():
    data = JointStateEncoder(["j"]).pack(-1, 0, math.nan, -0.0, math.inf)
    m = deserialize_message(data, JointState)
    assert math.isnan(m.position[0]) and math.copysign(1, m.velocity[0]) < 0 and m.effort[0] == math.inf
    assert m.header.stamp.sec == -1


@pytest.mark.parametrize("names", [[], ["joint1"], ["a", "bb_joint", "ccc"]])
@pytest.mark.parametrize("frame_id", ["", "base", "abcd1"])
def test_joint_state_codec_matches_rclpy_serialisation(names, frame_id):
    """The raw-bytes JointState path (hot loop) reads and writes exactly what rclpy does."""
    decoder = JointStateDecoder()
    fields_sets = itertools.chain.from_iterable(
        itertools.combinations(JointStateEncoder.FIELDS, k) for k in range(4)
    )
    for fields in fields_sets:
        enc = JointStateEncoder(names, fields, frame_id)
        values = [0.5 + i for i in range(len(names) * len(fields))]
        expected = JointState()
        expected.header.stamp.sec, expected.header.stamp.nanosec = 12, 345
        expected.header.frame_id = frame_id
        expected.name = names
        for i, f in enumerate(fields):
            setattr(expected, f, values[i * len(names) : (i + 1) * len(names)])
        data = enc.pack(12, 345, *values)
        assert deserialize_message(data, JointState) == expected
        for payload in (serialize_message(expected), data, data):  # compile, then the cached layout
            sample = decoder.decode(payload)
            assert (sample.sec, sample.nanosec, sample.stamp_ns) == (12, 345, 12_000_000_345)
            assert (sample.frame_id, sample.name) == (frame_id, tuple(names))
            for f in JointStateEncoder.FIELDS:
                assert list(getattr(sample, f)) == list(getattr(expected, f))
    # a different layout on the same decoder (names, lengths) is recompiled, not misread
    other = JointStateEncoder(["x_joint", "y"], ("position",)).pack(1, 2, 3.0, 4.0)
    s = decoder.decode(other)
    assert s.name == ("x_joint", "y") and s.position == (3.0, 4.0) and s.velocity == ()


def test_decoded_joint_sample_works_with_the_select_helpers():
    from friction_ros.core.input_gate import select_command, select_sample

    msg = JointState(name=["a", "joint1"], position=[0.1, 0.2], velocity=[1.0, 2.0], effort=[0.5, 1.5])
    s = JointStateDecoder().decode(serialize_message(msg))
    assert select_command(s, "joint1", math.inf)[0] == 1.5 and select_command(s, "other", math.inf)[0] is None
    assert select_sample(s, "joint1")[0] == (0.2, 2.0, 1.5) and select_sample(s, "b")[0] is None


@pytest.mark.parametrize("n", [0, 1, 2, 4])
@pytest.mark.parametrize("shift", [0, 1, 3])
def test_joint_state_decoder_round_trips_rclpy_messages(n, shift):
    dec = JointStateDecoder()
    for k in range(4):
        for fields in itertools.combinations(JointStateEncoder.FIELDS, k):
            names = [NAMES[(i + shift) % len(NAMES)] for i in range(n)]
            values = [-1.25 * i + shift for i in range(n * len(fields))]
            m = _joint_state(names, fields, values, "w" * shift, shift, 1000 + n)
            for _ in range(2):  # compile, then the cached layout
                s = dec.decode(serialize_message(m))
                assert (s.sec, s.nanosec, s.frame_id, s.name) == (shift, 1000 + n, "w" * shift, tuple(names))
                for f in JointStateEncoder.FIELDS:
                    assert s.__getattribute__(f) == tuple(getattr(m, f))


def test_joint_state_decoder_reads_big_endian_and_xcdr2():
    """Payloads the fast path does not take go through the schema-driven decoder of the bag core."""
    # frame_id "", no names, one position: no padding before the double, so XCDR1 bytes are XCDR2 too
    le = serialize_message(JointState(position=[2.5]))
    s = JointStateDecoder().decode(b"\x00\x07" + le[2:])
    assert s.position == (2.5,) and s.name == () and s.velocity == () and isinstance(s.position[0], float)
    be = (
        b"\x00\x00\x00\x00"
        + struct.pack(">iII", 9, 10, 1)  # stamp, frame_id length
        + b"\0\0\0\0"  # frame_id NUL + 3 bytes of padding
        + struct.pack(">IIdII", 0, 1, 2.5, 0, 0)  # no names, one position (at 24: aligned), no others
    )
    s = JointStateDecoder().decode(be)
    assert (s.sec, s.nanosec, s.position, s.velocity, s.effort) == (9, 10, (2.5,), (), ())
    with pytest.raises(ValueError):
        JointStateDecoder().decode(b"\x00\x01\x00\x00\x01")


# ------------------------------------------------------------------------------- friction_msgs
def test_wire_field_tables_match_the_message_definitions():
    cs = ControllerState.get_fields_and_field_types()
    assert CONTROLLER_STATE_FLOATS == tuple(k for k, t in cs.items() if t == "double")
    ds = DriveState.get_fields_and_field_types()
    assert DRIVE_STATE_FLOATS == tuple(k for k, t in ds.items() if t == "double")
    assert DRIVE_STATE_UINTS == tuple(k for k, t in ds.items() if t == "uint32")


@pytest.mark.parametrize("joint", ["", "j", "joint1", "abcdefg", "élbow_joint_3"])
@pytest.mark.parametrize("mode", ["", "pid", "dnpf", "cascade", "gain_scheduling", "sliding_mode"])
@pytest.mark.parametrize("saturated", [False, True])
def test_controller_state_encoder_is_byte_identical_to_rclpy(joint, mode, saturated):
    enc = ControllerStateEncoder(joint)
    values = [0.125 * i - 1 for i in range(len(CONTROLLER_STATE_FLOATS))]
    m = ControllerState(joint_name=joint, mode=mode, saturated=saturated)
    m.header.stamp.sec, m.header.stamp.nanosec = 1_700_000_000, 42
    for k, v in zip(CONTROLLER_STATE_FLOATS, values, strict=True):
        setattr(m, k, v)
    for _ in range(2):  # the layout of a mode is built once, then reused
        data = enc.pack(1_700_000_000, 42, mode, values, saturated)
        assert_wire(data, m)
    assert deserialize_message(data, ControllerState) == m


@pytest.mark.parametrize("joint", ["", "j1", "abc", "élbow_joint_3"])
@pytest.mark.parametrize("protocol", ["odrive_cansimple", "mit", ""])
def test_drive_state_encoder_is_byte_identical_to_rclpy(joint, protocol):
    from friction_ros.nodes.drive_state_publishers import StatePackets

    vals = (0.5, -1.5, math.inf, -3.5, 4.5, 24.0, 8, 0xDEADBEEF, 33, True)
    m = DriveState(joint_name=joint, protocol=protocol)
    m.header.stamp.sec, m.header.stamp.nanosec = -7, 999_999_999
    for k, v in zip((*DRIVE_STATE_FLOATS, *DRIVE_STATE_UINTS, "enabled"), vals, strict=True):
        setattr(m, k, v)
    enc = DriveStateEncoder(joint, protocol)
    assert_wire(enc.pack(-7, 999_999_999, *vals), m)
    assert len(enc.pack(0, 0, *vals)) == enc.size
    p = StatePackets(joint, protocol)
    assert p.verify() == ""
    assert_wire(p.set_drive(-7, 999_999_999, *vals), m)
    js = _joint_state([joint], JointStateEncoder.FIELDS, [1.0, 2.0, 3.0], "", 5, 6)
    assert_wire(p.set_joint(5, 6, 1.0, 2.0, 3.0), js)


# ------------------------------------------------------------------------------------ bag codec
def test_bag_codec_shares_the_wire_primitives_and_matches_rclpy():
    from friction_ros.core.bag.cdr import decode, encode
    from friction_ros.core.bag.msgdef import load_installed

    defs = load_installed("sensor_msgs/msg/JointState")
    value = {
        "header": {"stamp": {"sec": 3, "nanosec": 4}, "frame_id": "abc"},
        "name": ["a", "bbbbb"],
        "position": [1.0, 2.0],
        "velocity": [],
        "effort": [0.5, -0.5],
    }
    data = encode(defs, "sensor_msgs/msg/JointState", value)
    m = _joint_state(["a", "bbbbb"], ("position",), [1.0, 2.0], "abc", 3, 4)
    m.effort = [0.5, -0.5]
    assert_wire(data, m)
    enc = JointStateEncoder(["a", "bbbbb"], ("position", "effort"), "abc")
    assert enc.pack(3, 4, 1.0, 2.0, 0.5, -0.5) == data
    back = decode(defs, "sensor_msgs/msg/JointState", data)
    assert back["name"] == ("a", "bbbbb") and back["effort"].tolist() == [0.5, -0.5]
    cdefs = load_installed("friction_msgs/msg/ControllerState")
    cm = ControllerState(joint_name="j", mode="pid", command=1.5, saturated=True)
    cvalue = {"joint_name": "j", "mode": "pid", "command": 1.5, "saturated": True}
    assert_wire(encode(cdefs, "friction_msgs/msg/ControllerState", cvalue), cm)


@pytest.mark.parametrize(
    "model, state, names, coefs, std",
    [
        ("coulomb_viscous", [], ["fc", "fv"], [1.5, 0.25], [0.1, 0.2]),
        ("lugre", [0.001], ["fc", "fs", "vs", "sigma0", "sigma1", "fv"], [1, 2, 0.1, 1e4, 3, 0.2], []),
        ("gms", [1e-3, -2e-3, 3e-3], ["k[0]", "alpha[0]"], [math.pi, -math.inf], [1e-9, math.inf]),
        ("", [], [], [], []),
    ],
)
@pytest.mark.parametrize("joint", ["", "j1", "élbow_joint_3"])
def test_friction_estimate_encoder_is_byte_identical_to_rclpy(joint, model, state, names, coefs, std):
    enc = FrictionEstimateEncoder(joint)
    for flags in ((True, False), (False, True)):
        m = FrictionEstimate(
            joint_name=joint, model=model, friction_torque=0.5, model_torque=-0.25, velocity=1.25,
            state=state, coefficient_names=names, coefficients=coefs, coefficient_std=std,
            excitation_ok=flags[0], converged=flags[1],
        )  # fmt: skip
        m.header.stamp.sec, m.header.stamp.nanosec = 1_700_000_000, 42
        data = enc.pack(1_700_000_000, 42, model, 0.5, -0.25, 1.25, state, names, coefs, std, *flags)
        assert_wire(data, m)
        back = deserialize_message(data, FrictionEstimate)
        assert list(back.coefficients) == pytest.approx(coefs)
        assert list(back.coefficient_std) == pytest.approx(std)
        assert (back.joint_name, back.model, back.converged) == (joint, model, flags[1])
    with pytest.raises(ValueError, match="2 coefficient names, 1 values"):
        enc.pack(0, 0, "m", 0.0, 0.0, 0.0, [], ["a", "b"], [1.0], [], False, False)


@pytest.mark.parametrize("n_status", [0, 1, 3])
def test_diagnostic_array_encoding_is_byte_identical_to_rclpy(n_status):
    from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue

    from friction_ros.core.wire import encode_diagnostic_array

    statuses = [
        (
            i % 4,
            f"/ns/node/j{i}",
            "running" * i,
            "" if i == 1 else f"hw{i}",
            [(f"k{k}", "v" * k) for k in range(i + 1)],
        )
        for i in range(n_status)
    ]
    msg = DiagnosticArray()
    msg.header.stamp.sec, msg.header.stamp.nanosec = 1_700_000_000, 42
    for level, name, text, hw, values in statuses:
        msg.status.append(
            DiagnosticStatus(
                level=bytes([level]),
                name=name,
                message=text,
                hardware_id=hw,
                values=[KeyValue(key=k, value=v) for k, v in values],
            )
        )
    data = encode_diagnostic_array(1_700_000_000, 42, statuses)
    assert_wire(data, msg)
    assert deserialize_message(data, DiagnosticArray) == msg
