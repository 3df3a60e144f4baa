"""Benchmark of the bag I/O: recorder at 1 kHz on five topics, reader speed on a 1-million-message bag.

    .venv/bin/python bench/bags.py [--duration 10] [--messages 1000000]

1. Recorder: a publisher process sends JointState, ControllerState, DriveState, FrictionEstimate and
   ExperimentEvent... at 1 kHz each (5 kHz total) for ``--duration`` s; the recorder (separate
   process, real DDS) records them; SIGINT; drops = published - recorded; CPU = recorder user+system
   time during publishing / wall time (1.0 = one core).
2. Reader: a bag with ``--messages`` JointState messages (1 joint) is written with BagWriter, then
   ``read_bag`` (all fields as numpy columns) and ``.joint("joint1")`` are timed.
"""

from __future__ import annotations

import argparse
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.append(str(Path(__file__).resolve().parent))  # bench/can.py must not shadow python-can
from _common import print_table, write_results  # noqa: E402

from friction_ros.core.bag import BagWriter, encode, load_installed, read_bag  # noqa: E402

PUBLISHER = r"""
import sys, time, rclpy
from rclpy.qos import QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import JointState
from friction_msgs.msg import ControllerState, DriveState, FrictionEstimate
from std_msgs.msg import Float64
rclpy.init()
n = rclpy.create_node('bench_pub')
q = QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE)
types = [("/bench/joint_states", JointState), ("/bench/controller_state", ControllerState),
         ("/bench/drive_state", DriveState), ("/bench/friction_estimate", FrictionEstimate),
         ("/bench/command", Float64)]
pubs = [(n.create_publisher(c, t, q), c) for t, c in types]
end = time.monotonic() + 20
while any(p.get_subscription_count() < 1 for p, _ in pubs):
    time.sleep(0.01)
    if time.monotonic() > end: sys.exit("recorder never subscribed")
msgs = []
for p, c in pubs:
    m = c()
    if c is JointState:
        m.name = ["joint1"]; m.position = [0.0]; m.velocity = [0.0]; m.effort = [0.0]
    if c is FrictionEstimate:
        m.coefficient_names = ["fc", "fs", "vs", "b"]; m.coefficients = [0.1, 0.2, 0.01, 0.003]
    msgs.append(m)
duration = float(sys.argv[1])
period = 1e-3
count = 0
late = 0
print("START", flush=True)
t0 = time.monotonic()
k = 0
while True:
    target = t0 + k * period
    now = time.monotonic()
    if now - t0 >= duration: break
    if target > now:
        time.sleep(target - now)
    elif now - target > period:
        late += 1
    for (p, c), m in zip(pubs, msgs):
        if c is Float64:
            m.data = float(k)
        elif c is JointState:
            m.position = [float(k)]
        p.publish(m)
    count += 1
    k += 1
print("END", count, late, time.monotonic() - t0, flush=True)
time.sleep(1.0)
"""


