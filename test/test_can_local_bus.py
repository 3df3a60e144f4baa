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
from pathlib import Path

import can
import pytest

from friction_ros.can_bus.local_bus import LocalBus, pack_frame, unpack_frame
from friction_ros.core.can import odrive as od

HERE = Path(__file__).resolve().parent
# the drive and its node hold a joint at 1 kHz on the wall clock: a CPU of their own
pytestmark = pytest.mark.realtime


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
class Sniffer:
    """This process as one more member of the bus: every frame with its receive time (candump)."""

    def __init__(self, channel: str):
        self.bus = LocalBus(channel)
        self.rows: list[tuple[float, int, bytes]] = []
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def _run(self):
        while not self._stop.is_set():
            m = self.bus.recv(0.05)
            if m is not None:
                self.rows.append((time.time(), m.arbitration_id, bytes(m.data)))

    def stop(self):
        self._stop.set()
        self._thread.join(2)
        self.bus.shutdown()


def stop_all(*procs: subprocess.Popen) -> None:
    """SIGINT (the drives' safe stop) to every process still running, SIGKILL after 10 s."""
    for p in procs:
        if p.poll() is None:
            p.send_signal(signal.SIGINT)
            try:
                p.communicate(timeout=10)
            except subprocess.TimeoutExpired:
                p.kill()


def start_emulator(channel: str, *node_ids: int) -> subprocess.Popen:
    """The drive_emulator program (ABB M19-S preset behind each drive) as a process of its own."""
    return subprocess.Popen(
        [sys.executable, "-m", "friction_ros.nodes.drive_emulator", "--interface", "friction_local",
         "--channel", channel, "--node-id", *map(str, node_ids), "--preset", "abb_m19s", "--status-period", "60"],
        env=os.environ.copy(), stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
    )  # fmt: skip


@pytest.mark.ros
@pytest.mark.flaky(reruns=2)
def test_emulator_and_node_in_separate_processes(channel):
    from test_can_e2e import KT, PdController

    sniffer = Sniffer(channel)
    rows = sniffer.rows
    env = os.environ.copy()
    emu = start_emulator(channel, 1)
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
        stop_all(node, emu)
        sniffer.stop()
    assert node.returncode == 0, out
    assert hold and max(hold) < 0.05, f"hold error {max(hold) if hold else math.nan:.4f} rad"
    enc = [r for r in rows if r[1] == (1 << 5) | od.Cmd.GET_ENCODER_ESTIMATES]
    torque = [r for r in rows if r[1] == (1 << 5) | od.Cmd.SET_INPUT_TORQUE]
    assert len(enc) > 1000 and len(torque) > 1000, (len(enc), len(torque))  # ~1 kHz each way
    idle = bytes([1, 0, 0, 0])
    idles = [t for t, arb, d in rows if arb == (1 << 5) | od.Cmd.SET_AXIS_STATE and d[:4] == idle]
    assert any(t >= t_int for t in idles), "no IDLE frame on the bus after SIGINT"
    assert "drive left safe" in out


# ---- several drives on one bus, one node ----------------------------------------------------------------
def _node_cmd(channel: str, *params: str) -> list[str]:
    ros = ["-p", "interface:=friction_local", "-p", f"channel:={channel}", "-p", "enable_on_start:=true"]
    for p in params:
        ros += ["-p", p]
    return [sys.executable, "-m", "friction_ros.nodes.drive_interface", "--ros-args", *ros]


@pytest.mark.ros
@pytest.mark.parametrize(
    "params, words",
    [
        (
            ["joints:=[a, b]", "a.node_id:=1", "b.node_id:=1"],
            ["node ids must differ", "a.node_id = 1", "b.node_id = 1"],
        ),
        (["joints:=[a, 2b]", "a.node_id:=1"], ["joints[1]", "'2b'", "letter"]),
        (["joints:=[a, a]"], ["appears twice"]),
        (["joints:=[a, mit]"], ["clashes"]),
        (["c.node_id:=3"], ["unknown parameter", "c.node_id"]),
        # the old name of the drive's rate is named with what replaced it
        (["control_rate_hz:=500.0"], ["unknown parameter", "control_rate_hz is now control_period [s]"]),
    ],
)
def test_several_drives_bad_parameters_refuse_to_start_with_one_line(channel, params, words):
    p = subprocess.run(
        _node_cmd(channel, *params), env=os.environ.copy(), capture_output=True, text=True, timeout=60
    )
    out = p.stdout + p.stderr
    assert p.returncode == 2, out
    assert all(w in out for w in words) and "Traceback" not in out, out


