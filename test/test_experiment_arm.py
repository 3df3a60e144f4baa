"""Identification experiments on an arm: the core sequencing (one_at_a_time / together, PD hold,
safety) on toy joints, the CLI's per-joint sizing, and friction-experiment over real DDS on a
3-joint lockstep plant: the bag read back has each joint's segments in turn, the held joints stay
put, ``friction-fit BAG --joint jX`` fits each joint from its own segments, and a per-joint limit
stops the whole arm with zero torque on every joint."""

from __future__ import annotations

import json
import math
import subprocess
import sys

import numpy as np
import pytest

from friction_ros.core.experiment.arm import ARM_PROGRAM, ArmExperiment, hold_gains
from friction_ros.core.experiment.events import ABORT, END, START
from friction_ros.core.experiment.excitation import ExcitationProgram


# ------------------------------------------------------------------------------------ core, toy joints
def _cfg(**kw):
    c = {
        "program": "plateaus",
        "profile": "quick",
        "plateaus": {"v_min": 0.5, "v_max": 2.0, "count": 2, "repeats": 1, "settle": 0.2, "hold": 0.3},
    }
    c.update(kw)
    return c


def _simulate(arm, t_end, J=0.0012, fc=0.3, b=0.01, push=None):
    """Rigid joints with Coulomb + viscous friction, 1 kHz; ``push(t, q)``: external torques."""
    n = len(arm.joints)
    q, v, dt = np.zeros(n), np.zeros(n), 1e-3
    rows, events = [], []
    for k in range(int(round(t_end / dt))):
        t = k * dt
        tau, ev = arm.update(t, q, v)
        events += ev
        tau = np.asarray(tau)
        ext = np.zeros(n) if push is None else np.asarray(push(t, q))
        drive = tau + ext
        f = np.where(np.abs(v) > 1e-6, fc * np.sign(v), np.clip(drive, -fc, fc))
        v = v + (drive - f - b * v) / J * dt
        v = np.where((np.abs(v) < 1e-4) & (np.abs(drive) <= fc), 0.0, v)
        q = q + v * dt
        rows.append((t, *q, *tau))
        if arm.done and arm.t > t_end:
            break
    return np.array(rows), events


def _window(events, i):
    ts = [e.time for j, e in events if j == i]
    return min(ts), max(ts)


def test_one_at_a_time_runs_the_joints_in_turn_and_holds_the_others():
    progs = [ExcitationProgram(_cfg()) for _ in range(3)]
    arm = ArmExperiment(["a", "b", "c"], progs, "one_at_a_time", gap=0.3)
    assert arm.total_duration == pytest.approx(3 * progs[0].total_duration + 2 * 0.3)
    assert arm.marked_count == 12
    # hold gains: the velocity loop's (the tracking design's PD: p = K_d, i = K_p), within the limits
    h = arm.holds[0]
    assert (h.p, h.d, h.limit, h.bias) == (20.0, 0.5, 2.0, 0.0)
    log, events = _simulate(arm, arm.total_duration + 0.2)
    assert arm.done and not arm.aborted and arm.not_excited is None
    for i in range(3):
        own = [e for j, e in events if j == i]
        assert [e.event for e in own] == [START, END] * 4
        assert [e.segment for e in own[::2]] == ["plateau+2", "plateau-2", "plateau+0.5", "plateau-0.5"]
    w = [_window(events, i) for i in range(3)]
    for k in range(2):  # in turn, joint_gap apart
        assert w[k + 1][0] - w[k][1] == pytest.approx(0.3, abs=1.5e-3)
    t = log[:, 0]
    for i in range(3):  # a joint not being excited stays put (a waiting joint exactly at its start)
        for o in range(3):
            if o != i:
                m = (t >= w[o][0]) & (t <= w[o][1])
                assert np.ptp(log[m, 1 + i]) < 1e-3, (i, o)
        assert np.all(log[t < w[i][0], 1 + i] == 0.0)


