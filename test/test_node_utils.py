"""Shared node plumbing: parameter validation, config flattening, loops, latency statistics."""

import math
import time

import numpy as np
import pytest

from friction_ros.core.config import Field, flatten, unflatten
from friction_ros.core.validation import ParameterError
from friction_ros.nodes.loops import DeadlineLoop, LatencyHistogram


def test_latency_histogram_matches_exact_percentiles_within_one_bin_in_constant_memory():
    x = np.random.default_rng(1).exponential(4e-4, 200_000)
    h = LatencyHistogram()
    for v in x:
        h.add(float(v))
    for q in (50, 90, 99):
        assert abs(h.percentile(q) - np.percentile(x, q)) <= LatencyHistogram.BIN_S
    assert h.max == x.max() and h.n == x.size
    assert h.counts.nbytes < 100_000  # does not grow with the number of samples
    assert math.isnan(LatencyHistogram().percentile(50))


def test_flatten_unflatten_round_trip():
    cfg = {"mode": "pid", "pid": {"p": 200.0, "d": 0.15}, "friction": {"model": "gms", "k": [1.0, 2.0]}}
    flat = flatten(cfg)
    assert flat["pid.p"] == 200.0 and flat["friction.k"] == [1.0, 2.0]
    assert unflatten(flat) == cfg


@pytest.mark.parametrize(
    "spec, value, message",
    [
        (Field("gain", 1.0, "g", lo=0.0, hi=10.0), 20.0, r"gain = 20 is out of range: must be in \[0, 10\]"),
        (Field("mode", "a", "m", choices=("a", "b")), "c", "must be one of a, b"),
        (Field("gain", 1.0, "g"), "x", "has type str: must be float"),
        (Field("gain", 1.0, "g"), math.nan, "nan is not a number"),
    ],
)
def test_param_check_names_the_parameter_and_the_allowed_values(spec, value, message):
    with pytest.raises(ParameterError, match=message):
        spec.check(value)


def test_deadline_loop_ticks_at_its_period_between_executor_callbacks():
    class Executor:  # stands in for an rclpy executor: spin_once waits up to the timeout
        def spin_once(self, timeout_sec):
            time.sleep(timeout_sec)

    ticks = []
    loop = DeadlineLoop(0.005, lambda: ticks.append(time.monotonic()))
    end = time.monotonic() + 0.5
    while time.monotonic() < end:
        loop.run_once(Executor())
    assert 80 <= loop.stats.cycles <= 101
    assert np.median(np.diff(ticks)) == pytest.approx(0.005, abs=0.001)


def test_deadline_loop_runs_waiting_callbacks_before_a_late_tick():
    """A command that arrived before the step is applied by it, even when the loop reaches the
    deadline late (the previous callback overran): it is not left a period behind the tick."""
    events = []

    class Executor:  # spin_once runs one waiting callback, else waits up to the timeout
        queue: list = []

        def spin_once(self, timeout_sec):
            if self.queue:
                self.queue.pop(0)()
            else:
                time.sleep(timeout_sec)

    ex = Executor()
    loop = DeadlineLoop(0.01, lambda: events.append("tick"))
    loop.run_once(ex)  # first tick at once
    ex.queue.append(lambda: events.append("command"))
    time.sleep(0.012)  # the deadline passed while the command was waiting
    loop.run_once(ex)
    assert events == ["tick", "command", "tick"]
    ex.queue.extend([lambda: events.append("a"), lambda: events.append("b"), lambda: events.append("c")])
    time.sleep(0.012)
    loop.run_once(ex)  # at most READY_BEFORE_TICK waiting callbacks go first: the tick is not starved
    assert events[3:] == ["a", "b", "tick"][: DeadlineLoop.READY_BEFORE_TICK] + ["tick"]
    assert ex.queue and loop.stats.cycles == 3


def test_deadline_loop_without_wake_on_events_handles_messages_just_before_the_tick():
    """wake_on_events=False: a message that arrives mid-period does not wake the loop (the executor
    is never asked to wait); it is handled right before the next tick, and ticks keep the period."""
    events = []

    class Executor:  # spin_once runs one waiting callback; a wait (timeout > 0) is recorded
        queue: list = []
        waits = 0

        def spin_once(self, timeout_sec):
            if timeout_sec > 0:
                self.waits += 1
            if self.queue:
                self.queue.pop(0)()
            elif timeout_sec > 0:
                time.sleep(timeout_sec)

    ex = Executor()
    loop = DeadlineLoop(0.01, lambda: events.append(("tick", time.monotonic())), wake_on_events=False)
    loop.EVENT_WAIT_EVERY = 1000  # no draining period in this window
    loop.run_once(ex)  # first tick at once
    first = events[0][1]
    ex.queue.append(lambda: events.append(("command", time.monotonic())))
    while loop.stats.cycles < 3:
        loop.run_once(ex)
    assert ex.waits == 0
    assert [e[0] for e in events] == ["tick", "command", "tick", "tick"]
    assert events[1][1] >= first + 0.01 - 1e-4  # handled at the deadline, not when it arrived
    assert events[2][1] - events[1][1] < 0.005  # and the tick follows it at once
    assert events[3][1] - events[2][1] == pytest.approx(0.01, abs=0.004)