@pytest.mark.ros
@pytest.mark.flaky(reruns=2)
def test_two_drives_on_one_bus_one_node(channel):
    """drive_interface with joints [shoulder, elbow] (node ids 1, 2; different gear ratios) and one
    emulator process with two drives: one joint_states message with both joints, both hold their own
    set-points from one joint_commands message, a command naming only one joint leaves the other to
    its watchdog (zero torque), SIGINT idles both drives on the wire."""
    import rclpy
    from friction_msgs.msg import DriveState
    from rclpy.executors import SingleThreadedExecutor
    from sensor_msgs.msg import JointState
    from test_can_e2e import KT

    from friction_ros.nodes.qos import COMMAND_QOS, SENSOR_QOS, STATE_QOS

    sniffer = Sniffer(channel)
    rows = sniffer.rows
    env = os.environ.copy()
    emu = start_emulator(channel, 1, 2)
    node = subprocess.Popen(
        _node_cmd(channel, "joints:=[shoulder, elbow]", "shoulder.node_id:=1", "elbow.node_id:=2",
                  f"torque_constant:={KT}", "torque_limit:=4.0", "command_timeout:=0.1",
                  "elbow.gear_ratio:=2.0", "elbow.torque_limit:=3.0"),
        env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
    )  # fmt: skip
    ctx = rclpy.Context()
    rclpy.init(context=ctx)
    ros = rclpy.create_node("two_drive_test", context=ctx)
    target = {"shoulder": 0.3, "elbow": -0.2}
    names = {"both": ["shoulder", "elbow"], "shoulder only": ["shoulder"]}
    mode = ["both"]
    states: list[tuple[float, list[str], list[float]]] = []
    drive_states: list[DriveState] = []
    pub = ros.create_publisher(JointState, "joint_commands", COMMAND_QOS)

    def on_state(msg: JointState):
        states.append((time.time(), list(msg.name), list(msg.position)))
        q = dict(zip(msg.name, msg.position))
        dq = dict(zip(msg.name, msg.velocity))
        send = names[mode[0]]
        if all(n in q for n in send):
            u = [30.0 * (target[n] - q[n]) - 0.3 * dq[n] for n in send]
            pub.publish(JointState(name=send, effort=u))

    ros.create_subscription(JointState, "joint_states", on_state, STATE_QOS)
    ros.create_subscription(DriveState, "drive_state", drive_states.append, SENSOR_QOS)
    ex = SingleThreadedExecutor(context=ctx)
    ex.add_node(ros)
    try:
        deadline = time.time() + 30
        while time.time() < deadline and len(states) < 3000:
            ex.spin_once(timeout_sec=0.05)
        t_hold = time.time()
        mode[0] = "shoulder only"
        end = time.time() + 0.5
        while time.time() < end:
            ex.spin_once(timeout_sec=0.05)
        t_int = time.time()
        node.send_signal(signal.SIGINT)
        out, _ = node.communicate(timeout=15)
        time.sleep(0.1)
    finally:
        ros.destroy_node()
        rclpy.shutdown(context=ctx)
        stop_all(node, emu)
        sniffer.stop()
    assert node.returncode == 0, out
    assert len(states) >= 3000, f"{len(states)} joint_states in 30 s"
    # one message with both joints (a drive without fresh telemetry, e.g. before its first frames or
    # late by more than 3 telemetry periods when the emulator process is descheduled, is left out
    # rather than made up: 1-5 % of periods with both cores busy, measured)
    both = [(t, q) for t, n, q in states if n == ["shoulder", "elbow"]]
    assert len(both) >= 0.9 * len(states) and all(set(n) <= set(target) for _, n, _ in states)
    hold = [q for t, q in both if t_hold - 0.5 < t <= t_hold]
    assert abs(hold[-1][0] - 0.3) < 0.05 and abs(hold[-1][1] + 0.2) < 0.05, hold[-1]
    # elbow (node 2) left out of the commands: its watchdog zeroes its torque; shoulder keeps holding
    by_joint = {j: [s for s in drive_states if s.joint_name == j] for j in target}
    late = {
        j: [s for s in v if s.header.stamp.sec + 1e-9 * s.header.stamp.nanosec > t_hold + 0.3]
        for j, v in by_joint.items()
    }
    assert late["elbow"] and all(s.fault_flags & DriveState.FAULT_COMMAND_WATCHDOG for s in late["elbow"])
    assert late["shoulder"] and not any(
        s.fault_flags & DriveState.FAULT_COMMAND_WATCHDOG for s in late["shoulder"]
    )
    torque2 = [
        od._F1.unpack_from(d)[0]
        for t, arb, d in rows
        if arb == (2 << 5) | od.Cmd.SET_INPUT_TORQUE and t_hold + 0.3 < t < t_int
    ]
    assert torque2 and all(v == 0.0 for v in torque2)
    idle = bytes([1, 0, 0, 0])
    for nid in (1, 2):
        idles = [t for t, arb, d in rows if arb == (nid << 5) | od.Cmd.SET_AXIS_STATE and d[:4] == idle]
        assert any(t >= t_int for t in idles), f"no IDLE frame for node {nid} after SIGINT"
    assert "drives left safe" in out


