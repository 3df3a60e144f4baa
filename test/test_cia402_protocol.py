"""The registered ``cia402`` drive protocol: the real DriveAxis + CanBusLink (host) against the
emulated CiA 402 drives (canopen LocalNode + plant) on a python-can ``virtual`` bus, in real time."""

from __future__ import annotations

import math
import time
import uuid

import can
import pytest
from can_support import StandInPlant

from friction_ros.core.can.axis import DriveAxis
from friction_ros.core.can.axis_config import AxisConfig
from friction_ros.core.can.cia402 import State
from friction_ros.core.can.cia402.emulator import emulated_drives
from friction_ros.core.can.cia402.protocol import Cia402Protocol, set_axis_parameters
from friction_ros.core.can.drive_set import frame_router
from friction_ros.core.can.faults import FAULT_DRIVE_ERROR
from friction_ros.core.can.joint import JointConversion
from friction_ros.core.can.protocol import drive_protocol
from friction_ros.core.validation import ParameterError
from friction_ros.nodes.can_bus import CanBusLink

DT = 0.002
CONV = JointConversion(gear_ratio=10.0, torque_constant=0.5)


class Logger:
    def error(self, *a, **k):
        raise AssertionError(a)

    warning = error


class Rig:
    def __init__(self, node_ids):
        channel = f"cia402p-{uuid.uuid4().hex[:8]}"
        plant = lambda: (StandInPlant(inertia=0.5, viscous=0.5, coulomb=0.2), CONV)  # noqa: E731
        self.enet, self.drives = emulated_drives(
            can.Bus(interface="virtual", channel=channel), node_ids, plant_factory=plant
        )
        self.axes = [
            DriveAxis(
                AxisConfig(
                    protocol="cia402",
                    node_id=n,
                    conversion=CONV,
                    telemetry_period=DT,
                    torque_limit=5.0,
                    effort_source="torque_estimate",
                    command_timeout=1.0,  # a loaded test machine pauses this loop for 100 ms and more
                )
            )
            for n in node_ids
        ]
        self.link = CanBusLink(
            "virtual", channel, 1_000_000, self.axes, frame_router(self.axes), 5, 1.0, Logger()
        )
        self.results = []

    def run(self, seconds, torques=None, until=None):
        nxt = time.monotonic()
        end = nxt + seconds
        while time.monotonic() < end:
            now = time.monotonic()
            self.link.receive(now)
            for k, a in enumerate(self.axes):
                if torques is not None:
                    a.set_command(torques[k], now)
                r = a.cycle(now)
                self.results.append(r)
                assert self.link.send(r.frames)
            if until is not None and until():
                return True
            nxt += DT
            time.sleep(max(0.0, nxt - time.monotonic()))
        return False

    def close(self):
        self.link.send([f for a in self.axes for f in a.shutdown_frames()])
        time.sleep(0.05)
        self.link.close()
        for d in self.drives:
            d.stop()
        self.enet.disconnect()


@pytest.fixture
def rig():
    made = []

    def make(node_ids):
        made.append(Rig(node_ids))
        return made[-1]

    yield make
    for r in made:
        r.close()


def test_registered_and_checks_node_id():
    assert drive_protocol("cia402") is Cia402Protocol
    with pytest.raises(
        ParameterError,
        match=r"^node_id = 0 is out of range: must be an integer in \[1, 127\], i.e. >= 1 and <= 127$",
    ):
        AxisConfig(protocol="cia402", node_id=0)