def test_deadline_loop_without_wake_on_events_drains_a_fast_publishers_queue():
    """Three messages a period (more than READY_BEFORE_TICK): the periods that wait in the executor
    keep its queue bounded; without them it would hold ~2 x the periods run."""

    class Executor:  # one callback per spin_once; a wait returns at once when something is queued
        queue: list = []

        def spin_once(self, timeout_sec):
            if self.queue:
                self.queue.pop(0)()
            elif timeout_sec > 0:
                time.sleep(timeout_sec)

    ex = Executor()
    loop = DeadlineLoop(0.002, lambda: ex.queue.extend([lambda: None] * 3), wake_on_events=False)
    longest = 0
    while loop.stats.cycles < 60:
        loop.run_once(ex)
        longest = max(longest, len(ex.queue))
    assert longest <= (3 - DeadlineLoop.READY_BEFORE_TICK) * DeadlineLoop.EVENT_WAIT_EVERY + 3


def test_scheduling_parameters_pin_and_raise_every_thread_of_a_node(tmp_path):
    """drive_interface started with cpu_affinity / realtime_priority: all its threads (executor and
    the middleware's) end up on that CPU, with SCHED_FIFO where the machine permits it."""
    import os
    import signal
    import subprocess
    import sys

    cpu = max(os.sched_getaffinity(0))
    cmd = [sys.executable, "-m", "friction_ros.nodes.drive_interface", "--ros-args", "-p", "interface:=virtual",
           "-p", "channel:=sched_test", "-p", f"cpu_affinity:={cpu}", "-p", "realtime_priority:=5"]  # fmt: skip
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    try:

        def pinned() -> bool:
            tids = os.listdir(f"/proc/{proc.pid}/task")
            return len(tids) > 3 and all(os.sched_getaffinity(int(t)) == {cpu} for t in tids)

        deadline = time.monotonic() + 30.0
        while time.monotonic() < deadline and proc.poll() is None and not pinned():
            time.sleep(0.2)
        assert proc.poll() is None, proc.stdout.read()
        assert pinned()  # every thread (rclpy, Fast DDS) on the requested CPU
        try:  # does this machine permit SCHED_FIFO at all?
            os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(1))
            os.sched_setscheduler(0, os.SCHED_OTHER, os.sched_param(0))
            permitted = True
        except PermissionError:
            permitted = False

        def fifo() -> list[bool]:
            return [
                os.sched_getscheduler(int(t)) == os.SCHED_FIFO for t in os.listdir(f"/proc/{proc.pid}/task")
            ]

        # the node raises its threads one by one after start-up (a busy machine may take a while)
        while permitted and time.monotonic() < deadline and not all(fifo()):
            time.sleep(0.1)
        time.sleep(0.3)  # and they stay so
        assert all(fifo()) if permitted else not any(fifo())
    finally:
        proc.send_signal(signal.SIGINT)
        out, _ = proc.communicate(timeout=20)
    assert proc.returncode == 0, out
    assert "drive left safe" in out
    if not permitted:
        assert "SCHED_FIFO not permitted" in out


def test_nodes_use_the_packages_writer_profile_unless_the_user_has_one(tmp_path, monkeypatch):
    """Every node process points Fast DDS at the package's writer profile (a 0.1 s heartbeat, so an
    exiting node's last messages are confirmed in ~0.1 s, not Fast DDS's 3 s period); a profile the
    user names, or one in the working directory, is left as it is."""
    import xml.etree.ElementTree as ET

    from friction_ros.nodes.runtime import WRITER_PROFILE, use_writer_profile

    ns = {"d": "http://www.eprosima.com/XMLSchemas/fastRTPS_Profiles"}
    writer = ET.parse(WRITER_PROFILE).getroot().find("d:profiles/d:data_writer", ns)
    assert writer.get("is_default_profile") == "true"
    period = writer.find("d:times/d:heartbeatPeriod", ns)
    assert int(period.find("d:sec", ns).text) + int(
        period.find("d:nanosec", ns).text
    ) * 1e-9 == pytest.approx(0.1)
    monkeypatch.chdir(tmp_path)
    env: dict[str, str] = {}
    assert use_writer_profile(env) and env == {"FASTRTPS_DEFAULT_PROFILES_FILE": WRITER_PROFILE}
    for var in (
        "FASTRTPS_DEFAULT_PROFILES_FILE",
        "FASTDDS_DEFAULT_PROFILES_FILE",
        "RMW_FASTRTPS_USE_QOS_FROM_XML",
    ):
        env = {var: "/robot/dds.xml"}
        assert not use_writer_profile(env) and env == {var: "/robot/dds.xml"}
    (tmp_path / "DEFAULT_FASTRTPS_PROFILES.xml").write_text("<dds/>")
    env = {}
    assert not use_writer_profile(env) and env == {}