def test_together_starts_every_joint_at_once_and_holds_the_early_finisher():
    short = ExcitationProgram(_cfg(plateaus={"v_min": 1.0, "v_max": 2.0, "count": 1, "repeats": 1}))
    long = ExcitationProgram(_cfg())
    arm = ArmExperiment(["a", "b"], [short, long], "together")
    assert arm.total_duration == pytest.approx(long.total_duration)
    log, events = _simulate(arm, arm.total_duration + 0.2)
    assert arm.done and not arm.aborted
    (s0, e0), (s1, e1) = _window(events, 0), _window(events, 1)
    assert s0 == s1 == 0.0 and e0 < e1
    m = log[:, 0] > e0 + 0.2  # short one held where it ended while the other runs on
    assert np.ptp(log[m & (log[:, 0] <= e1), 1]) < 1e-3


def test_a_held_joint_leaving_its_limits_stops_every_joint():
    """j2 is pushed (3 N*m, above its 2 N*m hold) while j1 runs: j2 passes its 0.2 rad travel, the
    whole arm stops with zero torque on both joints, the reason names j2 and the limit, and j1's
    open segment ends with an ABORT saying why."""
    progs = [ExcitationProgram(_cfg()), ExcitationProgram(_cfg(limits={"max_travel": 0.2}))]
    arm = ArmExperiment(["j1", "j2"], progs, "one_at_a_time", gap=0.3)
    log, events = _simulate(arm, 2.0, push=lambda t, q: [0.0, 3.0 if t >= 0.5 else 0.0])
    assert arm.done and arm.aborted and arm.stopped and arm.failed_joint == "j2"
    reason = arm.abort_reasons[-1]
    assert reason.startswith("joint j2: position limit while held: travel +0.2")
    assert "exceeds limits.max_travel = 0.2 rad" in reason
    aborts = [(j, e) for j, e in events if e.event == ABORT]
    assert [(j, e.program, e.segment) for j, e in aborts] == [
        (1, ARM_PROGRAM, "hold"),
        (0, "plateaus", "plateau-2"),
    ]
    assert aborts[1][1].note == f"stopped: {reason}"
    t_stop = aborts[0][1].time
    assert 0.5 < t_stop < 0.8
    after = log[:, 0] > t_stop
    assert after.sum() > 1000 and np.all(log[after, 3:] == 0.0)  # every joint's torque: exactly 0
    assert not np.all(log[log[:, 0] < t_stop, 3] == 0.0)  # j1 was driven before


def test_a_joint_not_excited_stops_the_arm_and_is_named():
    arm = ArmExperiment(["j1", "j2"], [ExcitationProgram(_cfg()) for _ in range(2)], gap=0.0)
    _simulate(arm, arm.total_duration + 1.0, fc=np.array([0.3, 5.0]))  # j2: stuck beyond 2 N*m
    assert arm.done and arm.stopped and not arm.aborted and arm.failed_joint == "j2"
    assert arm.not_excited.startswith("joint not excited: joint j2: ")


def test_hold_gains_from_the_velocity_loop_within_the_torque_limit():
    prog = ExcitationProgram(
        _cfg(velocity_loop={"p": 0.3, "i": 12.0, "torque_limit": 2.0}, limits={"max_torque": 2.5}, bias=1.0)
    )
    h = hold_gains(prog.config)
    assert (h.p, h.d, h.limit, h.bias) == (12.0, 0.3, 1.5, 1.0)
    assert h.torque(0.0, -1.0, 0.0) == 2.5 and h.torque(0.0, 1.0, 0.0) == -0.5  # bias +- limit
    assert hold_gains(prog.config, p=50.0, d=2.0).p == 50.0


# ------------------------------------------------------------------------------------ CLI sizing
GRAVITY_FILE = """\
plant_simulator:
  ros__parameters:
    joints: [j1, j2]
    presets: [abb_m19s, abb_m19s]
    plant:
      j2:
        gravity: 2.0
        gravity_phase: 1.5707963267948966
identification_experiment:
  ros__parameters:
    gap: 0.2
    limits:
      j1:
        max_travel: 0.05
"""


