"""CiA 402 pure core: EDS, state machine (both sides, against canopen's tables), PDO codecs (against
canopen's generic PDO machinery), SDO frames, units, configuration errors. No bus, no threads."""

from __future__ import annotations

import math
import subprocess
import sys

import canopen
import pytest
from canopen.profiles.p402 import State402

from friction_ros.core.can.cia402 import frames as fr
from friction_ros.core.can.cia402 import objects as ob
from friction_ros.core.can.cia402.config import Cia402Config, eds_defaults
from friction_ros.core.can.cia402.emulator import DEFAULT_EDS
from friction_ros.core.can.cia402.sdo_script import SdoScript, SdoStep
from friction_ros.core.can.cia402.state_machine import (
    STATE_NAMES,
    STATE_STATUSWORD,
    DriveStateMachine,
    State,
    master_controlword,
    state_from_statusword,
)
from friction_ros.core.can.cia402.units import Cia402Scaling
from friction_ros.core.can.joint import JointConversion
from friction_ros.core.validation import ParameterError

REQUIRED = {  # index: data type (CiA 402-2 / CiA 301)
    0x1000: 0x7, 0x1017: 0x6, 0x1005: 0x7, 0x1006: 0x7, 0x6040: 0x6, 0x6041: 0x6, 0x6060: 0x2, 0x6061: 0x2,
    0x6064: 0x4, 0x606C: 0x4, 0x6071: 0x3, 0x6072: 0x6, 0x6076: 0x7, 0x6077: 0x3, 0x6078: 0x3,
}  # fmt: skip


def test_eds_loads_with_canopen_and_default_mapping_is_the_drivers():
    od = canopen.import_od(DEFAULT_EDS, 5)
    for index, data_type in REQUIRED.items():
        assert od[index].data_type == data_type, hex(index)
    for comm, mapping, cob, entries in (
        (0x1400, 0x1600, 0x205, fr.RPDO1_MAP),
        (0x1800, 0x1A00, 0x185, fr.TPDO1_MAP),
        (0x1801, 0x1A01, 0x285, fr.TPDO2_MAP),
    ):
        assert od[comm][1].default == cob  # $NODEID resolved
        assert od[comm][2].default == ob.SYNC_TRANSMISSION
        assert od[mapping][0].default == len(entries)
        assert tuple(od[mapping][k + 1].default for k in range(len(entries))) == entries
    assert od[0x6502].default & 0x200  # cyclic synchronous torque supported
    assert eds_defaults(DEFAULT_EDS) == {
        "counts_per_rev": 131072, "gear_ratio": 1.0, "rated_torque": 1.0, "rated_current": 10.0,
    }  # fmt: skip


def test_statusword_states_agree_with_canopen_p402():
    for state, sw in STATE_STATUSWORD.items():
        name = STATE_NAMES[state]
        mask, value = State402.SW_MASK[name]
        assert sw & mask == value
        assert state_from_statusword(sw | 0x10 | 0x200) == state  # voltage enabled / remote bits ignored
    assert state_from_statusword(0x0237) == State.OPERATION_ENABLED


def test_master_walk_matches_canopen_transition_table_and_reaches_operation_enabled():
    drive = DriveStateMachine()
    cw, path = 0, []
    for _ in range(6):
        before = drive.state
        cw = master_controlword(drive.state, State.OPERATION_ENABLED, cw)
        if before != State.OPERATION_ENABLED:
            nxt = State402.next_state_indirect(STATE_NAMES[before])
            assert State402.TRANSITIONTABLE[(STATE_NAMES[before], nxt)] == cw
        drive.apply(cw)
        path.append(drive.state)
    assert path[:3] == [State.READY_TO_SWITCH_ON, State.SWITCHED_ON, State.OPERATION_ENABLED]
    assert path[3:] == [State.OPERATION_ENABLED] * 3


