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
    from friction_ros.core.plateaus import breakaway_torques, plateau_map

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
