"""A disk that fills while a bag is written: one error line, the bag closed and readable.

The small disk is a 2 MiB tmpfs mounted for the test (root) or, where mounting is not permitted, a
2 MiB file size limit (RLIMIT_FSIZE with SIGXFSZ ignored: EFBIG). Bags are read back with the
independent ``rosbags`` reader and the ``mcap`` library.
"""

from __future__ import annotations

import contextlib
import os
import random
import resource
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest
import yaml
from mcap.reader import make_reader
from rosbags.rosbag2 import Reader
from rosbags.typesys import Stores, get_typestore

SIZE = 2 * 1024 * 1024
TYPES = get_typestore(Stores.ROS2_JAZZY)


@contextlib.contextmanager
def small_disk(tmp_path: Path, kind: str):
    """(folder, preexec_fn): a 2 MiB tmpfs (``kind`` "tmpfs") or a 2 MiB file size limit ("fsize")."""
    d = tmp_path / "disk"
    d.mkdir()
    if kind == "fsize":

        def limit():
            signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
            resource.setrlimit(resource.RLIMIT_FSIZE, (SIZE, SIZE))

        yield d, limit
        return
    r = subprocess.run(["mount", "-t", "tmpfs", "-o", "size=2m", "tmpfs", str(d)], capture_output=True)
    if r.returncode != 0:
        pytest.skip(f"mounting a tmpfs is not permitted here ({r.stderr.decode().strip()}): fsize covers it")
    try:
        yield d, None
    finally:
        subprocess.run(["umount", "-l", str(d)], check=False)


def kind_here(tmp_path: Path) -> str:
    """ "tmpfs" where mounting one is permitted, else "fsize"."""
    probe = tmp_path / "probe"
    probe.mkdir()
    if subprocess.run(["mount", "-t", "tmpfs", "-o", "size=4k", "tmpfs", str(probe)]).returncode == 0:
        subprocess.run(["umount", str(probe)], check=True)
        return "tmpfs"
    return "fsize"


def read_sequence(bag: Path) -> list[int]:
    """velocity[0] (the publisher's sequence number) of every message, read by rosbags."""
    with Reader(bag) as r:
        return [int(TYPES.deserialize_cdr(raw, c.msgtype).velocity[0]) for c, _, raw in r.messages()]