@pytest.mark.ros
def test_several_drives_parameters_per_joint_and_at_run_time(channel):
    """Per-joint values override the node's; run-time limits change per joint (all or nothing); a
    node-level limit is refused with the per-joint name to use; ids are read-only."""
    import rclpy
    from rclpy.parameter import Parameter

    from friction_ros.nodes.drive_interface import DriveInterface

    ctx = rclpy.Context()
    rclpy.init(context=ctx)
    overrides = [
        Parameter("interface", value="friction_local"),
        Parameter("channel", value=channel),
        Parameter("joints", value=["a", "b"]),
        Parameter("a.node_id", value=1),
        Parameter("b.node_id", value=2),
        Parameter("torque_limit", value=2.0),
        Parameter("b.gear_ratio", value=9.0),
        Parameter("b.direction", value=-1),
    ]
    node = DriveInterface(context=ctx, parameter_overrides=overrides)
    try:
        a, b = node.axes
        assert node.joints == ["a", "b"] and (a.cfg.node_id, b.cfg.node_id) == (1, 2)
        assert (a.cfg.torque_limit, b.cfg.torque_limit) == (2.0, 2.0)
        assert (a.conv.gear_ratio, b.conv.gear_ratio, b.conv.direction) == (1.0, 9.0, -1)
        assert [f["can_id"] for f in node.link.filters] == [1 << 5, 2 << 5]
        r = node.set_parameters([Parameter("b.torque_limit", value=2.5)])[0]
        assert r.successful and (a.cfg.torque_limit, node.axes[1].cfg.torque_limit) == (2.0, 2.5)
        r = node.set_parameters([Parameter("b.torque_limit", value=-1.0)])[0]
        assert not r.successful and "b.torque_limit" in r.reason and node.axes[1].cfg.torque_limit == 2.5
        r = node.set_parameters([Parameter("torque_limit", value=3.0)])[0]
        assert not r.successful and "<joint>.torque_limit" in r.reason, r.reason
        r = node.set_parameters([Parameter("command_timeout", value=0.05)])[0]  # shared by all drives
        assert r.successful and all(x.cfg.command_timeout == 0.05 for x in node.axes)
        r = node.set_parameters([Parameter("a.node_id", value=5)])[0]
        assert not r.successful and node.axes[0].cfg.node_id == 1
        # a period without any drive on the bus: no joint_states made up, diagnostics per joint
        sent = []
        node.diag.publish = lambda level, message, values: sent.append((level, message, values))
        node.pub_joint.publish = lambda msg: sent.append(("joint_states", msg))
        node._cycle_inner()
        node._publish_diagnostics(time.monotonic())
        # diagnostics only (the period's own and the explicit one), WARN: no telemetry from either drive
        assert [x[0] for x in sent] == [1, 1], sent
        level, message, values = sent[-1]
        assert message == "a: disabled, no telemetry yet; b: disabled, no telemetry yet", message
        assert {"a.enabled", "b.enabled", "a.frames_decoded", "bus_state", "loop_overruns"} <= set(values)
    finally:
        node.on_shutdown()
        node.destroy_node()
        rclpy.shutdown(context=ctx)


