"""friction-experiment over real DDS: plant_simulator + bag_recorder + identification_experiment as
separate processes, lockstep on the ABB M19-S preset; the bag is checked with rosbags (independent
reader) and the static friction map is read straight from it."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

from friction_ros.core.presets import load_preset


@pytest.fixture(scope="module")
def quick_bag(tmp_path_factory):
    out = tmp_path_factory.mktemp("experiment") / "quick_bag"
    r = subprocess.run(
        [
            sys.executable,
            "-m",
            "friction_ros.cli.experiment",
            "--profile",
            "quick",
            "--mode",
            "lockstep",
            "--preset",
            "abb_m19s",
            "--sizing",
            "profile",  # the profile's program as written (the sized one is tested in test_joint_sizing)
            "--diagnostics",
            "-o",
            str(out),
            "--timeout",
            "240",
        ],
        capture_output=True,
        text=True,
        timeout=300,
    )
    return out, r


def test_cli_runs_quick_profile_and_prints_summary(quick_bag):
    out, r = quick_bag
    assert r.returncode == 0, r.stdout[-3000:] + r.stderr[-3000:]
    assert f"bag: {out.resolve()}" in r.stdout
    assert "plateau map" in r.stdout and "breakaway torques" in r.stdout
    # the truth column is the joint-level friction of the preset: the plateaus agree with it
    errors = [
        float(ln.split()[-1].rstrip("%"))
        for ln in r.stdout.splitlines()
        if ln.strip().startswith("plateau") and ln.rstrip().endswith("%")
    ]
    assert errors and max(abs(e) for e in errors) < 5.0, errors
    assert "Traceback" not in r.stdout + r.stderr
    assert (out / "metadata.yaml").is_file()


def test_rosbags_reads_the_bag_with_segment_markers(quick_bag):
    from rosbags.rosbag2 import Reader
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    out, r = quick_bag
    assert r.returncode == 0, r.stderr[-3000:]
    ts = get_typestore(Stores.EMPTY)
    with Reader(out) as reader:
        conns = {c.topic: (c.msgtype, c.msgcount) for c in reader.connections}
        assert conns["/joint_states"][0] == "sensor_msgs/msg/JointState"
        assert conns["/experiment_events"][0] == "friction_msgs/msg/ExperimentEvent"
        assert conns["/joint_states"][1] > 20000  # ~29 s at 1 kHz
        for c in reader.connections:
            ts.register(get_types_from_msg(c.msgdef.data, c.msgtype))
        events = [
            ts.deserialize_cdr(raw, c.msgtype)
            for c, _, raw in reader.messages()
            if c.topic == "/experiment_events"
        ]
    starts = [e for e in events if e.event == 0]
    ends = [e for e in events if e.event == 1]
    assert not [e for e in events if e.event == 2]
    assert len(starts) == len(ends) == 14
    assert [e.program for e in ends][:2] == ["breakaway", "breakaway"]
    assert {e.program for e in ends} == {"breakaway", "plateaus", "presliding", "random", "chirp"}
    for e in ends[:2]:  # breakaway torques in the END target
        assert abs(e.target) == pytest.approx(0.95, rel=0.03)


def test_static_friction_map_read_directly_matches_preset(quick_bag):
    from friction_ros.core.identification.data.plateau_map import breakaway_torques, plateau_map

    out, r = quick_bag
    assert r.returncode == 0, r.stderr[-3000:]
    pm = plateau_map(out, "joint1")
    assert len(pm) == 8 and pm.settle == 0.2
    truth = load_preset("abb_m19s").friction
    v, tau, sd = pm.velocity, pm.torque, pm.torque_std
    assert np.all(np.sign(v) == np.sign(pm.column("target")))
    np.testing.assert_allclose(v, pm.column("target"), rtol=0.03)
    np.testing.assert_allclose(tau, truth.steady_state(v), rtol=0.05)
    assert np.all((sd > 0) & (sd < 0.05))  # spread: sensor noise, no stick-slip
    agg = pm.aggregate()
    assert len(agg) == 8 and all(a["repeats"] == 1 for a in agg)
    assert [round(abs(b), 2) for _, b in breakaway_torques(out)] == [0.95, 0.95]


def test_bad_parameters_give_one_clear_line(tmp_path):
    r = subprocess.run(
        [
            sys.executable,
            "-m",
            "friction_ros.cli.experiment",
            "--set",
            "plateaus.v_min=-1",
            "-o",
            str(tmp_path / "x"),
        ],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert r.returncode == 2 and "Traceback" not in r.stderr
    assert "plateaus.v_min = -1 is out of range" in r.stderr
    r = subprocess.run(
        [
            sys.executable,
            "-m",
            "friction_ros.nodes.identification_experiment",
            "--ros-args",
            "-p",
            "breakaway.counts:=0",
        ],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert r.returncode == 2 and "Traceback" not in r.stderr
    assert "breakaway.counts = 0 is out of range" in r.stderr


# ---------------------------------------------------------------------------------------- failed runs
def _experiment(tmp_path, *args, timeout=180):
    """Run the CLI; past ``timeout`` it is stopped with SIGTERM (it then stops its nodes) before the
    test fails, so that no node outlives the test and loads the rest of the suite."""
    cmd = [sys.executable, "-m", "friction_ros.cli.experiment", "--profile", "quick", *args]
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=tmp_path)
    try:
        out, err = proc.communicate(timeout=timeout)
    except subprocess.TimeoutExpired:
        proc.terminate()
        try:
            out, err = proc.communicate(timeout=30)
        except subprocess.TimeoutExpired:
            proc.kill()
            out, err = proc.communicate()
        pytest.fail(
            f"friction-experiment {' '.join(args)} ran past {timeout} s:\n{out[-3000:]}\n{err[-2000:]}"
        )
    return subprocess.CompletedProcess(cmd, proc.returncode, out, err)


class _Joint:
    """A real-time simulated joint in its own process, standing in for drive_interface (--no-sim)."""

    def __init__(self, **params):
        args = [a for k, v in params.items() for a in ("-p", f"{k}:={v}")]
        self.proc = subprocess.Popen(
            [sys.executable, "-m", "friction_ros.nodes.plant_simulator", "--ros-args", *args],
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
        )

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.proc.terminate()
        self.proc.wait(timeout=20)


def _one_error_line(r) -> str:
    err = r.stderr.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("error: "), r.stderr[-3000:]
    out = r.stdout + r.stderr
    assert "Traceback" not in out and "KeyboardInterrupt" not in out, out[-3000:]
    return err[0]


def test_a_joint_that_cannot_move_ends_with_abort_the_reason_and_exit_1(tmp_path):
    """--no-sim on a faulted drive (every command rejected: zero torque, position stays put): the
    program stops after three plateaus without motion instead of running its 5.6 s, with an ABORT
    event naming the reason, and the CLI exits 1 with that reason as its one error line."""
    from friction_ros.core.identification.data.plateau_map import experiment_events

    out = tmp_path / "stuck"
    with _Joint(max_effort=0.001):  # rejects every command above 1 mN*m: a drive that does not move
        r = _experiment(
            tmp_path, "--no-sim", "--program", "plateaus", "-o", str(out), "--quiet", "--timeout", "60"
        )
    assert r.returncode == 1, r.stdout[-3000:] + r.stderr[-3000:]
    line = _one_error_line(r)
    assert "joint not excited: 3 segments in a row without the expected motion" in line
    assert "held +0 rad/s on average" in line and "motion_check.fraction" in line
    ev = experiment_events(out, "joint1")
    aborts = [e for e in ev if e.event == 2]
    assert [e.segment for e in aborts][-1] == "program" and aborts[-1].note in line
    assert len(aborts) == 4 and not [e for e in ev if e.event == 1]  # no plateau completed
    start = min(e.time for e in ev)  # the program's first event (after the wait for the recorder)
    assert aborts[-1].time - start < 3.0  # stopped after ~2.1 s of the 5.6 s program
    assert "4 ABORT" in r.stdout and "plateau map: no plateau completed" in r.stdout


@pytest.mark.parametrize("quiet", [True, False])
def test_a_node_that_refuses_its_parameters_is_the_one_line_the_user_sees(tmp_path, quiet):
    """The experiment node refuses a parameter file (unknown key): the plant and the recorder are
    stopped quietly, the one error line names the node and the key, exit 2, and the bag folder it
    created is gone so the same -o works again."""
    bad = tmp_path / "bad.yaml"
    bad.write_text("identification_experiment:\n  ros__parameters:\n    bogus_key: 1\n")
    out = tmp_path / "refused"
    r = _experiment(
        tmp_path, "--mode", "lockstep", "--params", str(bad), "-o", str(out), *(["--quiet"] * quiet)
    )
    assert r.returncode == 2, r.stdout[-3000:] + r.stderr[-3000:]
    line = _one_error_line(r)
    assert line.startswith("error: identification_experiment: unknown parameter(s) bogus_key")
    assert "bag has no topic" not in r.stdout + r.stderr
    assert not out.exists()
    if not quiet:  # the node's own line was forwarded; nothing else failed
        assert "[identification_experiment] error:" in r.stdout
        assert "exited with code" not in r.stdout + r.stderr


def test_a_wrong_joint_name_is_named_instead_of_waiting_silently(tmp_path):
    """drive_interface's old default joint name 'joint' against the experiment's 'joint1': the
    experiment logs the joints it sees; on the timeout that is the error line; no folder is left."""
    out = tmp_path / "wrong_joint"
    with _Joint(joint_name="joint"):
        # long enough for the first joint states to arrive on a busy machine (it waits it out)
        r = _experiment(tmp_path, "--no-sim", "-o", str(out), "--timeout", "15")
    assert r.returncode == 1, r.stdout[-3000:] + r.stderr[-3000:]
    line = _one_error_line(r)
    assert "timed out" in line and "joint_states carry no joint 'joint1' (they carry: joint)" in line
    assert "[identification_experiment]" in r.stdout and "carry no joint 'joint1'" in r.stdout
    assert not out.exists()


def test_user_limits_constrain_the_program_instead_of_aborting_it(tmp_path):
    """README's real-joint call with --set limits.max_travel=3.0: the profile's 5 rad/s plateaus
    (3.5 rad each) are re-derived to fit (2.143 rad/s, 1.5 rad), so the run completes inside 3 rad."""
    from friction_ros.core.bag import read_bag
    from friction_ros.core.identification.data.plateau_map import experiment_events

    out = tmp_path / "limited"
    with _Joint():
        r = _experiment(
            tmp_path, "--no-sim", "--program", "plateaus", "--set", "limits.max_travel=3.0", "-o", str(out),
            "--quiet", "--timeout", "90",
            # what is tested is the program fitted to the limits; the motion check (tested on its own)
            # failed a slow real-time plateau in 2 of 16 runs with both cores busy
            "--set", "motion_check.fraction=0",
        )  # fmt: skip
    assert r.returncode == 0, r.stdout[-3000:] + r.stderr[-3000:]
    ev = experiment_events(out, "joint1")
    assert not [e for e in ev if e.event == 2]
    targets = sorted({abs(e.target) for e in ev if e.event == 1})
    assert max(targets) == pytest.approx(3.0 * 0.5 / 0.7, rel=1e-3)  # half the travel per 0.7 s plateau
    assert targets[0] == pytest.approx(0.2 * max(targets) / 5.0, rel=1e-3)  # the profile's span kept
    pos = read_bag(out)["/joint_states"].joint("joint1").position
    assert np.ptp(pos) < 3.0
