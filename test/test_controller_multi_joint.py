"""Issue 18: one compensating_controller for N joints (per-joint parameters in the ros2_controllers
layout), over DDS: it equals N single-joint controllers, handles a missing joint per joint and names
the joint and the key of a bad per-joint parameter."""

from __future__ import annotations

import math
import subprocess
import sys
import time

import pytest
from ros_graph import Graph, Listener, write_params

from friction_ros.cli.bringup import NodeSpec
from friction_ros.core.joint_config import JointLayout, joint_values
from friction_ros.core.wire import JointStateEncoder
from friction_ros.nodes.qos import RECORDED_QOS

JOINTS = [f"joint{i}" for i in range(1, 8)]


def _joint_params(i: int) -> dict:
    """Single-joint parameters of joint i (1..7): different gains, models, loads and references."""
    models = [
        {"model": "lugre", "fc": 1.0, "fs": 1.4, "vs": 0.02, "sigma0": 1e4, "sigma1": 30.0, "fv": 0.5},
        {"model": "coulomb_viscous", "fc": 2.0, "fv": 1.5},
        {"model": "stribeck", "fc": 0.6, "fs": 0.9, "vs": 0.05, "fv": 0.3},
    ]
    return {
        "pid": {
            "p": 150.0 + 10 * i,
            "i": 20.0,
            "d": 1.0 + 0.1 * i,
            "u_clamp_max": 40.0 + i,
            "u_clamp_min": -40.0 - i,
        },
        "inertia": 0.01 * i,
        "effort_limit": 50.0 + i,
        "friction": models[i % 3],
        "compensation": {"source": "blended" if i % 2 else "feedforward", "gain": 0.8 + 0.02 * i},
        "load": {"gravity": 1.5 * (i % 4), "gravity_phase": 0.1 * i, "load_friction": 0.02 * (i % 2)},
        "reference": {"type": "sinusoid", "amplitude": 0.2 + 0.05 * i, "frequency": 0.5 + 0.1 * i},
    }


def _multi_params() -> dict:
    """The same 7 joints in one node: node-level defaults + gains.<joint>.* / <section>.<joint>.*"""
    doc: dict = {"joints": JOINTS, "pid": {"p": 100.0, "i": 0.0, "d": 1.0}, "gains": {}}
    for i, j in enumerate(JOINTS, start=1):
        p = _joint_params(i)
        doc["gains"][j] = {
            **p["pid"],
            "inertia": p["inertia"],
            "effort_limit": p["effort_limit"],
        }  # ros2_controllers: u_clamp_* are the PID's
        for section in ("friction", "compensation", "load", "reference"):
            doc.setdefault(section, {})[j] = p[section]
    return doc


def test_layout_resolves_the_per_joint_values_like_the_single_joint_file():
    from friction_ros.core.config import flatten
    from friction_ros.core.control.controller_config import CONTROLLER_FIELDS
    from friction_ros.core.control.pid import PID_SCHEMA

    doc = _multi_params()
    layout = JointLayout(
        JOINTS,
        ["pid", "friction", "compensation", "load", "reference"],
        "pid",
        [f.name for f in PID_SCHEMA],
        [f.name for f in CONTROLLER_FIELDS],
    )
    flat = flatten({k: v for k, v in doc.items() if k != "joints"})
    node, per_joint = layout.split_all(flat)
    assert node == {"pid.p": 100.0, "pid.i": 0.0, "pid.d": 1.0}
    for i, j in enumerate(JOINTS, start=1):
        got = joint_values(
            {"pid": {"p": 100.0, "i": 0.0, "d": 1.0}, "friction": {"model": "none"}}, per_joint[j]
        )
        want = _joint_params(i)
        assert got["pid"] == want["pid"] and got["friction"] == want["friction"]
        assert got["load"] == want["load"] and got["inertia"] == want["inertia"]
    with pytest.raises(Exception, match=r"gains\.joint2\.bogus: 'bogus' is not a per-joint gain"):
        layout.split("gains.joint2.bogus")


def _states(k: int) -> tuple[list[float], list[float], list[float]]:
    """Deterministic 7-joint states at step k (motion with some irregularity)."""
    t = 0.002 * k
    pos = [0.3 * math.sin(2 * math.pi * 0.4 * t + i) + 1e-4 * ((k * (i + 3)) % 7) for i in range(7)]
    vel = [0.3 * 2 * math.pi * 0.4 * math.cos(2 * math.pi * 0.4 * t + i) for i in range(7)]
    eff = [0.0] * 7
    return pos, vel, eff


