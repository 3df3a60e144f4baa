"""plant_simulator with several joints ("manipulator scale"): per-joint plant configuration (pure),
the pendulum gravity load of the core plant, and 3-/2-joint plants over real DDS."""

from __future__ import annotations

import math
import threading
import time
from pathlib import Path

import numpy as np
import pytest
import yaml
from ros_graph import Graph, Listener, stamp_s, write_params

from friction_ros.cli.bringup import NodeSpec
from friction_ros.core.config import flatten, unflatten
from friction_ros.core.input_gate import select_joint_commands
from friction_ros.core.joint_config import JointLayout
from friction_ros.core.plant.multi_joint import PRESET_SECTIONS, joint_plant_configs, resolve_joint_presets
from friction_ros.core.presets import load_preset, resolve_preset
from friction_ros.core.validation import ParameterError
from friction_ros.nodes.plant_simulator import parameter_schema

ROOT = Path(__file__).resolve().parents[1]
HALF_PI = math.pi / 2


def node_values(**given):
    """The node's values as declare_config returns them (schema defaults + ``given``, nested)."""
    values = parameter_schema().defaults()
    values.update(given)
    return values


# -- (1) pure: per-joint configuration ------------------------------------------------------------
def test_per_joint_presets_and_sections_lie_over_the_node_level_values():
    joints = ["a", "b", "c"]
    values = node_values(
        joints=joints,
        presets=["abb_m19s", "seed000_gearhead", "abb_m19s"],
        plant={"current_offset": 0.01},  # node level: every joint
        friction_motor={"fc": 0.5},  # node level, no model: merged into each joint's preset model
    )
    overrides = {
        "b": {"plant.gravity": 0.6, "plant.gravity_phase": HALF_PI, "plant.current_offset": 0.02},
        "c": {"friction_motor.model": "coulomb_viscous", "friction_motor.fc": 0.3, "friction_motor.fv": 0.0},
    }
    cfg = joint_plant_configs(values, joints, overrides)
    assert [(j, p) for j, p, _ in cfg] == [("a", "abb_m19s"), ("b", "seed000_gearhead"), ("c", "abb_m19s")]
    assert cfg[0][2] == {
        "plant": {"current_offset": 0.01},
        "friction_motor": {"fc": 0.5},
        "friction_load": {},
    }
    assert cfg[1][2]["plant"] == {"current_offset": 0.02, "gravity": 0.6, "gravity_phase": HALF_PI}
    assert cfg[2][2]["friction_motor"] == {
        "model": "coulomb_viscous",
        "fc": 0.3,
        "fv": 0.0,
    }  # replaced as a whole

    a, b, c = resolve_joint_presets(values, joints, overrides)
    abb, gear = load_preset("abb_m19s"), load_preset("seed000_gearhead")
    assert a.params.current_offset == 0.01 and a.params.gravity == 0.0
    assert a.friction_motor.name == "gms" and a.friction_motor["fc"] == 0.5
    assert a.friction_motor["fs"] == abb.friction_motor["fs"] == 0.95
    assert b.params.gravity == 0.6 and b.params.gravity_phase == HALF_PI and b.params.current_offset == 0.02
    assert b.params.gear_ratio == gear.params.gear_ratio == 10.0
    assert b.friction_motor["fc"] == 0.5 and b.friction_load.name == gear.friction_load.name
    assert c.friction_motor.name == "coulomb_viscous" and c.friction_motor["fc"] == 0.3
    assert {p.control_period for p in (a, b, c)} == {0.001}  # the node's period, not seed000_gearhead's own


def test_one_joint_is_the_node_preset_with_its_sections():
    values = node_values(preset="seed001_harmonic_drive", plant={"motor_damping": 0.3})
    (pr,) = resolve_joint_presets(values, ["joint1"], {})
    ref = resolve_preset("seed001_harmonic_drive", {"plant": {"motor_damping": 0.3}, "control_period": 0.001})
    assert pr.to_config() == ref.to_config() and pr.control_period == 0.001
    (pr,) = resolve_joint_presets(node_values(presets=["seed004_dc_motor"]), ["joint1"], {})
    assert pr.name == "seed004_dc_motor"


