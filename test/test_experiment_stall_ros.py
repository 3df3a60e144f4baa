"""A recorder that stalls during a simulated (lockstep) experiment loses no joint state: the plant
and the experiment run composed in one process, faster than a stalled recorder, and the plant's
joint_states history (LOCKSTEP_RECORDED_QOS) holds what the recorder has not taken yet. With the
5000-deep history of the other recorded topics, a 1.5 s stall lost states."""

from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
import time

import numpy as np


def _start(out):
    """friction-experiment (quick, seed004_dc_motor, lockstep) writing to ``out``; its output is read
    line by line."""
    cmd = [sys.executable, "-m", "friction_ros.cli.experiment", "--profile", "quick", "--preset",
           "seed004_dc_motor", "--mode", "lockstep", "-o", str(out), "--timeout", "120"]  # fmt: skip
    return subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)


def _recorder_pid(out) -> int:
    found = subprocess.run(["pgrep", "-f", f"bag_recorder.*output:={out}"], capture_output=True, text=True)
    return int(found.stdout.split()[0])


def _finish(proc, lines: list[str], out):
    """Wait for the run; its exit code 0 and no drop counted; returns (bag, unique state stamps [ns], text)."""
    from friction_ros.core.bag import read_bag

    rest, _ = proc.communicate(timeout=150)
    text = "".join(lines) + rest
    assert proc.returncode == 0, text[-3000:]
    bag = read_bag(out)
    assert bag.metadata["friction_ros_recording"]["dropped"] == "0", text[-3000:]
    f = bag["/joint_states"].fields
    stamps = np.unique(f["header.stamp.sec"].astype(np.int64) * 10**9 + f["header.stamp.nanosec"])
    return bag, stamps, text


def test_a_stalled_recorder_loses_no_state(tmp_path):
    out = tmp_path / "stalled"
    proc = _start(out)
    lines, recorder = [], None
    for line in proc.stdout:
        lines.append(line)
        if recorder is None and "[bag_recorder]" in line:
            recorder = _recorder_pid(out)
        if "starting the program" in line:
            break
    assert recorder is not None, "".join(lines)
    time.sleep(0.3)
    os.kill(recorder, signal.SIGSTOP)  # the recorder takes nothing for 1.5 s; the graph runs on
    time.sleep(1.5)
    os.kill(recorder, signal.SIGCONT)
    _, stamps, _ = _finish(proc, lines, out)
    assert stamps[0] == 0 and np.all(np.diff(stamps) == 1_000_000)  # every period, none missing
    assert len(stamps) == 31_164  # the whole run: the same states as an unstalled run


def test_a_recorder_stalled_through_the_end_still_gets_every_state_and_event(tmp_path):
    """The recorder takes nothing from late in the program until after the composed plant and
    experiment have finished: the plant and the experiment wait for the recorder to confirm their
    last messages before their process exits, so the bag is complete all the same."""
    out = tmp_path / "stalled_end"
    proc = _start(out)
    lines, recorder, stopped = [], None, False
    for line in proc.stdout:
        lines.append(line)
        if recorder is None and "[bag_recorder]" in line:
            recorder = _recorder_pid(out)
        pct = re.search(r"\[\s*(\d+)%\]", line)
        if pct and int(pct.group(1)) >= 70 and recorder is not None and not stopped:
            # from here (the last third of the run) to after its end, the recorder takes nothing; a
            # stall shorter than the middleware's liveliness lease (20 s), which would unmatch it
            os.kill(recorder, signal.SIGSTOP)
            stopped = True
        if stopped and "complete:" in line:
            break
    assert stopped, "".join(lines)
    time.sleep(1.5)  # the program is over: the composed process now waits for the recorder
    os.kill(recorder, signal.SIGCONT)
    bag, stamps, text = _finish(proc, lines, out)
    assert len(stamps) == 31_164 and np.all(np.diff(stamps) == 1_000_000), text[-3000:]
    events = bag["/experiment_events"].fields["event"]
    # every segment's START has its END (START 0, END 1, ABORT 2), the last one included
    assert (events == 0).sum() > 0 and (events == 0).sum() == (events == 1).sum(), text[-3000:]
    assert events[-1] == 1, text[-3000:]