def test_cli_sizes_each_joint_to_its_plant_with_per_joint_sets(tmp_path):
    from friction_ros.cli.experiment import build_parser
    from friction_ros.cli.experiment_arm import arm_setup
    from friction_ros.cli.experiment_config import parse_sets

    args = build_parser().parse_args(
        ["--profile", "quick", "--joints", "j1,j2", "--presets", "abb_m19s,seed004_dc_motor"]
        + ["--set", "plateaus.count=3", "--set", "limits.j2.max_travel=3.0"]
    )
    arm = arm_setup(args, parse_sets(args.set))
    p = arm.node_params
    assert arm.joints == ["j1", "j2"] and arm.presets == ["abb_m19s", "seed004_dc_motor"]
    assert p["plateaus.j1.count"] == p["plateaus.j2.count"] == 3
    assert p["limits.j2.max_travel"] == 3.0 and p["limits.j1.max_travel"] == 100.0
    assert p["plateaus.j2.v_max"] == pytest.approx(3.0 * 0.5 / 0.7)  # fitted to j2's travel only
    assert p["plateaus.j1.v_max"] == pytest.approx(500.0 / 7.0)
    assert p["gains.j1.bias"] == 0.0 and p["gains.j1.gap"] == 0.3
    assert p["breakaway.j1.start"] == pytest.approx(0.475, rel=0.01)  # half the breakaway torques
    assert p["breakaway.j2.start"] == pytest.approx(4.1435e-4, rel=0.01)
    assert p["limits.j2.max_torque"] < 0.01 < p["limits.j1.max_torque"]
    assert not any(k.count(".") == 1 for k in p)  # only per-joint names
    # a multi-joint parameter file: joints, presets and the pendulum load from it; the held load
    # at the start position (-2 N*m at q = 0) is the joint's bias
    f = tmp_path / "arm.yaml"
    f.write_text(GRAVITY_FILE)
    args = build_parser().parse_args(["--profile", "quick", "--params", str(f)])
    arm = arm_setup(args, {})
    assert arm.joints == ["j1", "j2"] and arm.presets == ["abb_m19s", "abb_m19s"]
    assert arm.node_params["gains.j2.bias"] == pytest.approx(2.0) and arm.node_params["gains.j1.bias"] == 0.0
    # the file's node-level gap applies to every joint (no sized per-joint gap over it); its
    # per-joint limit is not sized, it wins over the sized value as the later parameter file
    assert "gains.j1.gap" not in arm.node_params and arm.node_params["limits.j1.max_travel"] == 100.0
    assert arm.total_duration("one_at_a_time", 0.5) == pytest.approx(sum(arm.durations) + 0.5)
    assert arm.total_duration("together", 0.5) == max(arm.durations)


def test_commands_carry_every_joint():
    from friction_ros.core.wire import JointStateDecoder
    from friction_ros.nodes.commands import ArmCommandPublisher

    class _Node:
        def create_publisher(self, *a):
            return type("P", (), {"publish": lambda self, m: None})()

        def get_fully_qualified_name(self):
            return "/arm/experiment"

    pub = ArmCommandPublisher(_Node(), ["j1", "j2", "j3"])
    pub.publish(type("S", (), {"sec": 3, "nanosec": 7})(), [0.5, -1.0, 0.0])
    msg = JointStateDecoder().decode(pub.last)
    assert list(msg.name) == ["j1", "j2", "j3"] and list(msg.effort) == [0.5, -1.0, 0.0]
    assert (msg.sec, msg.nanosec) == (3, 7) and len(msg.position) == 0
    assert msg.frame_id == "/arm/experiment"  # the command source (one owner per joint)


