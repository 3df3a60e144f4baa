"""CiA 402 on a real python-can bus (``virtual`` and ``friction_local``): the project's driver
(Cia402Network + Cia402Master) against the emulated drive (canopen LocalNode + plant), the emulator
against canopen's own master-side CiA 402 support (BaseNode402), the driver against a reference drive
built only from canopen's LocalNode and canopen's p402 tables; several drives with one SYNC; faults."""

from __future__ import annotations

import time
import uuid

import can
import canopen
import pytest
from can_support import StandInPlant, make_plant
from canopen.profiles.p402 import BaseNode402, State402

from friction_ros.core.can.cia402 import Cia402Config, Cia402Master, Cia402Network, State
from friction_ros.core.can.cia402.emulator import DEFAULT_EDS, emulated_drives
from friction_ros.core.can.joint import JointConversion

PERIOD = 2e-3


class Sniffer(can.Listener):
    def __init__(self):
        self.frames = []

    def on_message_received(self, msg):
        self.frames.append((msg.arbitration_id, bytes(msg.data)))


def stand_in():
    """A cheap rigid plant (torque in) with a gear ratio of 10 and k_t = 0.5 N*m/A."""
    return StandInPlant(inertia=0.5, viscous=0.5, coulomb=0.2), JointConversion(
        gear_ratio=10.0, torque_constant=0.5
    )


@pytest.fixture
def bench():
    """make(node_ids, interface, **master_cfg) -> (net, masters, drives, emulator network, sniffer)."""
    made = []

    def make(node_ids=(1,), interface="virtual", channel=None, plant=stand_in, **cfg):
        channel = channel or f"cia402-{uuid.uuid4().hex[:8]}"
        enet, drives = emulated_drives(
            can.Bus(interface=interface, channel=channel), node_ids, plant_factory=plant
        )
        sniff_bus = can.Bus(interface=interface, channel=channel)
        sniffer = Sniffer()
        notifier = can.Notifier(sniff_bus, [sniffer], timeout=0.05)
        masters = [Cia402Master(Cia402Config(node_id=n, **cfg)) for n in node_ids]
        net = Cia402Network(can.Bus(interface=interface, channel=channel), masters, PERIOD)
        made.append((net, enet, drives, notifier, sniff_bus))
        return net, masters, drives, enet, sniffer

    yield make
    for net, enet, drives, notifier, sniff_bus in made:
        for d in drives:
            d.stop()
        notifier.stop()
        sniff_bus.shutdown()
        net.bus.shutdown()
        enet.disconnect()


def _enable(net, masters, timeout=2.0):
    net.start()
    assert net.run_until(lambda: all(m.phase == "operational" for m in masters), timeout), [
        m.fault for m in masters
    ]
    t = time.monotonic()
    for m in masters:
        m.enable(t)
    assert net.run_until(lambda: all(m.enabled for m in masters), timeout), [m.fault for m in masters]


def test_driver_configures_enables_and_commands_torque_on_emulator(bench):
    net, (m,), (d,), _, sniffer = bench((3,), plant=make_plant)  # the project's plant (abb_m19s)
    _enable(net, [m])
    # start-up wrote CST mode, heartbeat time and the mapping by SDO; units were read from the drive
    assert d.get(0x6060) == 10 and d.get(0x1017) == 100 and d.get(0x1A00, 0) == 3
    assert m.units == {
        "counts_per_rev": 131072,
        "gear_ratio": 1.0,
        "rated_torque": 1.0,
        "rated_current": 2.041,
    }
    assert d.state_log[-3:] == [State.READY_TO_SWITCH_ON, State.SWITCHED_ON, State.OPERATION_ENABLED]
    m.set_torque(0.75)
    net.run_until(lambda: False, 0.3)
    assert d.applied_torque == pytest.approx(0.75)  # motor side, gear ratio 1, rated 1 N*m: 750 per mille
    tel = m.telemetry
    assert tel.state == State.OPERATION_ENABLED and tel.torque == pytest.approx(0.75, abs=0.02)  # measured
    assert tel.position > 0.005  # it moved (abb_m19s sticks and slips at this torque)
    assert tel.position == pytest.approx(d.meas.position, abs=0.01)
    assert tel.current == pytest.approx(d.meas.motor_current, rel=0.01)
    assert m.fault == "" and net.send_errors == 0
    rpdo = [data for cob, data in sniffer.frames if cob == 0x203]
    assert rpdo[-1] == bytes([0x0F, 0x00]) + (750).to_bytes(2, "little")


