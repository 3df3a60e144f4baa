"""CAN codecs: DBC conformance (cantools oracle), MIT golden vectors, fuzzing, joint conversion."""

from __future__ import annotations

import math
import random
import sys
from pathlib import Path

import cantools
import numpy as np
import pytest

from friction_ros.core.can import mit as mitc
from friction_ros.core.can import odrive as od
from friction_ros.core.can.axis import DriveAxis
from friction_ros.core.can.axis_config import AxisConfig
from friction_ros.core.can.joint import JointConversion
from friction_ros.core.validation import ParameterError

DBC = Path(__file__).resolve().parent / "data" / "odrive-cansimple.dbc"  # copy of shared/specs (the oracle)
TWO_PI = 2 * math.pi

# 0.6.x messages the shared DBC (0.5.x) lacks, written from the anchors table (section 2.1).
DBC_06_SUPPLEMENT = """VERSION ""
BS_:
BU_:
BO_ 2 Estop: 0 Vector__XXX
BO_ 3 Get_Error: 8 Vector__XXX
 SG_ Active_Errors : 0|32@1+ (1,0) [0|0] "" Vector__XXX
 SG_ Disarm_Reason : 32|32@1+ (1,0) [0|0] "" Vector__XXX
BO_ 1 Heartbeat: 8 Vector__XXX
 SG_ Axis_Error : 0|32@1+ (1,0) [0|0] "" Vector__XXX
 SG_ Axis_State : 32|8@1+ (1,0) [0|0] "" Vector__XXX
 SG_ Procedure_Result : 40|8@1+ (1,0) [0|0] "" Vector__XXX
 SG_ Trajectory_Done_Flag : 48|1@1+ (1,0) [0|0] "" Vector__XXX
BO_ 23 Get_Bus_Voltage_Current: 8 Vector__XXX
 SG_ Bus_Voltage : 0|32@1+ (1,0) [0|0] "" Vector__XXX
 SG_ Bus_Current : 32|32@1+ (1,0) [0|0] "" Vector__XXX
BO_ 24 Clear_Errors: 1 Vector__XXX
 SG_ Identify : 0|8@1+ (1,0) [0|0] "" Vector__XXX
BO_ 28 Get_Torques: 8 Vector__XXX
 SG_ Torque_Target : 0|32@1+ (1,0) [0|0] "" Vector__XXX
 SG_ Torque_Estimate : 32|32@1+ (1,0) [0|0] "" Vector__XXX
SIG_VALTYPE_ 23 Bus_Voltage : 1;
SIG_VALTYPE_ 23 Bus_Current : 1;
SIG_VALTYPE_ 28 Torque_Target : 1;
SIG_VALTYPE_ 28 Torque_Estimate : 1;
"""


@pytest.fixture(scope="module")
def db():
    return cantools.database.load_file(str(DBC))


@pytest.fixture(scope="module")
def db06():
    return cantools.database.load_string(DBC_06_SUPPLEMENT, database_format="dbc")


def f32(x):
    return float(np.float32(x))


def rnd_float(rng, scale=100.0):
    return rng.uniform(-scale, scale)


# Encoders (node side and emulator side) with the DBC message and the expected wire values (turns).
def cases(rng):
    n = rng.randrange(0, 64)
    p, v, a, b = (rnd_float(rng) for _ in range(4))
    st = rng.choice([1, 3, 8])
    yield (
        n,
        "Get_Encoder_Estimates",
        od.encode_encoder_estimates(n, p, v),
        {
            "Pos_Estimate": f32(p / TWO_PI),
            "Vel_Estimate": f32(v / TWO_PI),
        },
    )
    yield n, "Get_Iq", od.encode_iq(n, a, b), {"Iq_Setpoint": f32(a), "Iq_Measured": f32(b)}
    yield n, "Set_Input_Torque", od.encode_set_input_torque(n, a), {"Input_Torque": f32(a)}
    yield n, "Set_Axis_State", od.encode_set_axis_state(n, st), {"Axis_Requested_State": st}
    yield (
        n,
        "Set_Controller_Mode",
        od.encode_set_controller_mode(n, 1, 1),
        {"Control_Mode": 1, "Input_Mode": 1},
    )
    yield (
        n,
        "Set_Limits",
        od.encode_set_limits(n, abs(p), abs(a)),
        {
            "Velocity_Limit": f32(abs(p) / TWO_PI),
            "Current_Limit": f32(abs(a)),
        },
    )
    err = rng.getrandbits(32)
    yield n, "Heartbeat", od.encode_heartbeat(n, err, st), {"Axis_Error": err, "Axis_State": st}