def check_closed(bag: Path, kept: int) -> None:
    """The bag holds ``kept`` messages 0..kept-1 per rosbags, the MCAP summary and metadata.yaml."""
    assert read_sequence(bag) == list(range(kept))
    with open(next(bag.glob("*.mcap")), "rb") as f:
        summary = make_reader(f).get_summary()
    assert summary is not None and summary.statistics.message_count == kept
    info = yaml.safe_load((bag / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    assert info["message_count"] == kept
    assert not (bag / ".space_reserve").exists()


WRITER = textwrap.dedent(
    """
    import random, sys
    from friction_ros.core.bag import BagWriter, DiskFullError, encode, load_installed
    defs = load_installed("sensor_msgs/msg/JointState")
    w = BagWriter(sys.argv[1], chunk_size=32768, flush_interval=0.0, compression="none")
    w.add_topic("/fill", "sensor_msgs/msg/JointState")
    n = 0
    try:
        while n < 100000:
            msg = {"name": ["j"], "position": [random.random() for _ in range(500)], "velocity": [float(n)]}
            w.write("/fill", encode(defs, "sensor_msgs/msg/JointState", msg), 10**9 + n)
            n += 1
    except DiskFullError as exc:
        print(f"{exc.kept} {exc.lost} {n}")
        print(exc, file=sys.stderr)
        sys.exit(1)
    """
)


@pytest.mark.parametrize("kind", ["tmpfs", "fsize"])
def test_writer_closes_the_bag_with_every_completed_chunk(tmp_path, kind):
    with small_disk(tmp_path, kind) as (disk, pre):
        bag = disk / "bag"
        r = subprocess.run(
            [sys.executable, "-c", WRITER, str(bag)],
            capture_output=True,
            text=True,
            preexec_fn=pre,
            timeout=60,
        )
        assert r.returncode == 1 and "Traceback" not in r.stderr, r.stderr
        kept, lost, n = map(int, r.stdout.split())
        assert kept + lost == n + 1 and kept > 100
        if kind == "tmpfs":  # a chunk per write (flush_interval 0): the space reserve holds the summary,
            assert lost == 1  # only the message whose chunk hit the full disk is lost
        # (at a file size limit the summary takes the place of the last chunks: a few are dropped)
        what = "no space left on" if kind == "tmpfs" else "file size limit reached on"
        assert r.stderr.count("\n") == 1 and r.stderr.startswith(f"disk full: {what} ")
        assert f"bag {bag}:" in r.stderr and f"the {kept} messages" in r.stderr
        if kind == "tmpfs":
            assert f" on {disk} (2.0 MiB file system" in r.stderr
        check_closed(bag, kept)


@pytest.mark.ros
@pytest.mark.parametrize("kind", ["tmpfs", "fsize"])
def test_bag_recorder_on_a_full_disk_logs_one_line_and_exits_1(tmp_path, kind):
    import rclpy
    from sensor_msgs.msg import JointState

    with small_disk(tmp_path, kind) as (disk, pre):
        bag = disk / "rec"
        env = {**os.environ, "RCUTILS_LOGGING_BUFFERED_STREAM": "0"}
        cmd = [sys.executable, "-m", "friction_ros.nodes.bag_recorder", "-o", str(bag), "/fill",
               "--compression", "none", "--chunk-size", "16384", "--flush-interval", "0.02"]  # fmt: skip
        proc = subprocess.Popen(
            cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, preexec_fn=pre, env=env
        )
        ctx = rclpy.Context()
        rclpy.init(context=ctx)
        try:
            node = rclpy.create_node("disk_filler", context=ctx)
            pub = node.create_publisher(JointState, "/fill", 1000)
            end = time.time() + 30
            while pub.get_subscription_count() == 0 and time.time() < end:
                time.sleep(0.02)
            n = 0
            while proc.poll() is None and time.time() < end:  # 8 KB messages until the recorder stops
                pub.publish(JointState(name=["j"], position=[float(n)] * 1000, velocity=[float(n)]))
                n += 1
                time.sleep(0.002)
            out, err = proc.communicate(timeout=20)
        finally:
            if proc.poll() is None:
                proc.kill()
            rclpy.shutdown(context=ctx)
        assert proc.returncode == 1, err
        assert "Traceback" not in err and "Traceback" not in out
        errors = [ln for ln in (out + err).splitlines() if "ERROR" in ln or "error" in ln.lower()]
        assert len(errors) == 1, errors
        assert "disk full:" in errors[0] and f"bag {bag}" in errors[0]
        assert (f" on {disk} " if kind == "tmpfs" else "file size limit reached") in errors[0]
        kept = int(errors[0].split("closed with the ")[1].split()[0])
        assert kept > 50 and n > kept
        check_closed(bag, kept)
        print(f"{kind}: published {n}, bag kept {kept}; {errors[0]}")


def test_friction_bag_recover_onto_a_full_disk_prints_one_line(tmp_path):
    from friction_ros.core.bag import BagWriter, encode, load_installed

    src = tmp_path / "src"
    defs = load_installed("sensor_msgs/msg/JointState")
    with BagWriter(src, compression="none") as w:
        w.add_topic("/fill", "sensor_msgs/msg/JointState")
        for n in range(400):  # ~3.2 MB of incompressible values: more than the small disk holds
            rng = random.Random(n)
            msg = {"name": ["j"], "position": [rng.random() for _ in range(1000)], "velocity": [float(n)]}
            w.write("/fill", encode(defs, "sensor_msgs/msg/JointState", msg), 10**9 + n)
    kind = kind_here(tmp_path)
    with small_disk(tmp_path, kind) as (disk, pre):
        out = disk / "out"
        r = subprocess.run(
            [sys.executable, "-m", "friction_ros.cli.bag", "recover", str(src), str(out)],
            capture_output=True,
            text=True,
            preexec_fn=pre,
            timeout=60,
        )
        assert r.returncode == 1 and "Traceback" not in r.stderr and r.stdout == "", r.stderr
        what = f"no space left on {disk} " if kind == "tmpfs" else "file size limit reached on "
        assert r.stderr.count("\n") == 1 and r.stderr.startswith(f"error: disk full: {what}"), r.stderr
        assert f"while writing {out}: nothing written (the input is unchanged)" in r.stderr
        assert list(disk.iterdir()) == []  # the temporary output is gone too
    assert read_sequence(src) == list(range(400))