def test_per_joint_errors_name_the_parameter():
    joints = ["a", "b"]
    with pytest.raises(ParameterError, match=r"presets = \['abb_m19s'\] has 1 names for 2 joints"):
        resolve_joint_presets(node_values(joints=joints, presets=["abb_m19s"]), joints, {})
    with pytest.raises(ParameterError, match=r"plant\.b\.gear_ratio = -2"):
        resolve_joint_presets(node_values(joints=joints), joints, {"b": {"plant.gear_ratio": -2.0}})
    with pytest.raises(ParameterError, match=r"joint a: .*plant\.gear_ratio"):
        resolve_joint_presets(node_values(joints=joints, plant={"gear_ratio": -2.0}), joints, {})
    with pytest.raises(ParameterError, match="only the plant sections"):
        joint_plant_configs(node_values(joints=joints), joints, {"a": {"scheduling.cpu_affinity": 1}})


def test_arm7_parameter_file_builds_seven_joints_with_gravity_on_the_pitch_joints():
    doc = yaml.safe_load((ROOT / "params" / "arm7_plant.yaml").read_text())
    flat = flatten(doc["/**/plant_simulator"]["ros__parameters"])
    joints = flat.pop("joints")
    assert joints == [f"joint{i}" for i in range(1, 8)]
    node_flat, per_joint = JointLayout(joints, PRESET_SECTIONS).split_all(flat)
    values = node_values(**unflatten(node_flat), joints=joints)
    presets = resolve_joint_presets(values, joints, per_joint)
    assert [p.name for p in presets] == [
        "abb_m19s",
        "seed001_harmonic_drive",
        "abb_m19s",
        "seed000_gearhead",
        "seed001_harmonic_drive",
        "seed004_dc_motor",
        "seed004_dc_motor",
    ]
    assert [p.params.gravity for p in presets] == [0.0, 4.0, 1.5, 0.6, 0.0, 0.003, 0.0]
    assert [p.params.seed for p in presets] == [3, 1, 13, 0, 11, 4, 7]
    assert presets[3].params.encoder_cpr == 4096  # an arm joint's encoder, not the preset's 60 counts
    for p in presets:
        plant = p.make_plant()
        if p.params.gravity:
            assert p.params.gravity_phase == HALF_PI
            # unpowered at q = 0 (link horizontal): gravity exceeds the static friction, the joint sags
            q = plant.run_open_loop(np.zeros(300), p.control_period)[:, 2]
            assert -math.pi < q[-1] < -0.4, p.name  # 0.3 s: sagged by more than 0.4 rad
        else:  # nothing moves an unpowered joint without gravity
            assert np.all(plant.run_open_loop(np.zeros(50), p.control_period)[:, 2] == 0.0)


def test_command_selection_for_several_joints():
    class Msg:
        def __init__(self, name, effort):
            self.name, self.effort = name, effort

    index = {"a": 0, "b": 1, "c": 2}
    lim = [10.0, 10.0, 1.0]
    assert select_joint_commands(Msg(["b"], [1.5]), index, lim) == ({1: 1.5}, [], 0)
    assert select_joint_commands(Msg(["c", "x", "a", "c"], [0.5, 9.0, -2.0, 0.7]), index, lim) == (
        {2: 0.5, 0: -2.0},
        [],
        1,
    )
    eff, rej, unknown = select_joint_commands(Msg(["a", "c"], [math.nan, 2.0]), index, lim)
    assert eff == {0: 0.0, 2: 0.0} and [r[:2] for r in rej] == [(0, "not_finite"), (2, "out_of_range")]
    assert select_joint_commands(Msg(["x"], [1.0]), index, lim)[1][0][:2] == (None, "wrong_joint")
    assert select_joint_commands(Msg(["a", "b"], [1.0]), index, lim)[1][0][:2] == (None, "wrong_length")
    assert select_joint_commands(Msg([], [1.0]), index, lim)[1][0][:2] == (None, "wrong_length")