def test_dbc_conformance_encode_then_cantools_decode(db):
    rng = random.Random(1)
    for _ in range(200):
        for node, name, frame, expected in cases(rng):
            msg = db.get_message_by_name(name)
            assert frame.arbitration_id == (node << 5) | msg.frame_id, name
            assert len(frame.data) == msg.length, name
            got = db.decode_message(msg.frame_id, frame.data)
            for k, val in expected.items():
                assert got[k] == pytest.approx(val, rel=1e-7, abs=1e-30), (name, k)


def test_dbc_conformance_cantools_encode_then_project_decode(db):
    rng = random.Random(2)
    dec = od.OdriveDecoder(range(64), role="any")
    for _ in range(200):
        node = rng.randrange(64)
        p, v, a, b = (rnd_float(rng) for _ in range(4))
        st = rng.choice([1, 8])
        err = rng.getrandbits(32)

        def enc(name, sig, node=node):
            m = db.get_message_by_name(name)
            return dec.decode((node << 5) | m.frame_id, m.encode(sig))

        e = enc("Get_Encoder_Estimates", {"Pos_Estimate": p, "Vel_Estimate": v})
        assert e == od.EncoderEstimates(node, pytest.approx(f32(p) * TWO_PI), pytest.approx(f32(v) * TWO_PI))
        assert enc("Get_Iq", {"Iq_Setpoint": a, "Iq_Measured": b}) == od.Iq(node, f32(a), f32(b))
        assert enc("Set_Input_Torque", {"Input_Torque": a}) == od.SetInputTorque(node, f32(a))
        assert enc("Set_Axis_State", {"Axis_Requested_State": st}) == od.SetAxisState(node, st)
        assert enc("Set_Controller_Mode", {"Control_Mode": 1, "Input_Mode": 1}) == od.SetControllerMode(
            node, 1, 1
        )
        lim = enc("Set_Limits", {"Velocity_Limit": abs(p), "Current_Limit": abs(a)})
        assert lim.velocity_limit == pytest.approx(f32(abs(p)) * TWO_PI) and lim.current_limit == f32(abs(a))
        hb = enc("Heartbeat", {"Axis_Error": err, "Axis_State": st})
        assert (hb.axis_error, hb.axis_state, hb.procedure_result) == (err, st, 0)
        vb = enc("Get_Vbus_Voltage", {"Vbus_Voltage": abs(a)})  # 0.5.x single-float form of 0x017
        assert vb.voltage == f32(abs(a)) and vb.current == 0.0  # unused upper bytes are 0


def test_dbc06_supplement_both_directions(db06):
    rng = random.Random(3)
    dec = od.OdriveDecoder(range(64), role="any")
    for _ in range(100):
        n = rng.randrange(64)
        a, b = rnd_float(rng), rnd_float(rng)
        err, dis = rng.getrandbits(32), rng.getrandbits(32)
        pairs = [
            (od.encode_torques(n, a, b), "Get_Torques", {"Torque_Target": f32(a), "Torque_Estimate": f32(b)}),
            (
                od.encode_bus_voltage_current(n, a, b),
                "Get_Bus_Voltage_Current",
                {"Bus_Voltage": f32(a), "Bus_Current": f32(b)},
            ),
            (od.encode_error(n, err, dis), "Get_Error", {"Active_Errors": err, "Disarm_Reason": dis}),
            (od.encode_clear_errors(n, 1), "Clear_Errors", {"Identify": 1}),
            (
                od.encode_heartbeat(n, err, 8, 3, True),
                "Heartbeat",
                {"Axis_Error": err, "Axis_State": 8, "Procedure_Result": 3, "Trajectory_Done_Flag": 1},
            ),
        ]
        for frame, name, expected in pairs:
            m = db06.get_message_by_name(name)
            assert frame.arbitration_id == (n << 5) | m.frame_id
            assert db06.decode_message(m.frame_id, frame.data) == pytest.approx(expected)
            back = dec.decode(frame.arbitration_id, m.encode(expected))
            assert back is not None, name
        assert dec.decode(
            (n << 5) | 28,
            db06.get_message_by_name("Get_Torques").encode({"Torque_Target": a, "Torque_Estimate": b}),
        ) == od.Torques(n, f32(a), f32(b))
        estop = od.encode_estop(n)
        assert estop.data == b"" and estop.arbitration_id == (n << 5) | 2
        assert dec.decode_frame(estop) == od.Estop(n)