def test_fault_needs_rising_edge_of_reset_bit_and_a_cleared_condition():
    drive = DriveStateMachine()
    drive.fault()
    assert drive.apply(0x0F) == State.FAULT  # reaction done
    assert drive.apply(0x80) == State.FAULT  # condition still active
    drive.clear_fault()
    assert drive.apply(0x80) == State.FAULT  # bit 7 held: no edge
    cw = master_controlword(State.FAULT, State.OPERATION_ENABLED, 0x80)
    assert cw == 0x00
    drive.apply(cw)
    cw = master_controlword(State.FAULT, State.OPERATION_ENABLED, cw)
    assert cw == 0x80 and drive.apply(cw) == State.SWITCH_ON_DISABLED


def test_quick_stop_then_disable_voltage():
    drive = DriveStateMachine()
    for cw in (0x06, 0x07, 0x0F):
        drive.apply(cw)
    cw = master_controlword(drive.state, State.QUICK_STOP_ACTIVE)
    assert cw == 0x02 and drive.apply(cw) == State.QUICK_STOP_ACTIVE
    assert drive.statusword & 0x6F == 0x07
    cw = master_controlword(drive.state, State.SWITCH_ON_DISABLED)
    assert cw == 0x00 and drive.apply(cw) == State.SWITCH_ON_DISABLED


def _canopen_pdo(index_map):
    """canopen's own PdoMap for one of the EDS's PDOs (generic machinery, read from the OD)."""
    node = canopen.Network().add_node(3, DEFAULT_EDS)
    pdo = {0x1600: node.rpdo[1], 0x1A00: node.tpdo[1], 0x1A01: node.tpdo[2]}[index_map]
    pdo.read(from_od=True)
    return pdo


@pytest.mark.parametrize("cw,tq", [(0x0F, -1234), (0x06, 0), (0x80, 32767), (0x02, -32768)])
def test_rpdo1_struct_packing_equals_canopen_pdo_map(cw, tq):
    pdo = _canopen_pdo(0x1600)
    pdo["Controlword"].raw = cw
    pdo["Target torque"].raw = tq
    assert fr.RPDO1.pack(cw, tq) == bytes(pdo.data)


def test_tpdo_struct_unpacking_equals_canopen_pdo_map():
    data1 = fr.TPDO1.pack(0x0237, -250, -7_000_123)
    pdo = _canopen_pdo(0x1A00)
    pdo.on_message(pdo.cob_id, bytearray(data1), 0.0)
    assert [v.raw for v in pdo] == [0x0237, -250, -7_000_123] == list(fr.TPDO1.unpack(data1))
    data2 = fr.TPDO2.pack(-400_000, 999)
    pdo2 = _canopen_pdo(0x1A01)
    pdo2.on_message(pdo2.cob_id, bytearray(data2), 0.0)
    assert [v.raw for v in pdo2] == [-400_000, 999]


def test_sdo_frames_and_script():
    f = fr.sdo_download(4, 0x6060, 0, 10, 1, True)
    assert f.arbitration_id == 0x604 and f.data == bytes([0x2F, 0x60, 0x60, 0, 10, 0, 0, 0])
    f = fr.sdo_download(4, 0x1017, 0, 100, 2)
    assert f.data == bytes([0x2B, 0x17, 0x10, 0, 100, 0, 0, 0])
    assert fr.sdo_upload(4, 0x6076, 0).data == bytes([0x40, 0x76, 0x60, 0, 0, 0, 0, 0])
    script = SdoScript(4, [SdoStep(0x6076, 0), SdoStep(0x6072, 0, 2000, 2)], timeout=0.1, retries=1)
    assert script.poll(0.0).data[0] == 0x40
    assert script.poll(0.05) is None  # waiting for the answer
    script.on_response(bytes([0x43, 0x76, 0x60, 0, 0xE8, 0x03, 0, 0]))  # upload 1000
    assert script.values[(0x6076, 0)] == 1000
    assert script.poll(0.06).data[:3] == bytes([0x2B, 0x72, 0x60])
    script.on_response(bytes([0x80, 0x72, 0x60, 0, 0x31, 0x00, 0x09, 0x06]))  # abort 0x06090031
    assert (
        script.done and "0x6072:00" in script.error and "value of parameter written too high" in script.error
    )
    late = SdoScript(4, [SdoStep(0x6076, 0)], timeout=0.01, retries=1)
    late.poll(0.0), late.poll(0.02), late.poll(0.04)
    assert late.error == "SDO timeout reading 0x6076:00 on node 4 (2 tries)"