def test_canopen_basenode402_walks_the_emulator_to_operation_enabled(bench):
    channel = f"cia402-{uuid.uuid4().hex[:8]}"
    _, _, (d,), _, _ = bench((4,), channel=channel)
    network = canopen.Network(can.Bus(interface="virtual", channel=channel))
    network.connect()
    try:
        node = BaseNode402(4, DEFAULT_EDS)
        network.add_node(node)
        node.nmt.state = "PRE-OPERATIONAL"
        node.setup_402_state_machine()  # reads the PDO configuration by SDO from the emulator
        node.sdo[0x6060].raw = 10
        node.nmt.state = "OPERATIONAL"
        network.sync.start(PERIOD)
        node.rpdo[1].start(PERIOD)
        node.state = "OPERATION ENABLED"
        assert node.state == "OPERATION ENABLED" and d.sm.state == State.OPERATION_ENABLED
        assert node.op_mode == "CYCLIC SYNCHRONOUS TORQUE"
        node.state = "SWITCH ON DISABLED"
        assert d.sm.state == State.SWITCH_ON_DISABLED
    finally:
        network.disconnect()


class ReferenceDrive:
    """A drive made only of canopen parts: LocalNode (SDO, NMT, heartbeat), canopen's PdoMap for the
    PDOs and canopen's p402 TRANSITIONTABLE / SW_MASK for the state machine."""

    def __init__(self, network, node_id):
        self.node = canopen.LocalNode(node_id, DEFAULT_EDS)
        self.state = "SWITCH ON DISABLED"
        self.cw = 0
        self.network = network
        network.add_node(self.node)
        network.subscribe(0x80, self.on_sync)
        network.subscribe(0, self.on_nmt)
        self.node.nmt.send_command(0x81)
        self.node.nmt.send_command(0x80)

    def on_nmt(self, can_id, data, ts):
        if self.node.nmt.state == "OPERATIONAL":
            self.node.rpdo.read()
            self.node.tpdo.read()
            self.node.rpdo[1].add_callback(lambda pdo: setattr(self, "cw", pdo["Controlword"].raw))

    def on_sync(self, can_id, data, ts):
        if self.node.nmt.state != "OPERATIONAL":
            return
        for (src, dst), cw in State402.TRANSITIONTABLE.items():
            if src == self.state and cw == self.cw and src != dst:
                self.state = dst
                break
        tpdo = self.node.tpdo[1]
        tpdo["Statusword"].raw = State402.SW_MASK[self.state][1]
        tpdo.transmit()
        self.node.tpdo[2].transmit()


def test_driver_walks_a_reference_canopen_drive(bench):
    channel = f"cia402-{uuid.uuid4().hex[:8]}"
    network = canopen.Network(can.Bus(interface="virtual", channel=channel))
    network.connect()
    try:
        ref = ReferenceDrive(network, 9)
        m = Cia402Master(Cia402Config(node_id=9, eds_path=DEFAULT_EDS))
        net = Cia402Network(can.Bus(interface="virtual", channel=channel), [m], PERIOD)
        _enable(net, [m])
        assert ref.state == "OPERATION ENABLED" and m.state == State.OPERATION_ENABLED
        assert m.units["rated_torque"] == 1.0  # from the EDS, not read from the drive
        net.close()
        time.sleep(0.05)
        assert ref.state == "SWITCH ON DISABLED" and ref.node.nmt.state == "PRE-OPERATIONAL"
        net.bus.shutdown()
    finally:
        network.disconnect()


def test_three_drives_one_sync(bench):
    net, masters, drives, _, sniffer = bench((1, 2, 3))
    _enable(net, masters)
    for k, m in enumerate(masters):
        m.set_torque(0.1 * (k + 1))
    syncs0 = [d.syncs for d in drives]
    n0 = len(sniffer.frames)
    # 30 periods (0.03 s on a quiet machine; up to 5 s of wall time on a loaded one: the count matters here)
    net.run_until(lambda: sum(1 for cob, _ in sniffer.frames[n0:] if cob == 0x80) >= 30, 5.0)
    time.sleep(0.1)  # the last frames reach the drives and the sniffer
    frames = sniffer.frames[n0:]
    n_sync = sum(1 for cob, _ in frames if cob == 0x80)
    assert n_sync >= 30
    for d, s0 in zip(drives, syncs0):
        assert d.syncs - s0 == pytest.approx(n_sync, abs=2)  # every drive saw every SYNC
    for n in (1, 2, 3):  # one RPDO per node per SYNC
        assert sum(1 for cob, _ in frames if cob == 0x200 + n) == pytest.approx(n_sync, abs=2)
    # joint torque 0.1 / 0.2 / 0.3 N*m through gear ratio 10: motor torque 10 / 20 / 30 mN*m
    assert [d.applied_torque for d in drives] == pytest.approx([0.01, 0.02, 0.03])
    assert [m.telemetry.torque for m in masters] == pytest.approx([0.1, 0.2, 0.3])
    assert all(m.telemetry.velocity > 0 for m in masters)