# -- the core plant's pendulum gravity load -------------------------------------------------------
def test_pendulum_gravity_load_of_the_core_plant():
    """J q'' = -m g l sin(q + q0): a frictionless torque-driven joint swings as a pendulum."""
    J, mgl, q0 = 0.01, 0.5, 0.2
    plant = resolve_preset(
        {
            "plant": {
                "motor_inertia": J,
                "torque_constant": 1.0,
                "actuation": "torque",
                "gravity": mgl,
                "gravity_phase": q0,
                "internal_dt": 1e-5,
            }
        }
    ).make_plant()
    plant.reset(position=0.3 - q0)  # 0.3 rad from hanging
    dt, n = 1e-3, 2000
    q = plant.run_open_loop(np.zeros(n), dt)[:, 2] + q0
    # reference: the same pendulum by RK4 at 1e-5 s
    th, w, h, ref = 0.3, 0.0, 1e-5, []
    f = lambda t_: -mgl / J * math.sin(t_)  # noqa: E731
    for _ in range(n):
        for _ in range(100):
            k1, l1 = w, f(th)
            k2, l2 = w + h / 2 * l1, f(th + h / 2 * k1)
            k3, l3 = w + h / 2 * l2, f(th + h / 2 * k2)
            k4, l4 = w + h * l3, f(th + h * k3)
            th += h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
            w += h / 6 * (l1 + 2 * l2 + 2 * l3 + l4)
        ref.append(th)
    assert np.max(np.abs(q - np.array(ref))) < 2e-4  # semi-implicit Euler at 1e-5 s
    assert q.min() == pytest.approx(-0.3, abs=1e-3)  # energy kept: swings to the other side
    # holding torque: a command of m g l sin(q + q0) keeps the joint where it is
    plant.reset(position=0.5)
    q = plant.run_open_loop(np.full(500, mgl * math.sin(0.5 + q0)), dt)[:, 2]
    assert np.max(np.abs(q - 0.5)) < 1e-12
    # gravity = 0: its phase changes nothing, bit for bit
    base = load_preset("abb_m19s")
    off = base.override({"plant": {"gravity": 0.0, "gravity_phase": 1.0}})
    u = 0.5 * np.sin(np.arange(300) * 0.05)
    assert np.array_equal(base.make_plant().run_open_loop(u, 1e-3), off.make_plant().run_open_loop(u, 1e-3))


@pytest.mark.ros
def test_in_process_node_declares_per_joint_parameters_read_only(tmp_path):
    """joints + presets + plant.<joint>.<key> declared as ROS parameters; a per-joint plant value
    cannot change at run time; one joint_states layout for all joints."""
    import rclpy
    from rclpy.parameter import Parameter

    from friction_ros.nodes.plant_simulator import PlantSimulator

    params = write_params(
        tmp_path / "p.yaml",
        {
            "plant_simulator": {
                "ros__parameters": {
                    "joints": ["a", "b"],
                    "presets": ["abb_m19s", "seed004_dc_motor"],
                    "mode": "lockstep",
                    "plant": {"b": {"gravity": 0.002, "gravity_phase": HALF_PI}},
                }
            }
        },
    )
    rclpy.init(args=["--ros-args", "--params-file", params])
    try:
        node = PlantSimulator()
        try:
            assert node.joints == ["a", "b"] and [p.name for p in node.presets] == [
                "abb_m19s",
                "seed004_dc_motor",
            ]
            assert node.get_parameter("plant.b.gravity").value == 0.002
            assert [pl.params.gravity for pl in node.plants] == [0.0, 0.002]
            assert node._encoder.names == ("a", "b") and node._pending == (0.0,) * 6
            bad = node.set_parameters([Parameter("plant.b.gravity", value=1.0)])[0]
            assert not bad.successful and "read-only" in bad.reason
            assert node.plants[1].params.gravity == 0.002
            ok = node.set_parameters([Parameter("resend_period", value=0.5)])[0]
            assert ok.successful and node.p["resend_period"] == 0.5
        finally:
            node.destroy_node()
    finally:
        rclpy.try_shutdown()


