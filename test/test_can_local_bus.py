"""friction_local: python-can bus between processes over Unix datagram sockets (no SocketCAN here).

Unit level: frames survive the SocketCAN ``struct can_frame`` encoding exactly, CAN broadcast
semantics (all other members hear a frame, the sender does not, channels are separate), filters,
stale members, clear errors. End to end: the ``drive_emulator`` program and the ``drive_interface``
node in two separate processes (as a drive and its node are on a robot), a PD controller over DDS
in this process, and this process also on the bus as a sniffer: the joint holds a position and
SIGINT to the node puts the drive to IDLE on the wire.
"""

from __future__ import annotations

import math
import os
import signal
import subprocess
import sys
import threading
import time
import uuid

import can
import pytest

from friction_ros.core.can import odrive as od
from friction_ros.core.can.local_bus import LocalBus, pack_frame, unpack_frame


@pytest.fixture
def channel(tmp_path, monkeypatch):
    monkeypatch.setenv("FRICTION_CAN_DIR", str(tmp_path / "can"))
    return f"c{uuid.uuid4().hex[:6]}"


def frames():
    yield can.Message(arbitration_id=0x029, data=b"\x01\x02\x03", is_extended_id=False)
    yield can.Message(arbitration_id=0x7FF, data=b"", is_extended_id=False)
    yield can.Message(arbitration_id=0x1ABCDEF0, data=bytes(range(8)), is_extended_id=True)
    yield can.Message(arbitration_id=0x02E, is_remote_frame=True, dlc=8, is_extended_id=False)
    yield can.Message(arbitration_id=0x020, is_error_frame=True, data=bytes(8), is_extended_id=False)


def same(a: can.Message, b: can.Message) -> bool:
    return (
        a.arbitration_id == b.arbitration_id
        and a.is_extended_id == b.is_extended_id
        and a.is_remote_frame == b.is_remote_frame
        and a.is_error_frame == b.is_error_frame
        and a.dlc == b.dlc
        and (a.is_remote_frame or bytes(a.data) == bytes(b.data))
    )


def test_frame_encoding_is_socketcan_can_frame():
    raw = pack_frame(can.Message(arbitration_id=0x1ABCDEF0, data=b"\xaa", is_extended_id=True))
    assert len(raw) == 16 and raw[:4] == (0x80000000 | 0x1ABCDEF0).to_bytes(4, "little")
    assert raw[4] == 1 and raw[8] == 0xAA
    for m in frames():
        assert same(unpack_frame(pack_frame(m), 0.0, "x"), m)
    assert unpack_frame(b"\x00" * 15, 0.0, "x") is None  # not a can_frame
    assert unpack_frame(bytes(4) + bytes([9]) + bytes(11), 0.0, "x") is None  # dlc 9


def test_broadcast_semantics_filters_and_channels(channel):
    a = can.Bus(interface="friction_local", channel=channel)  # through python-can's entry point
    b = LocalBus(channel)
    c = LocalBus(channel, can_filters=[{"can_id": 0x029, "can_mask": 0x7FF, "extended": False}])
    other = LocalBus(channel + "x")
    try:
        assert isinstance(a, LocalBus)
        sent = list(frames())
        for m in sent:
            a.send(m)
        got_b = [b.recv(0.5) for _ in sent]
        assert all(same(g, m) for g, m in zip(got_b, sent, strict=True))
        assert b.recv(0.0) is None
        assert same(c.recv(0.5), sent[0]) and c.recv(0.05) is None  # filtered like SocketCAN
        assert a.recv(0.05) is None  # a CAN node does not hear its own frames
        assert other.recv(0.05) is None  # another channel is another bus
        b.send(sent[2])
        assert same(a.recv(0.5), sent[2])
        assert c.recv(0.05) is None  # extended id 0x1ABCDEF0 does not pass c's filter
    finally:
        for bus in (a, b, c, other):
            bus.shutdown()