def test_drive_axis_enables_and_commands_two_cia402_drives_with_one_sync(rig):
    r = rig([1, 2])
    assert r.run(2.0, until=lambda: all(a.protocol.master.phase == "operational" for a in r.axes))
    for a in r.axes:
        a.request_enable()
    ok = r.run(2.0, [0.0, 0.0], until=lambda: all(d.sm.state == State.OPERATION_ENABLED for d in r.drives))
    assert ok, [a.fault_reason for a in r.axes]
    r.run(0.4, [2.0, -3.0])
    # joint torque 2 / -3 N*m through gear ratio 10: 0.2 / -0.3 N*m at the motor
    assert [d.applied_torque for d in r.drives] == pytest.approx([0.2, -0.3])
    s = [next(x.sample for x in r.results[-2 + k :: -2] if x.sample) for k in (0, 1)]
    efforts = [sorted(x.sample.effort for x in r.results[-40 + k :: 2] if x.sample) for k in (0, 1)]
    median = [e[len(e) // 2] for e in efforts]  # late periods (no fresh telemetry) have no sample
    assert median == pytest.approx([2.0, -3.0], abs=0.01)
    assert s[0].velocity > 0 > s[1].velocity
    assert s[0].position == pytest.approx(r.drives[0].meas.position, abs=0.02)
    assert all(a.enabled and not a.latched for a in r.axes)
    syncs = [d.syncs for d in r.drives]
    assert syncs[0] == pytest.approx(syncs[1], abs=2)  # both saw the same SYNCs
    n_periods = len(r.results) // 2
    assert syncs[0] <= n_periods + 2  # one SYNC per period for both drives, not two


def test_emcy_reaches_drive_axis_as_drive_error_with_text(rig):
    r = rig([3])
    a, d = r.axes[0], r.drives[0]
    r.run(2.0, until=lambda: a.protocol.master.phase == "operational")
    a.request_enable()
    assert r.run(2.0, [0.0], until=lambda: d.sm.state == State.OPERATION_ENABLED)
    d.set_max_torque(100)  # the drive's limit: 0.1 N*m motor = 1 N*m joint
    assert r.run(1.0, [2.0], until=lambda: bool(a.latched))
    assert a.latched & FAULT_DRIVE_ERROR and not a.enabled
    assert a.fault_reason == "drive reports error 0x8311 (excess torque)"
    assert r.run(1.0, [0.0], until=lambda: d.sm.state in (State.SWITCH_ON_DISABLED, State.FAULT))
    assert d.applied_torque == 0.0 and d.emcy_sent == [0x8311]


def test_set_axis_parameters_reach_the_master():
    set_axis_parameters(7, counts_per_rev=4096, rated_torque=2.5, rated_current=6.0)
    p = Cia402Protocol(AxisConfig(protocol="cia402", node_id=7, conversion=JointConversion(gear_ratio=50.0)))
    assert p.master.units == {
        "counts_per_rev": 4096,
        "gear_ratio": 1.0,
        "rated_torque": 2.5,
        "rated_current": 6.0,
    }


def test_drive_interface_parameters_reach_the_master():
    from friction_ros.core.can.axis_config import AXIS_SCHEMA, axis_config
    from friction_ros.core.can.cia402.emulator import DEFAULT_EDS
    from friction_ros.core.config import flatten

    v = flatten(AXIS_SCHEMA.validate({}, ""))
    v.update({"protocol": "cia402", "node_id": 12, "gear_ratio": 50.0, "cia402.eds_path": DEFAULT_EDS})
    v.update({"cia402.rated_torque": 0.8, "cia402.heartbeat_ms": 20})
    p = Cia402Protocol(axis_config(v, 1000.0))
    m = p.master
    assert m.units == {
        "counts_per_rev": 131072,
        "gear_ratio": 1.0,
        "rated_torque": 0.8,
        "rated_current": 10.0,
    }
    assert m.cfg.heartbeat_ms == 20 and m.cfg.node_id == 12
    with pytest.raises(ParameterError, match=r"heartbeat_ms = 0 is out of range"):
        AXIS_SCHEMA.validate({"cia402": {"heartbeat_ms": 0}}, "")


def test_frame_level_drive_emulator_speaks_cia402_in_lock_step():
    """DriveEmulator(protocol="cia402") (the drive_emulator / simulated_drive path) with DriveAxis, on a
    simulated clock: start-up by SDO, enable, torque, an injected drive error as EMCY, enable again."""
    from friction_ros.core.can.emulator import DriveEmulator, EmulatorConfig

    channel = f"cia402e-{uuid.uuid4().hex[:8]}"
    now = [100.0]
    emu_bus = can.Bus(interface="virtual", channel=channel)
    emu = DriveEmulator(
        emu_bus,
        StandInPlant(inertia=0.5, viscous=0.5, coulomb=0.2),
        EmulatorConfig(protocol="cia402", node_id=4, conversion=CONV),
        clock=lambda: now[0],
    )
    axis = DriveAxis(
        AxisConfig(
            protocol="cia402",
            node_id=4,
            conversion=CONV,
            telemetry_period=DT,
            torque_limit=5.0,
            effort_source="torque_estimate",
        )
    )
    link = CanBusLink("virtual", channel, 1_000_000, [axis], frame_router([axis]), 5, 1.0, Logger())
    results = []

    def run(seconds, torque=None, until=None):
        for _ in range(round(seconds / DT)):
            now[0] += DT
            emu.poll(0.0)
            time.sleep(0.0002)  # the virtual bus hands frames over between threads
            link.receive(now[0])
            if torque is not None:
                axis.set_command(torque, now[0])
            r = axis.cycle(now[0])
            assert link.send(r.frames)
            results.append(r)
            if until is not None and until():
                return True
        return False

    try:
        assert run(1.0, until=lambda: axis.protocol.master.phase == "operational")
        axis.request_enable()
        assert run(1.0, 0.0, until=lambda: emu.armed)
        run(0.2, 1.5)
        assert emu.applied_torque == pytest.approx(0.15)  # motor side, gear ratio 10
        assert results[-1].sample.effort == pytest.approx(1.5, abs=0.01)
        emu.inject_axis_error()
        assert run(0.5, 1.5, until=lambda: bool(axis.latched))
        assert axis.fault_reason == "drive reports error 0x1000 (generic error)"
        run(0.1, 0.0)
        assert emu.applied_torque == 0.0 and not emu.armed
        axis.request_enable()
        assert run(1.0, 0.5, until=lambda: emu.armed and emu.applied_torque > 0)
        assert link.send(axis.shutdown_frames())  # quick stop, SYNC, disable voltage, SYNC
        time.sleep(0.01)
        emu.poll(0.0)
        assert not emu.armed and emu.drive.cia.state_log[-2:] == [
            State.QUICK_STOP_ACTIVE,
            State.SWITCH_ON_DISABLED,
        ]
    finally:
        link.close()
        emu_bus.shutdown()


def _lock_step(fast: bool, effort_source: str):
    """DriveAxis against the frame-level emulator on a simulated clock, with odd frames mixed in;
    returns (per-period trace, axis, frames that reached the protocol's decode)."""
    from friction_ros.core.can.cia402 import frames as fr
    from friction_ros.core.can.emulator import DriveEmulator, EmulatorConfig
    from friction_ros.core.can.frame import Frame

    n = 5
    emu = DriveEmulator(
        None,
        StandInPlant(inertia=0.5, viscous=0.5, coulomb=0.2),
        EmulatorConfig(protocol="cia402", node_id=n, conversion=CONV),
    )
    axis = DriveAxis(
        AxisConfig(
            protocol="cia402",
            node_id=n,
            conversion=CONV,
            telemetry_period=DT,
            torque_limit=5.0,
            effort_source=effort_source,
            command_timeout=1.0,
        )
    )
    if not fast:
        axis._fast = {}
    decoded = []
    decode = axis._decode

    def counted(*frame):
        decoded.append(frame[0])
        return decode(*frame)

    axis._decode = counted
    odd = {  # period -> frames a broken or foreign sender adds
        400: [Frame(0x180 + n, bytes(7))],  # short TPDO1: rejected
        410: [Frame(0x280 + n, bytes(5))],  # short TPDO2: rejected
        420: [Frame(0x180 + n, b"", is_remote=True, dlc=8)],  # RTR: ignored
        430: [Frame(0x180 + n, fr.TPDO1.pack(0x0237, 0, 2**30)), Frame(0x280 + n, fr.TPDO2.pack(0, 0))],
        600: [Frame(0x180 + n, fr.TPDO1.pack(0x0208, 0, 0))],  # statusword FAULT: latched
    }  # 430: a position 8192 motor turns away (TPDO1), reported with a TPDO2: implausible
    t, trace, rx = 0.0, [], []
    for f in axis.startup_frames():
        emu.handle(f, t)
    for k in range(900):
        t += DT
        if k in (150, 550, 700):
            axis.request_enable()
        if k == 500:
            emu.inject_axis_error()  # EMCY (general path)
        for f in rx + odd.get(k, []):
            axis.on_frame(f.arbitration_id, bytearray(f.data), f.is_remote, f.is_extended, False, t)
        axis.set_command(2.0 * math.sin(k * DT * 6.0), t)
        r = axis.cycle(t)
        trace.append((r, repr(axis.telemetry), axis.fault_reason))
        for f in r.frames:
            emu.handle(f, t)
        emu.advance(t + DT)
        rx = emu.pop_due(t + DT)
    return trace, axis, decoded


@pytest.mark.parametrize("effort_source", ["torque_estimate", "current"])
def test_fast_tpdo_path_matches_the_decoder(effort_source):
    """TPDO1/TPDO2 through DriveAxis' fast path (fast_reports) and through the protocol's decode:
    the same frames sent, samples, telemetry, faults, counters and decode statistics, period by period."""
    fast, a, dec_fast = _lock_step(True, effort_source)
    slow, b, dec_slow = _lock_step(False, effort_source)
    assert len(fast) == len(slow)
    for k, (x, y) in enumerate(zip(fast, slow)):
        assert x == y, k
    assert a.counters == b.counters and a.decoder.stats == b.decoder.stats
    assert a.gate.log.total == b.gate.log.total >= 3  # 2 undecodable, 1 implausible
    assert a.decoder.stats.rejected == 2 and a.decoder.stats.ignored == 1
    # the run did enable, move, fault on EMCY and on the statusword and enable again
    assert a.counters.fault_trips >= 2 and a.enabled
    assert any(r[0].sample is not None and r[0].sample.velocity > 0.01 for r in fast)
    tpdo = {0x185, 0x285}
    assert sum(i in tpdo for i in dec_slow) > 1000  # the general path decoded every TPDO
    assert sum(i in tpdo for i in dec_fast) < 20  # the fast path: only odd ones and the first ones


def test_payload_less_frames_reuse_one_message_and_the_bus_still_carries_each():
    from friction_ros.core.can.cia402 import frames as fr
    from friction_ros.core.can.frame import Frame
    from friction_ros.nodes.can_bus import FrameMessages

    message = FrameMessages().message
    sync = message(fr.SYNC_FRAME)
    assert message(Frame(0x080, b"")) is sync
    assert (sync.arbitration_id, sync.dlc, sync.is_extended_id, sync.is_remote_frame) == (
        0x080,
        0,
        False,
        False,
    )
    rtr = message(Frame(0x21, b"", is_remote=True, dlc=8))
    assert rtr.is_remote_frame and rtr.dlc == 8 and message(Frame(0x21, b"", True, dlc=8)) is rtr
    rpdo = Frame(0x205, fr.RPDO1.pack(0x0F, -250))
    a, b = message(rpdo), message(rpdo)
    assert a is not b and bytes(a.data) == rpdo.data and a.dlc == 4 and not a.is_extended_id
    channel = f"cia402m-{uuid.uuid4().hex[:8]}"
    tx, rx = can.Bus(interface="virtual", channel=channel), can.Bus(interface="virtual", channel=channel)
    try:
        for f in (rpdo, fr.SYNC_FRAME, rpdo, fr.SYNC_FRAME):
            tx.send(message(f))
        got = [rx.recv(1.0) for _ in range(4)]
        assert [(m.arbitration_id, bytes(m.data)) for m in got] == [(0x205, rpdo.data), (0x080, b"")] * 2
    finally:
        tx.shutdown()
        rx.shutdown()


def test_reused_messages_are_refilled_per_frame_and_the_bus_carries_each_payload():
    """With reuse (SocketCAN, virtual, friction_local) one Message per id and length, refilled in
    place: every payload sent still arrives as sent; other lengths, RTR and a set dlc get their own."""
    from friction_ros.core.can.cia402 import frames as fr
    from friction_ros.core.can.frame import Frame
    from friction_ros.nodes.can_bus import FrameMessages

    message = FrameMessages(reuse=True).message
    rpdos = [Frame(0x205, fr.RPDO1.pack(0x0F, p)) for p in (-250, 0, 300, 32767)]
    first = message(rpdos[0])
    assert all(message(f) is first for f in rpdos[1:]) and bytes(first.data) == rpdos[-1].data
    other = Frame(0x206, fr.RPDO1.pack(0x07, 5))
    assert message(other) is not first and bytes(message(other).data) == other.data
    longer = Frame(0x205, bytes(range(8)))
    assert message(longer) is not first and message(longer).dlc == 8 and first.dlc == 4
    assert message(Frame(0x21, b"\x01", dlc=8)) is not message(Frame(0x21, b"\x01", dlc=8))
    channel = f"cia402r-{uuid.uuid4().hex[:8]}"
    tx, rx = can.Bus(interface="virtual", channel=channel), can.Bus(interface="virtual", channel=channel)
    try:
        sent = [f for r in rpdos for f in (r, fr.SYNC_FRAME, other)]
        for f in sent:
            tx.send(message(f))
        got = [rx.recv(1.0) for _ in sent]
        assert [(m.arbitration_id, bytes(m.data)) for m in got] == [(f.arbitration_id, f.data) for f in sent]
    finally:
        tx.shutdown()
        rx.shutdown()
