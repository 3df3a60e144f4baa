"""The node's bus link on ``friction_local`` moves raw ``struct can_frame`` bytes (no python-can
Message): every frame sent arrives as sent, every frame received reaches its axis exactly as the
Message path (python-can's ``virtual`` bus) hands it over, error frames count and bus-off kills."""

from __future__ import annotations

import time
import uuid

import can
import pytest

from friction_ros.core.can.cia402 import frames as fr
from friction_ros.core.can.frame import Frame
from friction_ros.nodes.can_bus import CanBusLink, RawFrames

FILTERS = [
    {"can_id": 0x185, "can_mask": 0x7FF, "extended": False},
    {"can_id": 0x020, "can_mask": 0x7E0, "extended": False},
    {"can_id": 0x1ABCDEF0, "can_mask": 0x1FFFFFFF, "extended": True},
]


class Logger:
    def error(self, *a, **k):
        raise AssertionError(a)

    warning = error


class Protocol:
    filters = FILTERS

    def receive_filters(self):
        return self.filters


class Axis:
    """What the link needs of a DriveAxis; records what it is handed."""

    def __init__(self, filters):
        self.protocol = Protocol()
        self.protocol.filters = filters
        self.frames: list[tuple] = []
        self.bus_faults: list[str] = []

    def startup_frames(self):
        return []

    def on_frame(self, arb, data, remote, extended, error, t):
        self.frames.append((arb, bytes(data), remote, extended, error, t))

    def report_bus_fault(self, reason):
        self.bus_faults.append(reason)

    def clear_bus_fault(self):
        pass


@pytest.fixture
def can_dir(tmp_path, monkeypatch):
    monkeypatch.setenv("FRICTION_CAN_DIR", str(tmp_path / "can"))


def link_and_peer(interface: str, filters=FILTERS):
    channel = f"raw{uuid.uuid4().hex[:6]}"
    axis = Axis(filters)
    link = CanBusLink(interface, channel, 1_000_000, [axis], lambda arb, data: axis, 3, 1.0, Logger())
    peer = can.Bus(interface=interface, channel=channel)
    if interface == "friction_local":
        link.bus._refresh(time.monotonic())  # each hears the other from now on
        peer._refresh(time.monotonic())
    return link, peer, axis


SENT = [
    Frame(0x205, fr.RPDO1.pack(0x0F, -250)),
    fr.SYNC_FRAME,
    Frame(0x1ABCDEF0, bytes(range(8)), is_extended=True),
    Frame(0x02E, b"", is_remote=True, dlc=8),
    Frame(0x205, fr.RPDO1.pack(0x07, 300)),
    fr.SYNC_FRAME,
]


def test_sent_frames_arrive_as_sent(can_dir):
    link, peer, _ = link_and_peer("friction_local")
    try:
        assert link._send_raw is not None  # the raw path is the one under test
        assert link.send(SENT)
        got = [peer.recv(1.0) for _ in SENT]
        assert peer.recv(0.0) is None
        seen = [(m.arbitration_id, bytes(m.data), m.is_remote_frame, m.is_extended_id, m.dlc) for m in got]
        assert seen == [(f.arbitration_id, f.data, f.is_remote, f.is_extended, f.length) for f in SENT]
        raw = RawFrames().raw
        assert raw(fr.SYNC_FRAME) is raw(Frame(0x080, b""))  # payload-less: packed once
        assert raw(SENT[0]) != raw(SENT[4])  # a data frame: packed per frame
    finally:
        link.close()
        peer.shutdown()


RECEIVED = [
    can.Message(arbitration_id=0x185, data=b"\x37\x02\x10\x00\x01\x00\x00\x00", is_extended_id=False),
    can.Message(arbitration_id=0x021, data=b"", is_extended_id=False),
    can.Message(arbitration_id=0x02E, is_remote_frame=True, dlc=8, is_extended_id=False),
    can.Message(arbitration_id=0x1ABCDEF0, data=bytes(range(8)), is_extended_id=True),
    # filtered out (last: python-can's ``recv(0)`` on ``virtual`` returns None at a filtered frame)
    can.Message(arbitration_id=0x186, data=b"\x01", is_extended_id=False),
    can.Message(arbitration_id=0x0ABCDEF0, data=b"\x02", is_extended_id=True),
]


@pytest.mark.parametrize("interface", ["virtual", "friction_local"])
def test_received_frames_reach_the_axis_like_the_message_path(can_dir, interface):
    link, peer, axis = link_and_peer(interface)
    try:
        assert (link._recv_raw is not None) == (interface == "friction_local")
        for m in RECEIVED:
            peer.send(m)
        time.sleep(0.05)
        lo = time.monotonic()
        time.sleep(0.002)
        link._rx_prev = lo
        now = time.monotonic()
        link.receive(now)
        got = [f[:5] for f in axis.frames]
        assert got == [
            (0x185, RECEIVED[0].data, False, False, False),
            (0x021, b"", False, False, False),
            (0x02E, b"", True, False, False),
            (0x1ABCDEF0, bytes(range(8)), False, True, False),
        ]
        assert all(lo <= f[5] <= now for f in axis.frames)  # receive times within this period
        assert link.error_frames == 0 and not axis.bus_faults
    finally:
        link.close()
        peer.shutdown()


def test_error_frames_count_and_bus_off_kills_the_bus(can_dir):
    link, peer, axis = link_and_peer("friction_local", filters=[])  # filters drop error frames
    try:
        peer.send(can.Message(arbitration_id=0x004, is_error_frame=True, data=bytes(8)))  # controller
        link.receive(time.monotonic() + 0.05)
        assert link.error_frames == 1 and link.dead_since is None and not axis.frames
        peer.send(can.Message(arbitration_id=0x040, is_error_frame=True, data=bytes(8)))  # bus-off
        link.receive(time.monotonic() + 0.05)
        assert link.error_frames == 2 and link.dead_since is not None
        assert axis.bus_faults and "bus-off" in axis.bus_faults[0]
    finally:
        link.close()
        peer.shutdown()