def test_units_revolute_and_prismatic():
    sc = Cia402Scaling(4096, 0.5, 8.0, JointConversion(gear_ratio=100.0, direction=-1, zero_offset=0.1))
    assert sc.joint_position(4096 * 100) == pytest.approx(-2 * math.pi - 0.1)
    assert sc.joint_velocity(4096) == pytest.approx(-2 * math.pi / 100)
    assert sc.joint_torque(1000) == pytest.approx(-50.0)  # rated 0.5 N*m at the motor x 100
    assert sc.torque_permille(-25.0) == 500 and sc.torque_permille(1e9) == -32768
    assert sc.current(-250) == pytest.approx(-2.0)
    lin = Cia402Scaling(10000, 0.2, 3.0, JointConversion(lead=0.005))  # 5 mm per motor turn
    assert lin.joint_position(10000) == pytest.approx(0.005)
    assert lin.joint_torque(1000) == pytest.approx(0.2 * 2 * math.pi / 0.005)  # N


@pytest.mark.parametrize(
    "kwargs,text",
    [
        ({"node_id": 0}, "node_id = 0 is out of range: must be an integer in [1, 127]"),
        ({"heartbeat_ms": 0}, "heartbeat_ms = 0 is out of range"),
        ({"gear_ratio": -1.0}, "gear_ratio = -1 is out of range"),
        ({"lead": 0.01, "gear_ratio": 5.0}, "leave gear_ratio at 0 or 1"),
        ({"direction": 2}, "direction = 2 is not allowed: must be one of 1, -1"),
    ],
)
def test_bad_configuration_names_the_parameter(kwargs, text):
    with pytest.raises(ParameterError, match=".*") as err:
        Cia402Config(**kwargs)
    assert text in str(err.value) and "\n" not in str(err.value)


def test_bad_eds_path_is_one_line(tmp_path):
    bad = tmp_path / "broken.eds"
    bad.write_text("[1000]\nObjectType=banana\n")
    with pytest.raises(ParameterError) as err:
        eds_defaults(str(bad))
    assert str(err.value).startswith(f"eds_path = '{bad}' does not load as an EDS")


def test_core_imports_no_rclpy():
    code = "import sys, friction_ros.core.can.cia402.emulator, friction_ros.core.can.cia402; print('rclpy' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False"


def test_master_unwraps_int32_position_and_converts_telemetry():
    from friction_ros.core.can.cia402 import Cia402Master

    m = Cia402Master(
        Cia402Config(node_id=2, counts_per_rev=1000, gear_ratio=2.0, rated_torque=0.5, rated_current=4.0)
    )
    m.start(0.0)
    m.step(0.0)  # no unit to read: straight to the configuration writes
    assert m.phase == "configure" and m.scaling is not None
    top = 2**31 - 10
    m.handle(0x182, fr.TPDO1.pack(0x0237, 100, top), 0.01)
    m.handle(0x282, fr.TPDO2.pack(500, -250), 0.01)
    m.handle(0x182, fr.TPDO1.pack(0x0237, 100, -(2**31) + 10), 0.02)  # wrapped: +20 counts
    tel = m.telemetry
    assert tel.position == pytest.approx((top + 20) / 1000 * 2 * math.pi / 2.0)
    assert tel.velocity == pytest.approx(0.5 * 2 * math.pi / 2.0)  # 500 counts/s, gear 2
    assert tel.torque == pytest.approx(0.1 * 0.5 * 2.0) and tel.current == pytest.approx(-1.0)
    assert tel.state == State.OPERATION_ENABLED