def test_node_names_a_bad_per_joint_value(tmp_path):
    r = subprocess.run(
        [sys.executable, "-m", "friction_ros.nodes.identification_experiment", "--ros-args"]
        + ["-p", "joints:=[j1,j2]", "-p", "plateaus.j2.v_min:=-1.0"],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert r.returncode == 2 and "Traceback" not in r.stderr, r.stderr[-2000:]
    assert "plateaus.j2.v_min = -1 is out of range" in r.stderr


# ------------------------------------------------------------------------------------ over DDS
JOINTS = ["j1", "j2", "j3"]
PRESETS = ["abb_m19s", "seed004_dc_motor", "abb_m19s"]


def _experiment(cwd, *args, timeout=240):
    return subprocess.run(
        [sys.executable, "-m", "friction_ros.cli.experiment", "--profile", "quick", "--program", "plateaus"]
        + ["--mode", "lockstep", *args],
        capture_output=True,
        text=True,
        timeout=timeout,
        cwd=cwd,
    )


@pytest.fixture(scope="module")
def arm_bag(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("arm")
    out = tmp / "arm_bag"
    r = _experiment(
        tmp, "--joints", ",".join(JOINTS), "--presets", ",".join(PRESETS), "--joint-gap", "0.3",
        "--set", "plateaus.count=3", "--set", "plateaus.v_min=0.5", "-o", str(out), "--quiet",
        "--timeout", "150",
    )  # fmt: skip
    return out, r


def _events(bag):
    from friction_ros.core.bag import read_bag

    b = read_bag(bag)
    js, ev = b["/joint_states"], b["/experiment_events"]
    return js, ev, np.asarray([str(f) for f in ev["header.frame_id"]])


def test_arm_bag_has_each_joints_segments_in_turn(arm_bag):
    out, r = arm_bag
    assert r.returncode == 0, r.stdout[-3000:] + r.stderr[-3000:]
    assert "Traceback" not in r.stdout + r.stderr
    assert "joints j1, j2, j3 (one_at_a_time)" in r.stdout
    js, ev, frames = _events(out)
    assert js.joint_names == JOINTS
    assert set(frames) == set(JOINTS)
    windows = []
    for j in JOINTS:
        own = frames == j
        kinds = ev["event"][own].tolist()
        assert kinds == [START, END] * 6, (j, kinds)
        segs = [str(s) for s in ev["segment"][own][::2]]
        assert segs[:2] == ["plateau+71.43", "plateau-71.43"] and segs[-2:] == ["plateau+0.5", "plateau-0.5"]
        windows.append((ev.stamp[own].min(), ev.stamp[own].max()))
    for (_, end), (start, _) in zip(windows, windows[1:]):
        assert start - end == pytest.approx(0.3, abs=2e-3)  # one after another, joint_gap apart
    # the held joints stay within a small band while another is excited
    t = js.stamp
    for i, j in enumerate(JOINTS):
        s = js.joint(j)
        for k, (a, b) in enumerate(windows):
            if k == i:
                continue
            m = (t >= a) & (t <= b)
            assert np.ptp(s.position[m]) < 1e-3, (j, JOINTS[k], np.ptp(s.position[m]))
            assert np.max(np.abs(s.velocity[m])) < 0.2, (j, JOINTS[k])
        own = (t >= windows[i][0]) & (t <= windows[i][1])
        assert np.ptp(s.position[own]) > 1.0  # ... and it moves in its own turn
    # the summary: one per joint, each plateau within 1 % of the preset's friction
    errors = [
        float(ln.split()[-1].rstrip("%"))
        for ln in r.stdout.splitlines()
        if ln.strip().startswith("plateau") and ln.rstrip().endswith("%")
    ]
    assert len(errors) >= 12 and max(abs(e) for e in errors) < 1.0, errors
    for j in JOINTS:
        assert f"joint {j}: " in r.stdout and "6 START, 6 END, 0 ABORT" in r.stdout


@pytest.mark.parametrize("joint, preset", list(zip(JOINTS, PRESETS)))
def test_friction_fit_fits_each_joint_from_its_own_segments(arm_bag, tmp_path, joint, preset):
    from friction_ros.core.presets import load_preset

    out, r = arm_bag
    assert r.returncode == 0, r.stderr[-3000:]
    fit = subprocess.run(
        [sys.executable, "-m", "friction_ros.cli.fit", str(out), "--joint", joint]
        + ["--models", "coulomb", "coulomb_viscous", "--no-plots", "--quiet", "--out", str(tmp_path / "fit")],
        capture_output=True,
        text=True,
        timeout=180,
    )
    assert fit.returncode == 0, fit.stdout[-3000:] + fit.stderr[-3000:]
    summary = json.loads((tmp_path / "fit" / "summary.json").read_text())
    assert summary["joint"] == joint
    js, ev, frames = _events(out)
    own = frames == joint
    t0 = js.stamp[0]
    a, b = ev.stamp[own].min() - t0, ev.stamp[own].max() - t0
    plateaus = summary["plateaus"]
    assert len(plateaus) >= 4, plateaus  # its own: not the 18 plateaus of the three joints
    assert all(p["source"] == "events" and a <= p["t_start"] < p["t_end"] <= b + 1e-6 for p in plateaus)
    targets = {abs(float(x)) for x in ev["target"][own]}
    truth = load_preset(preset)
    for p in plateaus:  # its own speeds, and its own plant's friction at them
        assert min(abs(abs(p["velocity"]) - v) / v for v in targets) < 0.02
        true = float(truth.joint_friction(np.array([p["velocity"]]))[0])
        assert p["torque"] == pytest.approx(true, rel=0.01)
    if preset == "abb_m19s":  # Coulomb 0.8 N*m + viscous 0.01 N*m*s/rad above the Stribeck speed
        assert summary["recommended"] == "coulomb_viscous"
        c = summary["models"]["coulomb_viscous"]["coefficients"]
        assert c["fc"] == pytest.approx(0.8, rel=0.01) and c["fv"] == pytest.approx(0.01, rel=0.03)


def test_a_per_joint_limit_stops_the_whole_arm_with_zero_torque(tmp_path):
    """A multi-joint parameter file (joints, presets, j2 lifting a link against 2 N*m gravity, a
    0.05 rad travel limit for j1): j1's first plateau passes it; one line names j1 and its limit,
    exit 3, and from then on neither joint gets torque: the held j2 drops."""
    f = tmp_path / "arm.yaml"
    f.write_text(GRAVITY_FILE)
    out = tmp_path / "aborted"
    r = _experiment(tmp_path, "--params", str(f), "-o", str(out), "--timeout", "90", timeout=150)
    assert r.returncode == 3, r.stdout[-3000:] + r.stderr[-3000:]
    text = r.stdout + r.stderr
    assert "Traceback" not in text
    lines = [ln for ln in text.splitlines() if "stopped by a safety limit" in ln]
    assert len(lines) == 1, lines
    assert (
        lines[0]
        .split("[identification_experiment]: ")[1]
        .startswith("program stopped by a safety limit at t = 0.01 s: joint j1: position limit: travel +0.05")
    )
    assert lines[0].endswith("exceeds limits.j1.max_travel = 0.05 rad")
    js, ev, frames = _events(out)
    aborts = ev["event"] == ABORT
    assert frames[aborts].tolist() == ["j1"] and ev["program"][aborts].tolist() == ["plateaus"]
    t_abort = ev.stamp[aborts][0]
    t = js.stamp
    after = t > t_abort + 0.02  # the current loop has followed the zero command
    assert after.sum() > 150  # the end tail (0.2 s) is recorded
    j1, j2 = js.joint("j1"), js.joint("j2")
    for s in (j1, j2):  # zero torque but the measured current's noise (~1 mN*m)
        assert np.max(np.abs(s.effort[after])) < 0.01, np.max(np.abs(s.effort[after]))
    before = t <= t_abort
    assert np.max(j2.effort[before]) > 1.5  # j2 was held against gravity (bias +2 N*m) ...
    assert j2.position[-1] < -0.5  # ... and falls once its torque is zero
    assert math.isfinite(j2.position[-1])


def test_set_values_in_exponent_form_are_numbers():
    """``--set breakaway.resolution=1e-4`` was refused as text (YAML 1.1 reads 1e-4 without a dot
    as a string)."""
    from friction_ros.cli.experiment_config import parse_sets

    got = parse_sets(["breakaway.resolution=1e-4", "plateaus.v_max=2", "profile=quick", "x=[1, 2]"])
    assert got == {"breakaway.resolution": 1e-4, "plateaus.v_max": 2, "profile": "quick", "x": [1, 2]}
