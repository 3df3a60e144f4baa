"""Recorder and player as separate processes over real DDS (domain isolated by conftest)."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import threading
import time

import numpy as np
import pytest

pytestmark = pytest.mark.ros

rclpy = pytest.importorskip("rclpy")
from friction_msgs.msg import ExperimentEvent  # noqa: E402
from rclpy.executors import SingleThreadedExecutor  # noqa: E402
from rclpy.qos import QoSProfile, ReliabilityPolicy  # noqa: E402
from rclpy.serialization import serialize_message  # noqa: E402
from sensor_msgs.msg import JointState  # noqa: E402
from std_msgs.msg import Float64  # noqa: E402

from friction_ros.core.bag import BagWriter, make_qos, read_bag  # noqa: E402

QOS = QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE)


@pytest.fixture(scope="module")
def node():
    ctx = rclpy.context.Context()
    rclpy.init(context=ctx)
    n = rclpy.create_node(f"bag_test_{os.getpid()}", context=ctx)
    ex = SingleThreadedExecutor(context=ctx)
    ex.add_node(n)
    stop = threading.Event()

    def spin():
        while not stop.is_set():
            ex.spin_once(timeout_sec=0.01)

    th = threading.Thread(target=spin, daemon=True)
    th.start()
    yield n
    stop.set()
    th.join(2)
    n.destroy_node()
    rclpy.shutdown(context=ctx)


def start(module: str, *args: str) -> subprocess.Popen:
    return subprocess.Popen(
        [sys.executable, "-m", module, *args], stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True
    )


def wait_subscribed(pubs, proc, timeout=60.0):
    end = time.monotonic() + timeout
    while not all(p.get_subscription_count() >= 1 for p in pubs):
        assert proc.poll() is None, proc.stdout.read()
        assert time.monotonic() < end, "recorder did not subscribe"
        time.sleep(0.02)


def publish_run(node, topic_prefix: str, n: int):
    js = node.create_publisher(JointState, f"{topic_prefix}/joint_states", QOS)
    cmd = node.create_publisher(Float64, f"{topic_prefix}/command", QOS)
    ev = node.create_publisher(ExperimentEvent, f"{topic_prefix}/events", QOS)
    return js, cmd, ev


def send(js, cmd, ev, n):
    for i in range(n):
        m = JointState(name=["joint1"], position=[0.01 * i], velocity=[float(i)], effort=[-float(i)])
        m.header.stamp.sec = i
        js.publish(m)
        cmd.publish(Float64(data=0.5 * i))
        if i % 50 == 0:
            ev.publish(
                ExperimentEvent(
                    program="plateaus", segment=f"s{i}", index=i // 50, event=ExperimentEvent.START
                )
            )
        time.sleep(0.001)


def test_sigint_records_everything_and_rosbags_reads_it(node, tmp_path):
    from rosbags.rosbag2 import Reader
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    out = tmp_path / "rec"
    pre = "/t_int"
    pubs = publish_run(node, pre, 0)
    rec = start(
        "friction_ros.nodes.bag_recorder",
        *(f"{pre}/{t}" for t in ("joint_states", "command", "events")),
        "-o", str(out), "--preset", "abb_m19s", "--program", "plateaus",
        "--ros-args", "-p", "flush_interval:=0.5",
    )  # fmt: skip
    wait_subscribed(pubs, rec)
    n = 600
    send(*pubs, n)
    time.sleep(0.3)
    rec.send_signal(signal.SIGINT)
    log = rec.communicate(timeout=20)[0]
    assert rec.returncode == 0, log
    b = read_bag(out)
    assert not b.truncated and b.run_metadata["program"] == "plateaus"
    assert {t: len(d) for t, d in b.topics.items()} == {
        f"{pre}/joint_states": n,
        f"{pre}/command": n,
        f"{pre}/events": n // 50,
    }
    j = b[f"{pre}/joint_states"].joint("joint1")
    np.testing.assert_allclose(j.position, 0.01 * np.arange(n))
    np.testing.assert_array_equal(b[f"{pre}/command"]["data"], 0.5 * np.arange(n))
    assert (np.diff(b[f"{pre}/joint_states"].log_time) >= 0).all()
    # independent reader: same topics, types, counts, values
    ts = get_typestore(Stores.EMPTY)
    with Reader(out) as r:
        assert {c.topic: (c.msgtype, c.msgcount) for c in r.connections} == {
            f"{pre}/joint_states": ("sensor_msgs/msg/JointState", n),
            f"{pre}/command": ("std_msgs/msg/Float64", n),
            f"{pre}/events": ("friction_msgs/msg/ExperimentEvent", n // 50),
        }
        for c in r.connections:
            ts.register(get_types_from_msg(c.msgdef.data, c.msgtype))
        vel = [
            ts.deserialize_cdr(raw, c.msgtype).velocity[0] for c, _, raw in r.messages() if "joint" in c.topic
        ]
        segs = [
            ts.deserialize_cdr(raw, c.msgtype).segment for c, _, raw in r.messages() if "events" in c.topic
        ]
    assert vel == list(map(float, range(n)))
    assert segs == [f"s{i}" for i in range(0, n, 50)]


def test_sigkill_loses_at_most_the_open_chunk(node, tmp_path):
    out = tmp_path / "killed"
    pre = "/t_kill"
    pubs = publish_run(node, pre, 0)
    rec = start(
        "friction_ros.nodes.bag_recorder", f"{pre}/joint_states", f"{pre}/command", f"{pre}/events",
        "-o", str(out), "--flush-interval", "0.2",
    )  # fmt: skip
    wait_subscribed(pubs, rec)
    n = 400
    send(*pubs, n)
    time.sleep(0.6)  # > flush_interval + poll period: everything is in completed chunks
    rec.kill()
    rec.communicate(timeout=10)
    assert not (out / "metadata.yaml").exists()
    b = read_bag(out)
    assert b.truncated
    assert len(b[f"{pre}/joint_states"]) == n and len(b[f"{pre}/command"]) == n
    np.testing.assert_array_equal(b[f"{pre}/command"]["data"], 0.5 * np.arange(n))
    # friction-bag recover turns it into a finished bag that rosbags reads
    fixed = tmp_path / "fixed"
    r = subprocess.run(
        [sys.executable, "-m", "friction_ros.cli.bag", "recover", str(out), str(fixed)],
        capture_output=True,
        text=True,
    )
    assert r.returncode == 0, r.stderr
    from rosbags.rosbag2 import Reader

    with Reader(fixed) as rd:
        assert {c.topic: c.msgcount for c in rd.connections}[f"{pre}/command"] == n


@pytest.mark.realtime  # wall-clock timing: a CPU of its own, after the other tests
def test_player_replays_sequence_and_timing(node, tmp_path):
    bag = tmp_path / "play"
    rng = np.random.default_rng(3)
    t = 1_700_000_000_000_000_000 + np.cumsum(rng.uniform(1e6, 8e6, 250)).astype(np.int64)
    payloads = []
    with BagWriter(bag) as w:
        w.add_topic("/js", "sensor_msgs/msg/JointState", qos_profiles=[make_qos(depth=10)])
        w.add_topic("/cmd", "std_msgs/msg/Float64", qos_profiles=[make_qos()])
        for i, ti in enumerate(t):
            if i % 5 == 4:
                data = serialize_message(Float64(data=float(i)))
                w.write("/cmd", data, int(ti))
            else:
                data = serialize_message(JointState(name=["j"], position=[float(i)]))
                w.write("/js", data, int(ti))
                payloads.append((int(ti), data))
    got = []
    clock = []
    sub = node.create_subscription(
        JointState, "/replay/js", lambda m: got.append((time.monotonic(), m)), QOS, raw=True
    )
    cmd_got = []
    sub2 = node.create_subscription(Float64, "/cmd", lambda m: cmd_got.append(m), QOS)
    from rosgraph_msgs.msg import Clock

    sub3 = node.create_subscription(
        Clock, "/clock", lambda m: clock.append(m.clock.sec * 10**9 + m.clock.nanosec), 100
    )
    player = start(
        "friction_ros.nodes.bag_player", str(bag), "--topics", "/js", "--remap", "/js=/replay/js",
        "--clock", "--clock-frequency", "0", "--wait-for-subscribers", "1", "--start-delay", "0.3",
    )  # fmt: skip
    log = player.communicate(timeout=30)[0]
    time.sleep(0.2)
    node.destroy_subscription(sub)
    node.destroy_subscription(sub2)
    node.destroy_subscription(sub3)
    assert player.returncode == 0, log
    assert [g[1] for g in got] == [p[1] for p in payloads]  # identical bytes, identical order
    assert not cmd_got  # topic filter
    recv = np.array([g[0] for g in got])
    rec = np.array([p[0] for p in payloads]) * 1e-9
    err = (recv - recv[0]) - (rec - rec[0])
    err -= np.median(err)
    assert np.median(np.abs(err)) < 1e-3, np.median(np.abs(err))
    assert set(clock) >= {p[0] for p in payloads}  # /clock carried the bag time


def test_player_rate_and_errors(node, tmp_path):
    bag = tmp_path / "rate"
    with BagWriter(bag) as w:
        w.add_topic("/r", "std_msgs/msg/Float64")
        for i in range(21):
            w.write("/r", serialize_message(Float64(data=float(i))), 1_000_000_000 + i * 50_000_000)  # 1 s
    t0 = time.monotonic()
    p = start("friction_ros.nodes.bag_player", str(bag), "--rate", "4")
    out = p.communicate(timeout=20)[0]
    assert p.returncode == 0, out
    # 1 s of bag at rate 4 = 0.25 s of playback (+ start-up of a Python/ROS process)
    assert "published 21 messages" in out
    for args, words in [
        (["/nonexistent_bag"], "no such bag"),
        ([str(bag), "--topics", "/zz"], "not in the bag"),
        ([str(bag), "--remap", "oops"], "must be of the form"),
        ([str(bag), "--rate", "0"], "rate"),
    ]:
        r = subprocess.run(
            [sys.executable, "-m", "friction_ros.nodes.bag_player", *args], capture_output=True, text=True
        )
        assert r.returncode == 2 and words in r.stderr and "Traceback" not in r.stderr, r.stderr
    assert time.monotonic() - t0 < 30


def _diag_values(box):
    """Latest bag_recorder diagnostics status as (level, {key: value})."""
    for arr in reversed(box):
        for st in arr.status:
            if st.name.endswith("bag_recorder"):
                return st.level, {kv.key: kv.value for kv in st.values}
    return None, {}


def _burst_and_settle(pubs, box, topic, n, timeout=60.0, paused=None):
    """A primer message (so the burst does not start the topic: a drop before the first message
    received cannot be seen), then ``n`` messages as fast as the publishers take them; waits until
    the recorder accounts for all of them (received + dropped). ``paused``: a recorder process held
    stopped (SIGSTOP) during the burst, as a descheduled recorder on a busy machine is: the
    recorder takes batches fast enough to keep up with a shallow writer otherwise."""
    pubs[0].publish(JointState(name=["j"], position=[-1.0]))
    end = time.monotonic() + 15
    while _diag_values(box)[1].get(f"{topic} received") != "1":
        assert time.monotonic() < end, "primer not recorded"
        time.sleep(0.02)
    if paused is not None:
        paused.send_signal(signal.SIGSTOP)
    try:
        for i in range(n):
            pubs[i % len(pubs)].publish(JointState(name=["j"], position=[float(i)]))
    finally:
        if paused is not None:
            paused.send_signal(signal.SIGCONT)
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        v = _diag_values(box)[1]
        if int(v.get(f"{topic} received", 0)) + int(v.get(f"{topic} dropped", 0)) >= n + 1:
            return
        time.sleep(0.05)


@pytest.mark.parametrize("variant", ["keep_all_recorder", "keep_last_10_recorder"])
def test_10k_burst_is_recorded_completely_or_its_drops_are_counted_exactly(node, tmp_path, variant):
    """10,000-message bursts from another process: with the recorder's default (keep-all) subscription a
    burst from a RECORDED_QOS (5000-deep) publisher is recorded completely; when a publisher gives
    samples up (keep-last 10 writer, one or two publishers on a topic) or a keep-last 10 recorder
    overwrites them, the reported drops equal the messages missing from the bag, per topic, in the
    log, the diagnostics and the bag's friction_ros_recording metadata record."""
    from diagnostic_msgs.msg import DiagnosticArray

    from friction_ros.nodes.qos import RECORDED_QOS

    n = 10_000
    pre = f"/burst_{variant}"
    shallow = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)
    deep = QoSProfile(depth=n + 10, reliability=ReliabilityPolicy.RELIABLE)
    if variant == "keep_all_recorder":
        pubs = {
            f"{pre}/recorded_qos": [node.create_publisher(JointState, f"{pre}/recorded_qos", RECORDED_QOS)],
            f"{pre}/keep_last_10": [node.create_publisher(JointState, f"{pre}/keep_last_10", shallow)],
            f"{pre}/two_publishers": [
                node.create_publisher(JointState, f"{pre}/two_publishers", shallow) for _ in range(2)
            ],
        }
        extra = []
    else:
        pubs = {f"{pre}/deep_publisher": [node.create_publisher(JointState, f"{pre}/deep_publisher", deep)]}
        extra = ["-p", "qos_depth:=10"]
    box: list = []
    sub = node.create_subscription(DiagnosticArray, "/diagnostics", box.append, 100)
    out = tmp_path / variant
    rec = start(
        "friction_ros.nodes.bag_recorder", *pubs, "-o", str(out),
        "--ros-args", "-p", "diagnostics_period:=0.1", *extra,
    )  # fmt: skip
    try:
        wait_subscribed([p for ps in pubs.values() for p in ps], rec)
        for topic, ps in pubs.items():
            # a topic whose writer or recorder keeps a shallow history loses samples while the
            # recorder is held; the 5000-deep writer's burst must arrive whole without that
            _burst_and_settle(ps, box, topic, n, paused=None if topic.endswith("recorded_qos") else rec)
        level, values = _diag_values(box)
    finally:
        rec.send_signal(signal.SIGINT)
        log = rec.communicate(timeout=30)[0]
        node.destroy_subscription(sub)
    assert rec.returncode == 0, log
    b = read_bag(out)
    record = b.metadata["friction_ros_recording"]
    total_dropped = 0
    for topic in pubs:
        pos = np.asarray(b[topic].joint("j").position)
        assert len(np.unique(pos)) == len(pos)  # nothing twice
        assert pos[0] == -1.0  # the primer
        missing = (n + 1) - len(pos)
        dropped = int(record[f"dropped:{topic}"])
        assert dropped == missing, (topic, dropped, missing, log)  # exact
        assert int(record[f"received:{topic}"]) == len(pos)
        assert int(values[f"{topic} dropped"]) == dropped and int(values[f"{topic} received"]) == len(pos)
        total_dropped += dropped
        if topic.endswith("recorded_qos"):
            assert dropped == 0, log  # a burst up to the publisher's depth waits, it is not dropped
        else:
            assert dropped > 0  # the publisher (or the keep-last recorder) really gave samples up
    assert int(record["dropped"]) == total_dropped
    assert level == (b"\x01" if total_dropped else b"\x00")  # WARN when anything was dropped
    assert f"DROPPED {total_dropped} message(s)" in log.splitlines()[-1] or total_dropped == 0
    if variant == "keep_all_recorder":
        from rosbags.rosbag2 import Reader

        with Reader(out) as r:  # independent reader: the complete burst, in order
            counts = {c.topic: c.msgcount for c in r.connections}
        assert counts[f"{pre}/recorded_qos"] == n + 1