# -- (2) over DDS ------------------------------------------------------------------------------------
MULTI_PRESETS = {"j1": "abb_m19s", "j2": "seed000_gearhead", "j3": "seed004_dc_motor"}
# PD gains and torque clamps per joint: deterministic commands from the multi-joint plant's state
GAINS = {"j1": (20.0, 0.5, 4.0), "j2": (5.0, 0.1, 2.0), "j3": (0.02, 2e-4, 0.005)}
STEPS = 300
STALL = 40  # the step at which j2's answer is held back


def _ref(k: int) -> float:
    return 0.3 * math.sin(2 * math.pi * 2.0 * k * 1e-3)


def _status(diags, name: str) -> dict[str, str]:
    """Key/values of the newest diagnostics status named ``name``."""
    for m in reversed(diags):
        for s in m.status:
            if s.name == name:
                return {kv.key: kv.value for kv in s.values}
    return {}


def _js(stamp, names, efforts):
    from sensor_msgs.msg import JointState

    m = JointState(name=list(names), effort=[float(e) for e in efforts])
    if stamp is not None:
        m.header.stamp = stamp
    return m


def _ns(msg) -> int:
    return msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec


@pytest.mark.ros
def test_lockstep_three_joints_advance_when_every_joint_is_answered(tmp_path):
    from diagnostic_msgs.msg import DiagnosticArray
    from sensor_msgs.msg import JointState

    from friction_ros.nodes.qos import COMMAND_QOS, RECORDED_QOS

    joints = list(MULTI_PRESETS)
    params = write_params(
        tmp_path / "plant3.yaml",
        {
            "plant_simulator": {
                "ros__parameters": {
                    "joints": joints,
                    "presets": list(MULTI_PRESETS.values()),
                    "mode": "lockstep",
                    "diagnostics_period": 0.2,
                    "plant": {"j1": {"gravity": 1.2, "gravity_phase": HALF_PI}},
                }
            }
        },
    )
    specs = [
        NodeSpec("plant_simulator", "", [params]),
        # the reference: a single-joint plant of j2's preset fed j2's commands
        NodeSpec(
            "plant_simulator",
            "single",
            [],
            {"preset": "seed000_gearhead", "mode": "lockstep", "joint_name": "j2"},
        ),
    ]
    multi: dict[int, object] = {}  # stamp -> state
    single: dict[int, object] = {}
    sent: dict[int, dict[str, float]] = {}  # stamp -> commands
    resends: dict[int, int] = {}
    lock = threading.Lock()
    done = threading.Event()
    stalled = threading.Event()
    with Listener("multi_joint_driver") as lis:
        pubs = {j: lis.publisher(JointState, "joint_commands", COMMAND_QOS) for j in joints}
        ghost = lis.publisher(JointState, "joint_commands", COMMAND_QOS)
        single_pub = lis.publisher(JointState, "single/joint_commands", COMMAND_QOS)
        diags = lis.subscribe(DiagnosticArray, "diagnostics")

        def answer(stamp_ns: int) -> None:
            """Both plants are at ``stamp_ns``: send j1..j3 (one message each) and j2 to the single."""
            if stamp_ns in sent or len(sent) >= STEPS:
                if len(sent) >= STEPS:
                    done.set()
                return
            m, s = multi[stamp_ns], single[stamp_ns]
            k = len(sent)
            tau = {}
            for i, j in enumerate(joints):
                kp, kd, lim = GAINS[j]
                tau[j] = min(max(kp * (_ref(k) - m.position[i]) - kd * m.velocity[i], -lim), lim)
            sent[stamp_ns] = tau
            for j in joints:
                if k == STALL and j == "j2":
                    continue  # held back: the plant must wait for it
                pubs[j].publish(_js(m.header.stamp, [j], [tau[j]]))
            single_pub.publish(_js(s.header.stamp, ["j2"], [tau["j2"]]))
            if k == STALL:
                stalled.set()

        def on_multi(msg) -> None:
            with lock:
                t = _ns(msg)
                if t in multi:
                    resends[t] = resends.get(t, 0) + 1
                    return
                multi[t] = msg
                if t in single:
                    answer(t)

        def on_single(msg) -> None:
            with lock:
                t = _ns(msg)
                if t in single:
                    return
                single[t] = msg
                if t in multi:
                    answer(t)

        lis.node.create_subscription(JointState, "joint_states", on_multi, RECORDED_QOS)
        lis.node.create_subscription(JointState, "single/joint_states", on_single, RECORDED_QOS)
        with Graph(specs) as g:
            assert lis.wait_for(stalled.is_set, 90, g), f"lockstep did not reach step {STALL}: {len(sent)}"
            stall_ns = STALL * 1_000_000
            stamp = multi[stall_ns].header.stamp
            time.sleep(0.7)  # > 3 resend periods
            with lock:
                assert max(multi) == stall_ns, "advanced without j2's command"
                assert resends.get(stall_ns, 0) >= 2  # the pending state is re-sent meanwhile
            ghost.publish(_js(stamp, ["ghost"], [5.0]))  # no joint of this plant: ignored
            pubs["j1"].publish(_js(stamp, ["j1"], [99.0]))  # j1 answered already: duplicate, ignored
            time.sleep(0.4)
            with lock:
                assert max(multi) == stall_ns, "advanced on an unknown joint's or a duplicate command"
            # j2 in a message that also names an unknown joint: j2 counts, ghost is ignored
            ghost.publish(_js(stamp, ["ghost", "j2"], [7.0, sent[stall_ns]["j2"]]))
            assert lis.wait_for(done.is_set, 120, g), f"lockstep stopped after {len(sent)} steps"
            assert lis.wait_for(lambda: _status(diags, "/plant_simulator").get("steps") == str(STEPS), 10, g)
            g.assert_alive()
    stamps = sorted(multi)
    assert stamps == [k * 1_000_000 for k in range(STEPS + 1)]  # one state per period, none skipped
    assert list(multi[stamps[1]].name) == joints
    # the multi-joint plant's j2 = the single-joint plant fed the same commands
    q2 = np.array([multi[t].position[1] for t in stamps])
    q_single = np.array([single[t].position[0] for t in stamps])
    assert np.max(np.abs(q2)) > 0.05  # it moved
    assert np.max(np.abs(q2 - q_single)) <= 1e-12
    assert (
        np.max(
            np.abs(np.array([multi[t].velocity[1] for t in stamps]) - [single[t].velocity[0] for t in stamps])
        )
        <= 1e-12
    )
    # every joint = its core plant fed the commands the test sent (the duplicate 99.0 was not applied)
    values = node_values(joints=joints, presets=list(MULTI_PRESETS.values()))
    presets = resolve_joint_presets(
        values, joints, {"j1": {"plant.gravity": 1.2, "plant.gravity_phase": HALF_PI}}
    )
    for i, (j, pr) in enumerate(zip(joints, presets, strict=True)):
        plant = pr.make_plant()
        plant.reset(position=0.0)
        q = [0.0] + [plant.step(sent[t][j] * plant.command_scale, 1e-3).position for t in stamps[:-1]]
        assert np.max(np.abs(np.array(q) - [multi[t].position[i] for t in stamps])) <= 1e-12, j
    v = _status(diags, "/plant_simulator")
    assert v["commands_ignored"] == "2" and v["rejected.wrong_joint"] == "1"  # ghost alone, duplicate
    assert v["unknown_joint_names"] == "2" and v["commands_rejected"] == "0"
    assert v["j1.preset"] == "abb_m19s" and v["j2.preset"] == "seed000_gearhead"