@pytest.mark.ros
def test_seven_joints_in_one_controller_equal_seven_single_joint_controllers(tmp_path):
    """Lockstep: every state waits until all 8 controllers answered it (a lost one is re-sent, a
    duplicate changes nothing), so both sides see the same samples; commands agree to 1e-9."""
    from sensor_msgs.msg import JointState

    docs = {"/**/compensating_controller": {"ros__parameters": {**_multi_params(), "state_timeout": 60.0}}}
    multi = write_params(tmp_path / "multi.yaml", docs)
    specs = [NodeSpec("compensating_controller", "multi", [multi])]
    for i, j in enumerate(JOINTS, start=1):
        single = write_params(
            tmp_path / f"{j}.yaml",
            {
                "/**/compensating_controller": {
                    "ros__parameters": {**_joint_params(i), "joint_name": j, "state_timeout": 60.0}
                }
            },
        )
        specs.append(NodeSpec("compensating_controller", f"s{i}", [single]))
    enc = JointStateEncoder(JOINTS)
    steps = 250
    with Listener() as lis:
        multi_cmd = lis.subscribe(JointState, "/multi/joint_commands", RECORDED_QOS)
        singles = [lis.subscribe(JointState, f"/s{i}/joint_commands", RECORDED_QOS) for i in range(1, 8)]
        pubs = [lis.publisher(JointState, "/multi/joint_states")] + [
            lis.publisher(JointState, f"/s{i}/joint_states") for i in range(1, 8)
        ]
        boxes = [multi_cmd, *singles]
        with Graph(specs) as g:
            assert lis.wait_for(lambda: all(p.get_subscription_count() >= 1 for p in pubs), 90, g)
            assert lis.wait_for(lambda: all(lis.matched(f"/s{i}/joint_commands") for i in range(1, 8)), 60, g)
            assert lis.wait_for(lambda: lis.matched("/multi/joint_commands"), 60, g)
            t0 = time.time_ns() - 10**9
            answered: dict[int, list] = {}
            for k in range(steps):
                stamp = t0 + k * 2_000_000
                data = enc.pack_ns(stamp, *[x for arr in _states(k) for x in arr])
                sec, ns = divmod(stamp, 10**9)

                def answers(sec=sec, ns=ns):
                    out = []
                    for box in boxes:
                        hit = [
                            m for m in box[-5:] if m.header.stamp.sec == sec and m.header.stamp.nanosec == ns
                        ]
                        if not hit:
                            return None
                        out.append(list(hit[-1].effort))
                    return out

                for _attempt in range(20):
                    for p in pubs:
                        p.publish(data)
                    if lis.wait_for(lambda a=answers: a() is not None, 2.0, g):
                        break
                got = answers()
                assert got is not None, f"step {k}: not every controller answered"
                answered[k] = got
    worst = 0.0
    moving = 0
    for m, *single in answered.values():
        assert len(m) == 7 and all(len(s) == 1 for s in single)
        for i in range(7):
            worst = max(worst, abs(m[i] - single[i][0]))
            moving += abs(m[i]) > 1e-3
    assert worst <= 1e-9, f"multi-joint vs single-joint controllers differ by {worst:g} N*m"
    assert moving > 0.9 * 7 * steps  # the commands are not trivially zero


@pytest.mark.realtime  # wall-clock timing: a CPU of its own, after the other tests
@pytest.mark.ros
def test_a_missing_joint_gets_zero_torque_and_the_others_stay_controlled(tmp_path):
    """Realtime: joint3 disappears from joint_states; after state_timeout its command is 0 (a warning
    names it), joints 1, 2 keep their P law; when it comes back it is controlled again."""
    from sensor_msgs.msg import JointState

    joints = ["joint1", "joint2", "joint3"]
    params = {
        "joints": joints,
        "effort_limit": 100.0,
        "pid": {"p": 100.0, "i": 0.0, "d": 0.0},
        "gains": {"joint2": {"p": 50.0}},
        "reference": {"type": "constant", "offset": 0.1},
        "state_timeout": 0.3,  # the test publishes every 5 ms; a busy CPU can hold it for 0.1 s
        "diagnostics_period": 0.1,
    }
    path = write_params(tmp_path / "p.yaml", {"compensating_controller": {"ros__parameters": params}})
    all3 = JointStateEncoder(joints)
    two = JointStateEncoder(["joint1", "joint2"])
    with Listener() as lis:
        cmds = lis.subscribe(JointState, "joint_commands", RECORDED_QOS)
        pub = lis.publisher(JointState, "joint_states")
        with Graph([NodeSpec("compensating_controller", "", [path])]) as g:
            assert lis.wait_for(
                lambda: pub.get_subscription_count() >= 1 and lis.matched("joint_commands"), 60, g
            )

            def run(enc, pos, seconds):
                end = time.monotonic() + seconds
                while time.monotonic() < end:
                    n = len(enc.names)
                    pub.publish(enc.pack_ns(time.time_ns(), *pos[:n], *([0.0] * n), *([0.0] * n)))
                    time.sleep(0.005)

            run(all3, [0.0, 0.02, 0.05], 1.0)
            assert lis.wait_for(lambda: bool(cmds), 10, g)
            assert list(cmds[-1].effort) == pytest.approx([10.0, 4.0, 5.0], abs=1e-12)
            run(two, [0.04, 0.06], 1.0)
            last = list(cmds[-1].effort)
            assert last[:2] == pytest.approx([100 * 0.06, 50 * 0.04], abs=1e-12)
            assert last[2] == 0.0, "joint3 is not safe after its states stopped"
            run(all3, [0.0, 0.0, 0.08], 0.5)
            assert list(cmds[-1].effort) == pytest.approx([10.0, 5.0, 2.0], abs=1e-12)
        out = g.output("compensating_controller")
    assert "joint3: no valid joint state for 0.3 s" in out
    assert "joint3: joint states valid again: controlling" in out
    assert "joint1: no valid joint state" not in out