def cpu_seconds(pid: int) -> float:
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def bench_recorder(duration: float, tmp: Path) -> dict:
    out = tmp / "rec"
    rec = subprocess.Popen(
        [sys.executable, "-m", "friction_ros.nodes.bag_recorder", "-a", "-o", str(out)],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    pub = subprocess.Popen(
        [sys.executable, "-c", PUBLISHER, str(duration)],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    assert pub.stdout.readline().strip() == "START", pub.stderr.read()
    c0, w0 = cpu_seconds(rec.pid), time.monotonic()
    end_line = pub.stdout.readline().split()
    c1, w1 = cpu_seconds(rec.pid), time.monotonic()
    pub.wait(timeout=30)
    time.sleep(0.5)
    rec.send_signal(signal.SIGINT)
    rec.wait(timeout=30)
    _, cycles, late, elapsed = end_line
    cycles, late, elapsed = int(cycles), int(late), float(elapsed)
    bag = read_bag(out)
    counts = {t: len(d) for t, d in bag.topics.items() if t.startswith("/bench/")}
    recorded = sum(counts.values())
    published = 5 * cycles
    return {
        "duration_s": elapsed,
        "publish_rate_hz_per_topic": cycles / elapsed,
        "late_cycles": late,
        "published": published,
        "recorded": recorded,
        "dropped": published - recorded,
        "recorder_cpu_fraction_of_one_core": (c1 - c0) / (w1 - w0),
        "bag_bytes": sum(f.stat().st_size for f in out.iterdir()),
    }


def make_big_bag(path: Path, n: int) -> float:
    defs = load_installed("sensor_msgs/msg/JointState")
    tpl = encode(
        defs,
        "sensor_msgs/msg/JointState",
        {"name": ["joint1"], "position": [1.5], "velocity": [2.5], "effort": [3.5]},
    )
    mat = np.tile(np.frombuffer(tpl, np.uint8), (n, 1))
    t = np.arange(n) * 1e-3
    for value, column in ((1.5, np.sin(t)), (2.5, np.cos(t)), (3.5, 0.1 * np.sign(np.cos(t)))):
        off = tpl.index(np.float64(value).tobytes())
        mat[:, off : off + 8] = column[:, None].view(np.uint8)
    mat[:, 4:8] = t.astype(np.int32)[:, None].view(np.uint8)
    t0 = time.perf_counter()
    base = 1_700_000_000_000_000_000
    with BagWriter(path, overwrite=True) as w:
        w.add_topic("/joint_states", "sensor_msgs/msg/JointState")
        for i in range(n):
            w.write("/joint_states", mat[i].tobytes(), base + i * 1_000_000)
    return n / (time.perf_counter() - t0)


def bench_reader(n: int, tmp: Path) -> dict:
    path = tmp / "big"
    write_rate = make_big_bag(path, n)
    size = sum(f.stat().st_size for f in path.iterdir())
    best = []
    for _ in range(3):
        t0 = time.perf_counter()
        bag = read_bag(path)
        t1 = time.perf_counter()
        j = bag["/joint_states"].joint("joint1")
        t2 = time.perf_counter()
        best.append((t1 - t0, t2 - t1))
        assert len(j.position) == n
    read_s = min(b[0] for b in best)
    code = (
        "import sys, time; from friction_ros.core.bag import read_bag; t = time.perf_counter(); "
        "read_bag(sys.argv[1]); print(time.perf_counter() - t)"
    )
    fresh = float(
        subprocess.run([sys.executable, "-c", code, str(path)], capture_output=True, text=True).stdout
    )
    return {
        "messages": n,
        "bag_bytes": size,
        "write_msgs_per_s": write_rate,
        "read_bag_s": read_s,
        "read_msgs_per_s": n / read_s,
        "read_fresh_process_msgs_per_s": n / fresh,
        "joint_select_s": min(b[1] for b in best),
    }


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--duration", type=float, default=10.0, help="recorder test length [s]")
    ap.add_argument("--messages", type=int, default=1_000_000, help="reader test bag size")
    ns = ap.parse_args()
    tmp = Path(tempfile.mkdtemp(prefix="bench_bags_"))
    os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    os.environ.setdefault("ROS_DOMAIN_ID", str(150 + os.getpid() % 70))
    try:
        rec = bench_recorder(ns.duration, tmp)
        rd = bench_reader(ns.messages, tmp)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    print_table(
        "Recorder: 5 topics x 1 kHz, separate processes over Fast DDS",
        ["duration s", "rate Hz/topic", "published", "recorded", "dropped", "recorder CPU (cores)", "bag MB"],
        [
            [
                rec["duration_s"],
                rec["publish_rate_hz_per_topic"],
                rec["published"],
                rec["recorded"],
                rec["dropped"],
                rec["recorder_cpu_fraction_of_one_core"],
                rec["bag_bytes"] / 1e6,
            ]
        ],
    )
    print_table(
        f"Reader: {rd['messages']} JointState messages (1 joint), zstd chunks",
        ["bag MB", "write msg/s", "read_bag s", "read msg/s", "read msg/s (fresh process)", "joint() s"],
        [
            [
                rd["bag_bytes"] / 1e6,
                rd["write_msgs_per_s"],
                rd["read_bag_s"],
                rd["read_msgs_per_s"],
                rd["read_fresh_process_msgs_per_s"],
                rd["joint_select_s"],
            ]
        ],
    )
    write_results(
        "bags",
        {"recorder": rec, "reader": rd},
        " ".join([".venv/bin/python", "bench/bags.py", *sys.argv[1:]]),
    )


if __name__ == "__main__":
    main()