@pytest.mark.realtime  # wall-clock timing: a CPU of its own, after the other tests
@pytest.mark.ros
@pytest.mark.flaky(reruns=2)  # wall-clock loop on a shared 2-core machine
def test_realtime_two_joints_zero_only_the_joint_whose_commands_stopped(tmp_path):
    from diagnostic_msgs.msg import DiagnosticArray
    from sensor_msgs.msg import JointState

    from friction_ros.nodes.qos import COMMAND_QOS, RECORDED_QOS

    specs = [
        NodeSpec(
            "plant_simulator",
            "",
            [],
            {"joints": ["a", "b"], "preset": "abb_m19s", "mode": "realtime", "diagnostics_period": 0.2},
        )
    ]
    with Listener() as lis:
        states = lis.subscribe(JointState, "joint_states", RECORDED_QOS)
        diags = lis.subscribe(DiagnosticArray, "diagnostics")
        pub_a = lis.publisher(JointState, "joint_commands", COMMAND_QOS)
        pub_b = lis.publisher(JointState, "joint_commands", COMMAND_QOS)
        with Graph(specs) as g:
            assert lis.wait_for(lambda: pub_a.get_subscription_count() >= 1 and len(states) > 10, 60, g)
            # 1 N*m against 0.8 N*m of Coulomb and 0.01 N*m*s/rad of viscous friction: ~20 rad/s
            end = time.monotonic() + 1.0
            while time.monotonic() < end:
                pub_a.publish(_js(None, ["a"], [1.0]))
                pub_b.publish(_js(None, ["b"], [1.0]))
                time.sleep(0.01)
            t_stop = time.time()  # realtime states are stamped with the ROS system (wall) clock
            end = time.monotonic() + 1.0  # b's controller stops: zero torque for b after 0.1 s
            while time.monotonic() < end:
                pub_a.publish(_js(None, ["a"], [1.0]))
                time.sleep(0.01)
            # judge by stamps, not by arrival: the listener may lag behind the 1 kHz states
            assert lis.wait_for(lambda: stamp_s(states[-1]) > t_stop + 0.9, 30, g)
            g.assert_alive()
            moving = [m for m in states if stamp_s(m) <= t_stop][-1]
            tail = [m for m in states if t_stop + 0.5 <= stamp_s(m) <= t_stop + 0.9]
            assert lis.wait_for(
                lambda: _status(diags, "/plant_simulator").get("b.command_fresh") == "False", 5
            )
            v = _status(diags, "/plant_simulator")
    assert list(moving.name) == ["a", "b"] and len(tail) > 100
    assert moving.velocity[0] > 10.0 and moving.velocity[1] > 10.0  # both driven
    # a: still driven near its terminal velocity (1 - 0.8) / 0.01 = 20 rad/s
    assert all(15.0 < m.velocity[0] < 21.0 for m in tail)
    # b: zero torque, stopped by friction and stuck: what is left is the GMS presliding (an undamped
    # spring-mass oscillation of ~1e-4 rad, one or two encoder counts), no sliding
    qb = np.array([m.position[1] for m in tail])
    assert np.ptp(qb) <= 3.2e-4 and max(abs(m.velocity[1]) for m in tail) < 0.2
    assert qb[0] > moving.position[1] + 0.5  # it coasted on after the stop
    assert v["a.command_fresh"] == "True" and v["b.command_fresh"] == "False"