def test_ids_rtr_and_worked_examples():
    assert od.arbitration_id(1, od.Cmd.GET_ENCODER_ESTIMATES) == 0x029
    assert od.arbitration_id(0, od.Cmd.SET_INPUT_TORQUE) == 0x00E
    assert od.split_id(0x029) == (1, 9)
    assert od.kernel_filter(3) == {"can_id": 0x060, "can_mask": 0x7E0, "extended": False}
    rtr = od.encode_rtr(5, od.Cmd.GET_IQ)
    assert rtr.is_remote and rtr.dlc == 8 and rtr.data == b"" and rtr.arbitration_id == (5 << 5) | 0x14
    host = od.OdriveDecoder([5], role="host")
    drive = od.OdriveDecoder([5], role="drive")
    assert host.decode_frame(rtr) is None and host.stats.ignored == 1
    assert drive.decode_frame(rtr) == od.RtrRequest(5, od.Cmd.GET_IQ)
    with pytest.raises(ParameterError, match="node_id = 64 is out of range"):
        od.arbitration_id(64, 1)
    with pytest.raises(ParameterError, match="not a telemetry message"):
        od.encode_rtr(1, od.Cmd.SET_INPUT_TORQUE)
    with pytest.raises(ParameterError, match="not finite"):
        od.encode_set_input_torque(1, math.nan)


def test_decoder_rejects_malformed_and_nan():
    dec = od.OdriveDecoder([1], role="host")
    assert dec.decode(0x029, b"\x00" * 4) is None  # too short
    nan = od._F2.pack(math.nan, 0.0)
    assert dec.decode(0x029, nan) is None
    assert dec.decode(0x049, b"\x00" * 8) is None  # node 2: ignored
    assert dec.decode(0x029, b"\x00" * 8, is_extended=True) is None
    assert (dec.stats.rejected, dec.stats.ignored, dec.stats.decoded) == (2, 2, 0)
    assert "not finite" in dec.stats.last_reject_reason


# ---- MIT ---------------------------------------------------------------------------------------------
GOLDEN_COMMANDS = [
    # (p, v, kp, kd, t) -> bytes, default ranges P +-12.5, V +-65, KP 0..500, KD 0..5, T +-18
    ((0.0, 0.0, 0.0, 0.0, 0.0), "7fff7ff0000007ff"),
    ((12.5, 65.0, 500.0, 5.0, 18.0), "ffffffffffffffff"),
    ((-12.5, -65.0, 0.0, 0.0, -18.0), "0000000000000000"),
    ((100.0, 1e3, 1e4, 99.0, 1e3), "ffffffffffffffff"),  # clamped to the range maxima
    ((-100.0, -1e3, -5.0, -1.0, -1e3), "0000000000000000"),  # clamped to the minima
    ((1.0, 10.0, 50.0, 1.0, -3.0), "8a3c93a1993336aa"),  # truncation: 35388.9 -> 35388, 2362.5 -> 2362 ...
]


@pytest.mark.parametrize(("args", "hexdata"), GOLDEN_COMMANDS)
def test_mit_command_golden(args, hexdata):
    codec = mitc.MitCodec(1)
    f = codec.encode_command(*args)
    assert f.arbitration_id == 1 and f.data.hex() == hexdata
    back = codec.decode_command(f.data)
    r = codec.r
    for got, want, lo, hi, bits in zip(
        back[1:],
        args,
        (r.p_min, r.v_min, r.kp_min, r.kd_min, r.t_min),
        (r.p_max, r.v_max, r.kp_max, r.kd_max, r.t_max),
        (16, 12, 12, 12, 12),
    ):
        lsb = (hi - lo) / ((1 << bits) - 1)
        assert min(max(want, lo), hi) - lsb - 1e-12 <= got <= min(max(want, lo), hi) + 1e-12