def test_over_torque_emcy_latches_fault_with_text_and_enable_resets(bench):
    net, (m,), (d,), _, _ = bench((2,))
    _enable(net, [m])
    d.set_max_torque(300)  # the drive's own limit lowered to 30 % of rated: 0.3 N*m motor, 3 N*m joint
    m.set_torque(5.0)
    assert net.run_until(lambda: bool(m.fault), 1.0)
    assert "drive node 2 EMCY 0x8311 excess torque (error register 0x01)" in m.fault
    assert net.run_until(lambda: m.state == State.FAULT, 1.0)
    assert d.applied_torque == 0.0 and d.error_code == 0x8311
    net.run_until(lambda: False, 0.05)
    assert m.fault  # latched
    m.set_torque(2.0)
    m.enable(time.monotonic())
    assert net.run_until(lambda: m.enabled, 1.0), m.fault
    assert d.emcy_sent == [0x8311, 0x0000] and d.error_code == 0
    net.run_until(lambda: False, 0.05)
    assert d.applied_torque == pytest.approx(0.2)  # motor side


def test_missing_heartbeat_is_a_fault_and_the_drive_is_stopped(bench):
    net, (m,), (d,), _, _ = bench((5,), heartbeat_ms=20, heartbeat_timeout=0.05)
    _enable(net, [m])
    m.set_torque(0.2)
    net.run_until(lambda: False, 0.1)
    assert m.fault == ""
    d.node.nmt.stop_heartbeat()  # PDOs continue, heartbeat stops
    t0 = time.monotonic()
    assert net.run_until(lambda: bool(m.fault), 1.0)
    assert m.fault == "heartbeat of drive node 5 missing for more than 50 ms"
    assert 0.02 <= time.monotonic() - t0 < 0.5  # 50 ms after the last heartbeat (20 ms period)
    assert net.run_until(lambda: d.sm.state == State.SWITCH_ON_DISABLED, 1.0)
    assert State.QUICK_STOP_ACTIVE in d.state_log[-2:] and d.applied_torque == 0.0


def test_silent_drive_is_stale_telemetry_fault(bench):
    net, (m,), (d,), _, _ = bench((6,), telemetry_timeout=0.05)
    _enable(net, [m])
    d.set_silent()
    assert net.run_until(lambda: bool(m.fault), 1.0)
    assert m.fault == "telemetry of drive node 6 stale: no TPDO1 for more than 50 ms"
    assert m.torque_permille == 0


def test_exit_sends_quick_stop_then_disable_on_friction_local(bench, tmp_path, monkeypatch):
    monkeypatch.setenv("FRICTION_CAN_DIR", str(tmp_path))
    net, (m,), (d,), _, sniffer = bench((7,), interface="friction_local", channel="cia402")
    _enable(net, [m])
    m.set_torque(0.3)
    net.run_until(lambda: False, 0.05)
    n0 = len(sniffer.frames)
    net.close()
    time.sleep(0.05)
    out = [(cob, data) for cob, data in sniffer.frames[n0:] if cob in (0x207, 0x000)]
    assert out == [(0x207, bytes([0x02, 0, 0, 0])), (0x207, bytes(4)), (0x000, bytes([0x80, 7]))]
    assert d.state_log[-2:] == [State.QUICK_STOP_ACTIVE, State.SWITCH_ON_DISABLED]
    assert d.node.nmt.state == "PRE-OPERATIONAL" and d.applied_torque == 0.0


def test_absent_drive_is_one_line_sdo_timeout(bench):
    channel = f"cia402-{uuid.uuid4().hex[:8]}"
    m = Cia402Master(Cia402Config(node_id=11, sdo_timeout=0.01, sdo_retries=1))
    net = Cia402Network(can.Bus(interface="virtual", channel=channel), [m], PERIOD)
    net.start()
    assert net.run_until(lambda: m.phase == "failed", 1.0)
    assert m.fault == "SDO timeout reading 0x608F:01 on node 11 (2 tries)"
    net.bus.shutdown()