def test_bursts_wait_for_a_full_queue_and_a_stalled_member_does_not_stall_the_bus(channel):
    """A receive queue holds only net.unix.max_dgram_qlen (10) frames: a burst of 100 frames to a
    member that keeps reading arrives whole and in order (the sender waits for room up to its send
    timeout: 1 s here, so a reader descheduled on a loaded machine loses nothing); a member that never
    reads loses frames after the send timeout instead of blocking the sender."""
    tx, rx = LocalBus(channel), LocalBus(channel)
    got: list[int] = []

    def reader():
        while len(got) < 100:
            m = rx.recv(5.0)
            if m is None:
                return
            got.append(m.data[0])

    th = threading.Thread(target=reader)
    th.start()
    try:
        for i in range(100):
            tx.send(can.Message(arbitration_id=0x10, data=bytes([i]), is_extended_id=False), timeout=1.0)
        th.join(10)
        assert got == list(range(100)) and tx.frames_dropped == 0
        stalled = LocalBus(channel)  # joins, never reads
        time.sleep(0.25)  # past the peer refresh period
        t0 = time.monotonic()
        for i in range(30):
            tx.send(can.Message(arbitration_id=0x11, data=bytes([i]), is_extended_id=False), timeout=0.001)
        assert time.monotonic() - t0 < 1.0
        assert tx.frames_dropped >= 15  # everything beyond the stalled member's queue
        stalled.shutdown()
    finally:
        tx.shutdown()
        rx.shutdown()


# ---- stale telemetry: a killed drive, a healthy one under load ---------------------------------------
def _log(out: str) -> list[tuple[str, float, str]]:
    """(level, wall time, message) of every drive_interface log line."""
    import re

    pat = re.compile(r"\[(\w+)\] \[(\d+\.\d+)\] \[drive_interface\]: (.*)")
    return [(m[1], float(m[2]), m[3]) for m in map(pat.search, out.splitlines()) if m]


SLACK = 0.25  # [s] a process on the loaded 2-core VM can be descheduled this long (bench/drive_soak.py)