def test_member_in_another_process_and_dead_member(channel, tmp_path):
    """A sender process; the receiver gets every frame in order. A member killed without shutdown
    leaves its socket file; the first send refused by it removes the file."""
    rx = LocalBus(channel)
    code = (
        "import can, time\n"
        f"b = can.Bus(interface='friction_local', channel='{channel}')\n"
        "time.sleep(0.3)\n"
        "for i in range(300):\n"
        "    b.send(can.Message(arbitration_id=0x100 + (i % 0x100), data=i.to_bytes(2, 'little'), is_extended_id=False))\n"
        "    time.sleep(0.0005)\n"
        "b.shutdown()\n"
    )
    try:
        p = subprocess.Popen([sys.executable, "-c", code], env=os.environ.copy())
        got = []
        deadline = time.time() + 60
        while len(got) < 300 and time.time() < deadline:
            m = rx.recv(0.1)
            if m is not None:
                got.append(int.from_bytes(m.data, "little"))
        assert p.wait(30) == 0
        assert got == list(range(300))
        # a member that died without shutdown()
        p = subprocess.Popen(
            [sys.executable, "-c", f"import can, time; b = can.Bus(interface='friction_local', channel='{channel}'); time.sleep(60)"],
            env=os.environ.copy(),
        )  # fmt: skip
        folder = tmp_path / "can" / channel
        deadline = time.time() + 20
        while len(os.listdir(folder)) < 2 and time.time() < deadline:
            time.sleep(0.05)
        assert len(os.listdir(folder)) == 2
        p.kill()
        p.wait()
        time.sleep(0.25)  # past the peer refresh period
        rx.send(can.Message(arbitration_id=1, data=b"", is_extended_id=False))
        assert os.listdir(folder) == [os.path.basename(rx._path)]
    finally:
        rx.shutdown()
    assert not (tmp_path / "can" / channel / os.path.basename(rx._path)).exists()


def test_clear_errors(channel):
    with pytest.raises(ValueError, match="plain name"):
        LocalBus("a/b")
    with pytest.raises(ValueError, match="receive_own_messages"):
        LocalBus(channel, receive_own_messages=True)
    b = LocalBus(channel)
    b.shutdown()
    with pytest.raises(can.CanOperationError, match="shut down"):
        b.send(can.Message(arbitration_id=1, is_extended_id=False))


# ---- end to end: emulator process + drive_interface process + controller and sniffer here ------------
@pytest.mark.ros
@pytest.mark.flaky(reruns=2)
def test_emulator_and_node_in_separate_processes(channel):
    from test_can_e2e import KT, PdController

    sniffer = LocalBus(channel)
    rows: list[tuple[float, int, bytes]] = []
    stop_sniff = threading.Event()

    def sniff():
        while not stop_sniff.is_set():
            m = sniffer.recv(0.05)
            if m is not None:
                rows.append((time.time(), m.arbitration_id, bytes(m.data)))

    th = threading.Thread(target=sniff, daemon=True)
    th.start()
    env = os.environ.copy()
    emu = subprocess.Popen(
        [sys.executable, "-m", "friction_ros.nodes.drive_emulator", "--interface", "friction_local",
         "--channel", channel, "--node-id", "1", "--preset", "abb_m19s", "--status-period", "60"],
        env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
    )  # fmt: skip
    node = subprocess.Popen(
        [sys.executable, "-m", "friction_ros.nodes.drive_interface", "--ros-args",
         "-p", "interface:=friction_local", "-p", f"channel:={channel}", "-p", "node_id:=1",
         "-p", "joint_name:=j1", "-p", "enable_on_start:=true", "-p", f"torque_constant:={KT}",
         "-p", "torque_limit:=4.0", "-p", "command_timeout:=0.1"],
        env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
    )  # fmt: skip
    pd = PdController()
    try:
        pd.ref = lambda t: (0.3, 0.0)
        pd.wait_started(timeout=30.0)
        time.sleep(2.5)
        t_hold = time.time()
        hold = [abs(r - q) for (ts, r, q) in pd.samples if ts > t_hold - 0.5]
        t_int = time.time()
        node.send_signal(signal.SIGINT)
        out, _ = node.communicate(timeout=15)
        time.sleep(0.1)
    finally:
        pd.close()
        for p in (node, emu):
            if p.poll() is None:
                p.send_signal(signal.SIGINT)
                try:
                    p.communicate(timeout=10)
                except subprocess.TimeoutExpired:
                    p.kill()
        stop_sniff.set()
        th.join(2)
        sniffer.shutdown()
    assert node.returncode == 0, out
    assert hold and max(hold) < 0.05, f"hold error {max(hold) if hold else math.nan:.4f} rad"
    enc = [r for r in rows if r[1] == (1 << 5) | od.Cmd.GET_ENCODER_ESTIMATES]
    torque = [r for r in rows if r[1] == (1 << 5) | od.Cmd.SET_INPUT_TORQUE]
    assert len(enc) > 1000 and len(torque) > 1000, (len(enc), len(torque))  # ~1 kHz each way
    idle = bytes([1, 0, 0, 0])
    idles = [t for t, arb, d in rows if arb == (1 << 5) | od.Cmd.SET_AXIS_STATE and d[:4] == idle]
    assert any(t >= t_int for t in idles), "no IDLE frame on the bus after SIGINT"
    assert "drive left safe" in out