def test_mit_reply_golden_and_special_frames():
    codec = mitc.MitCodec(1)
    assert codec.encode_reply(0.0, 0.0, 0.0).data.hex() == "017fff7ff7ff"
    assert codec.encode_reply(0.0, 0.0, 0.0, temperature=25, error=0).data.hex() == "017fff7ff7ff1900"
    assert codec.encode_reply(99.0, -99.0, 99.0).data.hex() == "01ffff000fff"
    r = codec.decode_reply(bytes.fromhex("017fff7ff7ff1903"))
    assert r.motor_id == 1 and abs(r.position) < 25 / 65535 and abs(r.torque) < 36 / 4095
    assert r.temperature == 25 and r.error == 3
    assert codec.encode_enter().data.hex() == "fffffffffffffffc"
    assert codec.encode_exit().data.hex() == "fffffffffffffffd"
    assert codec.encode_zero().data.hex() == "fffffffffffffffe"
    dec = mitc.MitDecoder(codec, role="drive")
    assert dec.decode(1, codec.encode_exit().data) == mitc.MitSpecial(1, "exit")
    host = mitc.MitDecoder(codec, role="host")
    assert host.decode(0, bytes.fromhex("027fff7ff7ff")) is None  # reply of motor 2: ignored
    assert host.decode(0, bytes.fromhex("017fff7ff7")) is None  # 5 bytes: rejected
    assert (host.stats.ignored, host.stats.rejected) == (1, 1)
    # custom ranges (AK80-64: V +-8, T +-144)
    ak = mitc.MitCodec(3, mitc.MitRanges(v_min=-8, v_max=8, t_min=-144, t_max=144))
    assert ak.decode_command(ak.encode_command(torque=100.0).data).torque == pytest.approx(
        100.0, abs=288 / 4095
    )
    with pytest.raises(ParameterError, match="mit.t_max = -20 is out of range"):
        mitc.MitRanges(t_max=-20.0)
    with pytest.raises(ParameterError, match="not finite"):
        codec.encode_command(torque=math.inf)


# ---- fuzz --------------------------------------------------------------------------------------------
def random_frames(n, seed):
    rng = random.Random(seed)
    for _ in range(n):
        ext = rng.random() < 0.05
        arb = rng.getrandbits(29) if ext else rng.getrandbits(11)
        length = rng.choice([0, 1, 2, 3, 4, 5, 6, 7, 8, 8, 8, 8, 12, 64])
        data = rng.randbytes(length)
        if rng.random() < 0.05:  # NaN / inf floats in plausible telemetry
            data = od._F2.pack(rng.choice([math.nan, math.inf, -math.inf]), 0.0)
        yield arb, data, rng.random() < 0.05, ext, rng.random() < 0.01


def test_fuzz_100k_frames_never_raise_and_are_counted():
    n = 100_000
    frames = list(random_frames(n, 42))
    decoders = [
        od.OdriveDecoder(range(64), role="any"),
        od.OdriveDecoder([0, 1], role="host"),
        mitc.MitDecoder(mitc.MitCodec(1), role="any"),
    ]
    axis = DriveAxis(AxisConfig())
    for arb, data, rtr, ext, err in frames:
        for d in decoders:
            d.decode(arb, data, rtr, ext, err)
        axis.on_frame(arb, data, rtr, ext, err, 0.0)
    for d in decoders:
        s = d.stats
        assert s.total == n
        assert s.decoded > 0 and s.ignored > 0 and s.rejected > 0, s
    assert axis.decode_stats.total == n
    # garbage must never produce NaN telemetry
    assert not any(
        math.isnan(x) or math.isinf(x)
        for x in (axis.telemetry.motor_position,)
        if axis.telemetry.encoder_time
    )


# ---- joint conversion -------------------------------------------------------------------------------
def test_joint_conversion_round_trip_and_validation():
    c = JointConversion(gear_ratio=9.0, torque_constant=0.091, direction=-1, zero_offset=0.2)
    assert c.joint_position(c.motor_position(1.234)) == pytest.approx(1.234)
    assert c.joint_velocity(9.0) == pytest.approx(-1.0)
    assert c.joint_torque(c.motor_torque(2.5)) == pytest.approx(2.5)
    assert c.joint_torque_from_current(c.motor_current(2.5)) == pytest.approx(2.5)
    assert c.motor_torque(9.0) == pytest.approx(-1.0)
    with pytest.raises(ParameterError, match="direction = 0 is not allowed"):
        JointConversion(direction=0)
    with pytest.raises(ParameterError, match="gear_ratio = -2 is out of range"):
        JointConversion(gear_ratio=-2.0)


def test_core_can_does_not_import_rclpy():
    import subprocess

    code = "import sys, friction_ros.core.can.emulator, friction_ros.core.can; print('rclpy' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False"