@pytest.mark.ros
@pytest.mark.flaky(reruns=2)
def test_killed_emulator_logs_one_stale_fault_within_the_timeout_idles_the_drive_and_enable_resets_it(
    channel,
):
    """README settings (automatic telemetry timeout at 1 kHz), PD controller moving the joint. The
    emulator process is killed (SIGKILL): torque goes to zero within 3 telemetry periods (+ one
    control period) of the drive's last frame; within the timeout + one control period the node
    logs one telemetry_stale error naming the action and the wire shows zero torque + IDLE. A new emulator process: the clear is logged
    once (the drive stays disabled); ~/enable logs the reset and re-enables the drive."""
    from std_srvs.srv import SetBool
    from test_can_e2e import KT, PdController

    from friction_ros.core.can.axis_config import AxisConfig

    timeout = AxisConfig(telemetry_period=0.001).stale_after  # what the node derives at 1 kHz
    enc_id = (1 << 5) | od.Cmd.GET_ENCODER_ESTIMATES
    axis_id, torque_id = (1 << 5) | od.Cmd.SET_AXIS_STATE, (1 << 5) | od.Cmd.SET_INPUT_TORQUE
    sniffer = Sniffer(channel)
    rows = sniffer.rows
    emu = start_emulator(channel, 1)
    assert emu.stdout.readline().startswith("drive_emulator:")  # the drive is up before the node
    node = subprocess.Popen(
        _node_cmd(channel, "node_id:=1", "joint_name:=j1", f"torque_constant:={KT}", "torque_limit:=4.0"),
        env=os.environ.copy(), stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
    )  # fmt: skip
    pd = PdController()
    emu2 = None
    try:
        pd.ref = lambda t: (0.3 * math.sin(2 * math.pi * t), 0.6 * math.pi * math.cos(2 * math.pi * t))
        pd.wait_started(timeout=30.0)
        time.sleep(1.5)
        emu.send_signal(signal.SIGKILL)
        emu.wait(10)
        t_kill = time.time()
        time.sleep(timeout + 1.0)
        t_restart = time.time()
        emu2 = start_emulator(channel, 1)
        end = time.time() + 30
        while not any(t > t_restart and arb == enc_id for t, arb, _ in list(rows)) and time.time() < end:
            time.sleep(0.05)
        time.sleep(0.5)
        client = pd.node.create_client(SetBool, "/drive_interface/enable")
        assert client.wait_for_service(timeout_sec=10)
        t_enable = time.time()
        client.call_async(SetBool.Request(data=True))
        time.sleep(1.0)
        node.send_signal(signal.SIGINT)
        out, _ = node.communicate(timeout=15)
    finally:
        pd.close()
        stop_all(node, emu, *([emu2] if emu2 else []))
        sniffer.stop()
    assert node.returncode == 0, out
    log = _log(out)
    last_enc = max(t for t, arb, _ in rows if arb == enc_id and t < t_restart)
    assert last_enc > t_kill - 0.5
    moving = [od._F1.unpack_from(d)[0] for t, arb, d in rows if arb == torque_id and t < last_enc]
    assert max(map(abs, moving)) > 0.1, "the drive was not producing torque before the kill"
    stale = [(lv, t, m) for lv, t, m in log if "telemetry_stale:" in m and "newest telemetry" in m]
    assert len(stale) == 1, out  # once, after telemetry had been received (not at start-up)
    level, t_fault, text = stale[0]
    assert level == "ERROR" and "newest telemetry is" in text and "drive disabled" in text, text
    # exact bound (timeout + one control period) in test_can_axis; here + the node's own lateness on
    # a shared 2-core machine (SLACK)
    assert timeout - 0.01 < t_fault - last_enc < timeout + 0.001 + SLACK, (t_fault - last_enc, out)
    idle = [t for t, arb, d in rows if arb == axis_id and d[:4] == bytes([1, 0, 0, 0]) and t > last_enc]
    assert idle and idle[0] - last_enc < timeout + 0.001 + SLACK
    # zero torque 3 telemetry periods after the last frame (one torque frame per 1 ms period: at most
    # 3 + 1 more non-zero), long before the fault; then the IDLE; nothing else until ~/enable
    after = [od._F1.unpack_from(d)[0] for t, arb, d in rows if arb == torque_id and last_enc < t < t_enable]
    nonzero = [i for i, v in enumerate(after) if v != 0.0]
    assert len(after) > 100 and (not nonzero or nonzero[-1] < 5), after[:10]
    assert not [t for t, arb, _ in rows if arb == torque_id and idle[0] + 0.05 < t < t_enable]  # disabled
    cleared = [(t, m) for _, t, m in log if "telemetry_stale cleared" in m]
    assert len(cleared) == 1 and t_restart < cleared[0][0] < t_enable, out
    assert cleared[0][1].endswith("drive stays disabled until ~/enable")
    reset = [t for _, t, m in log if "telemetry_stale fault reset by ~/enable" in m]
    assert len(reset) == 1 and reset[0] >= t_enable - 0.01, out
    closed = [t for t, arb, d in rows if arb == axis_id and d[:4] == bytes([8, 0, 0, 0]) and t > t_enable]
    assert closed, "the drive was not re-enabled by ~/enable"