@pytest.mark.parametrize(
    "params, line",
    [
        (
            {
                "joints": ["joint1", "joint2"],
                "friction": {"joint2": {"model": "coulomb_viscous", "fc": -1.0, "fv": 0.1}},
            },
            "friction.joint2.fc = -1",
        ),
        (
            {"joints": ["joint1", "joint2"], "gains": {"joint1": {"bogus": 1.0}}},
            "gains.joint1.bogus: 'bogus' is not a per-joint gain",
        ),
        (
            {"joints": ["joint1", "joint2"], "load": {"joint3": {"gravity": 1.0}}},
            "unknown parameter(s) load.joint3.gravity",
        ),
        ({"joints": ["joint1", "joint1"]}, "joints[1] = 'joint1' appears twice"),
        ({"joints": ["joint1", "pid"]}, "joints[1] = 'pid' clashes"),
        ({"load": {"ripple_cos": []}}, "an empty list (key: [] or key: ~): ROS 2 cannot type it"),
    ],
)
def test_per_joint_parameter_errors_name_the_joint_and_the_key(tmp_path, params, line):
    doc = {"compensating_controller": {"ros__parameters": {"effort_limit": 10.0, **params}}}
    path = write_params(tmp_path / "p.yaml", doc)
    r = subprocess.run(
        [
            sys.executable,
            "-m",
            "friction_ros.nodes.compensating_controller",
            "--ros-args",
            "--params-file",
            path,
        ],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert r.returncode == 2, r.stdout + r.stderr
    err = [ln for ln in r.stderr.splitlines() if ln.strip()]
    assert len(err) == 1 and line in err[0], r.stderr
    assert "Traceback" not in r.stdout + r.stderr


def test_per_joint_parameters_change_at_run_time_for_that_joint_only(tmp_path):
    """In-process node: gains.<joint>.p changes that joint's PID (states kept), a node-level key
    changes every joint without its own value, a bad per-joint value is refused naming its key."""
    import rclpy
    from rclpy.parameter import Parameter

    from friction_ros.nodes.compensating_controller import CompensatingControllerNode

    params = {
        "joints": ["a", "b", "c"],
        "effort_limit": 100.0,
        "pid": {"p": 100.0, "d": 1.0},
        "gains": {"b": {"p": 50.0}},
        "friction": {"c": {"model": "coulomb_viscous", "fc": 0.5, "fv": 0.1}},
    }
    path = write_params(tmp_path / "p.yaml", {"compensating_controller": {"ros__parameters": params}})
    rclpy.init(args=["--ros-args", "--params-file", path])
    try:
        node = CompensatingControllerNode()
        try:
            ctrl = {ch.joint: ch.controller for ch in node.channels}
            p = {j: c.pid.config()["p"] for j, c in ctrl.items()}
            assert p == {"a": 100.0, "b": 50.0, "c": 100.0}
            assert ctrl["c"].friction.model.name == "coulomb_viscous" and ctrl["a"].friction.model is None
            ok = node.set_parameters([Parameter("gains.b.p", value=80.0)])[0]
            assert ok.successful, ok.reason
            now = {ch.joint: ch.controller for ch in node.channels}
            assert now["b"] is ctrl["b"] and now["b"].pid.config()["p"] == 80.0  # same object: states kept
            assert now["a"].pid.config()["p"] == 100.0
            ok = node.set_parameters([Parameter("pid.p", value=120.0)])[0]
            assert ok.successful, ok.reason
            p = {ch.joint: ch.controller.pid.config()["p"] for ch in node.channels}
            assert p == {"a": 120.0, "b": 80.0, "c": 120.0}
            bad = node.set_parameters([Parameter("friction.c.fc", value=-1.0)])[0]
            assert not bad.successful and bad.reason.startswith("friction.c.fc = -1"), bad.reason
            assert node.channels[2].controller.friction.model.coefficients["fc"] == 0.5
            ok = node.set_parameters([Parameter("friction.c.fc", value=0.7)])[0]
            assert ok.successful, ok.reason
            assert node.channels[2].controller.friction.model.coefficients["fc"] == 0.7
            assert (
                node.channels[0].controller is now["a"] or node.channels[0].controller.friction.model is None
            )
        finally:
            node.destroy_node()
    finally:
        rclpy.try_shutdown()