@pytest.mark.ros
def test_healthy_emulator_under_cpu_load_gives_no_stale_fault_in_25_s():
    """The soak of bench/drive_soak.py, shortened: drive_emulator and drive_interface (README settings)
    in their own processes, PD controller over DDS here, two busy loops on the two cores. No
    stale-telemetry fault (diagnostics count and log lines); then the emulator is killed and the
    fault is logged and the drive disabled."""
    import importlib.util

    from friction_ros.core.can.axis_config import AxisConfig

    spec = importlib.util.spec_from_file_location("drive_soak", HERE.parent / "bench" / "drive_soak.py")
    soak = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(soak)
    r = soak.soak(25.0, load=len(os.sched_getaffinity(0)), kill=True)  # the cores this test may use
    out = r.pop("node_log")
    (d,) = r["per_drive"]
    assert r["node_exit"] == 0, out
    assert d["stale_faults"] == 0 and d["stale_log_lines"] == 0, (r, out)
    assert d["telemetry_age_max_ms"] < d["timeout_ms"] and d["enabled_at_end_of_soak"], r
    timeout = AxisConfig(telemetry_period=0.001).stale_after
    assert d["timeout_ms"] == pytest.approx(timeout * 1e3)
    assert r["joint_states_hz"] > 200, r  # the loop kept running under load
    assert r["kill_fault_lines"] == 1 and r["kill_disabled"], (r, out)
    # the node itself runs late under this load: bound = timeout + a generous scheduling allowance
    assert r["kill_to_fault_log_ms"] < timeout * 1e3 + 500, r


@pytest.mark.ros
def test_commands_for_other_joints_or_with_wrong_lengths_are_logged_and_counted(channel, capfd):
    import rclpy
    from rclpy.parameter import Parameter
    from sensor_msgs.msg import JointState

    from friction_ros.nodes.drive_interface import DriveInterface

    ctx = rclpy.Context()
    rclpy.init(context=ctx)
    overrides = [
        Parameter("interface", value="friction_local"),
        Parameter("channel", value=channel),
        Parameter("joint_name", value="j1"),
    ]
    node = DriveInterface(context=ctx, parameter_overrides=overrides)
    try:
        axis = node.axis
        node.commands.on_message(JointState(name=["j1"], effort=[0.25]), now=1.0)
        assert axis._cmd == 0.25 and axis._cmd_time == 1.0
        for i, msg in enumerate(
            [
                JointState(name=["joint1"], effort=[1.0]),  # another joint
                JointState(name=["j1"], effort=[]),  # names without efforts
                JointState(name=["j1", "j2"], effort=[1.0]),  # one short
                JointState(effort=[1.0, 2.0]),  # no names, not one effort per drive
                JointState(name=["other"], effort=[3.0]),  # within 1 s of the first: counted, not logged
            ]
        ):
            node.commands.on_message(msg, now=2.0 + i)
        assert axis._cmd == 0.25 and axis._cmd_time == 1.0  # all ignored: the previous command stands
        assert (node.commands.foreign, node.commands.malformed) == (2, 3)
        sent = []
        node.diag.publish = lambda level, message, values: sent.append(values)
        node._publish_diagnostics(time.monotonic())
        assert sent[-1]["commands_foreign"] == 2 and sent[-1]["commands_malformed"] == 3
        err = capfd.readouterr().err
        lines = [ln for ln in err.splitlines() if "ignored joint_commands" in ln]
        assert len(lines) == 2, err  # one per kind within a second
        assert "for ['joint1']: this node drives ['j1']" in lines[0]
        assert "1 names but 0 efforts: must carry one effort per name" in lines[1]
    finally:
        node.on_shutdown()
        node.destroy_node()
        rclpy.shutdown(context=ctx)


def test_drive_emulator_duration_is_the_run_time(channel):
    """--duration S stops the emulator S seconds after it started, whatever the status period."""
    p = subprocess.Popen(
        [sys.executable, "-m", "friction_ros.nodes.drive_emulator", "--interface", "friction_local",
         "--channel", channel, "--duration", "1.0", "--status-period", "30"],
        env=os.environ.copy(), stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
    )  # fmt: skip
    first = p.stdout.readline()
    t0 = time.monotonic()
    rc = p.wait(30)
    elapsed = time.monotonic() - t0
    assert rc == 0 and first.startswith("drive_emulator:"), first
    # the status period is 30 s: an emulator that waited for it would run >= 30 s; the upper bound
    # leaves room for a loaded machine
    assert 0.9 < elapsed < 10.0, f"ran {elapsed:.2f} s after starting, --duration 1.0"
