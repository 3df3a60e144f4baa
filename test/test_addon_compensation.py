"""Issue 18: friction compensation as an add-on to an arm's own controller (mode compensation_only):
the core law, and the node over DDS (desired state and trajectory in, Float64MultiArray and summed
JointState out, the on/off service)."""

from __future__ import annotations

import math
import time

import pytest
from ros_graph import Graph, Listener, write_params

from friction_ros.cli.bringup import NodeSpec
from friction_ros.core.control.controller import CompensatingController
from friction_ros.core.validation import ParameterError
from friction_ros.nodes.qos import COMMAND_QOS, RECORDED_QOS

FRICTION = {"model": "coulomb_viscous", "fc": 2.0, "fv": 1.5}


def _ctrl(mode: str, **extra) -> CompensatingController:
    cfg = {
        "mode": mode,
        "pid": {"p": 100.0, "d": 2.0},
        "inertia": 0.3,
        "feedforward_gain": 0.7,
        "friction": {"model": dict(FRICTION), "source": "feedforward", "gain": 0.9},
        "load": {"gravity": 4.0, "gravity_phase": 0.2, "offset": 0.3},
    }
    cfg.update(extra)
    return CompensatingController(cfg)


def test_compensation_only_outputs_the_friction_and_load_terms_of_the_full_controller():
    full, addon = _ctrl("pid"), _ctrl("compensation_only", compensation_scale=0.5)
    for k in range(50):
        t = 0.001 * k
        ref = (0.2 * math.sin(t), 0.4 * math.cos(3 * t) - 0.1, 0.05)
        meas = (ref[0] - 0.01, ref[1] + 0.02)
        f = full.compute(t, ref, meas, 0.001)
        a = addon.compute(t, ref, meas, 0.001)
        want = 0.5 * (f.friction_feedforward + f.friction_feedback + f.load_feedforward)
        assert a.command == pytest.approx(want, abs=1e-12)
        assert a.p_term == a.i_term == a.d_term == a.inertia_feedforward == 0.0
        assert abs(want) > 0.1  # friction and gravity are there
    addon.compensation_enabled = False
    assert addon.compute(0.06, (0.1, 0.3, 0.0), (0.1, 0.3), 0.001).command == 0.0
    addon.compensation_enabled = True
    assert addon.compute(0.061, (0.1, 0.3, 0.0), (0.1, 0.3), 0.001).command != 0.0


def test_compensation_only_is_clamped_and_its_scale_is_checked():
    a = _ctrl("compensation_only", u_clamp_max=1.0, u_clamp_min=-1.0)
    out = a.compute(0.0, (1.2, 1.0, 0.0), (1.2, 1.0), 0.001)
    assert out.command == 1.0 and out.saturated and out.command_unlimited > 4.0
    with pytest.raises(ParameterError, match="compensation_scale = 3 is out of range"):
        _ctrl("compensation_only", compensation_scale=3.0)


@pytest.mark.ros
def test_addon_node_sums_the_arm_command_and_switches_off(tmp_path):
    from friction_msgs.msg import ControllerState
    from sensor_msgs.msg import JointState
    from std_msgs.msg import Float64MultiArray
    from std_srvs.srv import SetBool
    from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

    joints = ["a", "b"]
    params = {
        "joints": joints,
        "effort_limit": 100.0,
        "mode": "compensation_only",
        "sum_base_command": True,
        "friction": {"model": "coulomb_viscous", "fc": 1.0, "fv": 0.5, "b": dict(FRICTION)},
        "compensation": {"source": "feedforward", "smoothing_velocity": 1e-6},
        "load": {"b": {"gravity": 3.0}},
        "state_timeout": 5.0,
    }
    path = write_params(tmp_path / "p.yaml", {"compensating_controller": {"ros__parameters": params}})

    def expected(joint: str, ref, meas) -> float:
        cfg = {
            "mode": "compensation_only",
            "friction": {
                "model": dict(FRICTION)
                if joint == "b"
                else {"model": "coulomb_viscous", "fc": 1.0, "fv": 0.5},
                "source": "feedforward",
                "smoothing_velocity": 1e-6,
            },
            "load": {"gravity": 3.0 if joint == "b" else 0.0},
        }
        return CompensatingController(cfg).compute(0.0, ref, meas, 0.001).command

    with Listener() as lis:
        comp = lis.subscribe(Float64MultiArray, "compensation_command", COMMAND_QOS)
        cmds = lis.subscribe(JointState, "joint_commands", RECORDED_QOS)
        sums = lis.subscribe(Float64MultiArray, "commands", COMMAND_QOS)
        terms = lis.subscribe(ControllerState, "controller_state", RECORDED_QOS)
        states = lis.publisher(JointState, "joint_states")
        desired = lis.publisher(JointState, "desired_joint_states")
        base = lis.publisher(JointState, "base_command", COMMAND_QOS)
        traj = lis.publisher(JointTrajectory, "reference")
        client = lis.node.create_client(SetBool, "/compensating_controller/set_feedforward_control")
        with Graph([NodeSpec("compensating_controller", "", [path])]) as g:
            assert lis.wait_for(
                lambda: (
                    states.get_subscription_count()
                    and base.get_subscription_count()
                    and desired.get_subscription_count()
                    and lis.matched("compensation_command")
                ),
                60,
                g,
            )

            def state(pa, pb):
                m = JointState(name=joints, position=[pa, pb], velocity=[0.0, 0.0], effort=[0.0, 0.0])
                m.header.stamp = lis.node.get_clock().now().to_msg()
                n = len(comp)
                states.publish(m)
                assert lis.wait_for(lambda: len(comp) > n, 10, g)
                return list(comp[-1].data)

            def arm(ea, eb):
                m = JointState(name=joints, effort=[ea, eb])
                m.header.stamp = lis.node.get_clock().now().to_msg()
                n = len(cmds)
                base.publish(m)
                assert lis.wait_for(lambda: len(cmds) > n, 10, g)
                return list(cmds[-1].effort)

            # no desired motion yet: nothing is added
            assert state(0.0, 0.2) == [0.0, 0.0]
            assert arm(1.0, -2.0) == [1.0, -2.0]
            d = JointState(name=["b", "a"], position=[0.2, 0.0], velocity=[-0.3, 0.5])
            desired.publish(d)
            time.sleep(0.3)
            got = state(0.0, 0.2)
            want = [expected("a", (0.0, 0.5, 0.0), (0.0, 0.0)), expected("b", (0.2, -0.3, 0.0), (0.2, 0.0))]
            assert got == pytest.approx(want, abs=1e-12)
            assert want[0] == pytest.approx(1.0 + 0.25, abs=1e-6)  # fc + fv v of joint a
            assert arm(1.0, -2.0) == pytest.approx([1.0 + want[0], -2.0 + want[1]], abs=1e-12)
            assert lis.wait_for(lambda: bool(sums) and list(sums[-1].data) == list(cmds[-1].effort), 10, g)
            # switched off: the arm's command passes unchanged
            fut = client.call_async(SetBool.Request(data=False))
            assert lis.wait_for(lambda: fut.done(), 20, g) and fut.result().success
            assert state(0.0, 0.2) == [0.0, 0.0]
            assert arm(1.0, -2.0) == [1.0, -2.0]
            fut = client.call_async(SetBool.Request(data=True))
            assert lis.wait_for(lambda: fut.done(), 20, g) and fut.result().success
            # a trajectory for joint a (the arm's JointTrajectory) replaces its desired state
            msg = JointTrajectory(joint_names=["a"])
            for tf, q in ((0.0, 0.0), (100.0, 50.0)):
                p = JointTrajectoryPoint(positions=[q], velocities=[0.5])
                p.time_from_start.sec = int(tf)
                msg.points.append(p)
            traj.publish(msg)
            time.sleep(0.3)
            n = len(terms)
            state(0.01, 0.2)
            assert lis.wait_for(lambda: len(terms) >= n + 2, 10, g)
            ta = [m for m in terms[n:] if m.joint_name == "a"][-1]
            tb = [m for m in terms[n:] if m.joint_name == "b"][-1]
            assert ta.reference_velocity == pytest.approx(0.5, abs=1e-9) and ta.mode == "compensation_only"
            assert tb.reference_velocity == pytest.approx(-0.3, abs=1e-12)
            assert ta.command == pytest.approx(ta.friction_feedforward, abs=1e-12)
            assert tb.command == pytest.approx(tb.friction_feedforward + tb.load_feedforward, abs=1e-12)
        out = g.output("compensating_controller")
    assert "no desired trajectory yet" in out and "compensation off" in out


def _pd_plus_addon(addon_cfg, seconds=4.0):
    """abb_m19s with the ABB M19-S paper PD (an arm's own controller) plus an add-on; RMS error, add-on."""
    import numpy as np

    from friction_ros.core.experiment.references import reference_from_config
    from friction_ros.core.presets import make_plant

    ref = reference_from_config(
        {"type": "band_limited_random", "amplitude": 0.05, "cutoff": 1.0, "duration": 10.0, "seed": 1}
    )
    plant = make_plant("abb_m19s")
    pd = CompensatingController({"mode": "pid", "pid": {"p": 200.0, "d": 0.15}})
    addon = CompensatingController(addon_cfg) if addon_cfg else None
    plant.reset(position=ref.sample(0.0)[0])
    pos, vel, errs = ref.sample(0.0)[0], 0.0, []
    for k in range(int(seconds / 1e-3)):
        t = k * 1e-3
        r = ref.sample(t)
        u = pd.compute(t, r, (pos, vel), 1e-3).command
        if addon is not None:
            u += addon.compute(t, r, (pos, vel), 1e-3).command
        m = plant.step(u * plant.command_scale, 1e-3)
        pos, vel = m.position, m.velocity
        errs.append(ref.sample(t + 1e-3)[0] - m.true_position)
    return float(np.sqrt(np.mean(np.square(errs)))), addon


def test_the_limit_cycle_detector_switches_a_destabilising_addon_off():
    """An add-on fed back from the measured velocity (static Stribeck, the case that made the seed
    003 loop limit-cycle ~9x worse) on an arm's PD: the detector switches it off, latched, and the
    arm tracks as with the PD alone; with the detector off the error is several times the PD's."""
    bad = {
        "mode": "compensation_only",
        "pid": {"p": 200.0, "d": 0.15},  # the arm controller's gains (feedback-path bound)
        "friction": {
            "model": {"model": "stribeck", "fc": 0.8, "fs": 0.95, "vs": 0.05, "delta": 2.0},
            "source": "feedback",
        },
    }
    pd_alone, _ = _pd_plus_addon(None)
    unwatched, _ = _pd_plus_addon({**bad, "limit_cycle_detection": False})
    watched, addon = _pd_plus_addon(bad)
    assert unwatched > 3.0 * pd_alone
    assert addon.compensation_fallback and "limit cycle" in addon.fallback_reason
    assert addon.limit_cycle.fired_at < 1.0
    assert watched < 1.5 * pd_alone


@pytest.mark.ros
def test_estimates_are_adopted_only_by_joints_that_adopt_them_and_only_when_converged(tmp_path):
    """friction_estimate (FrictionEstimate per joint) over DDS: joint b adopts, joint a does not;
    an unconverged estimate changes nothing."""
    from friction_msgs.msg import FrictionEstimate
    from sensor_msgs.msg import JointState
    from std_msgs.msg import Float64MultiArray

    from friction_ros.core.coefficient_exchange import to_fields

    joints = ["a", "b"]
    params = {
        "joints": joints,
        "effort_limit": 100.0,
        "mode": "compensation_only",
        "friction": {"model": "coulomb_viscous", "fc": 1.0, "fv": 0.5},
        "compensation": {"source": "feedforward", "smoothing_velocity": 1e-6},
        "adopt_estimator_coefficients": False,
        "gains": {"b": {"adopt_estimator_coefficients": True}},
        "state_timeout": 5.0,
    }
    path = write_params(tmp_path / "p.yaml", {"compensating_controller": {"ros__parameters": params}})
    with Listener() as lis:
        comp = lis.subscribe(Float64MultiArray, "compensation_command", COMMAND_QOS)
        states = lis.publisher(JointState, "joint_states")
        desired = lis.publisher(JointState, "desired_joint_states")
        estimates = lis.publisher(FrictionEstimate, "friction_estimate")
        with Graph([NodeSpec("compensating_controller", "", [path])]) as g:
            assert lis.wait_for(
                lambda: (
                    states.get_subscription_count()
                    and desired.get_subscription_count()
                    and estimates.get_subscription_count()
                    and lis.matched("compensation_command")
                ),
                60,
                g,
            )
            desired.publish(JointState(name=joints, position=[0.0, 0.0], velocity=[1.0, 1.0]))
            time.sleep(0.3)

            def output():
                m = JointState(name=joints, position=[0.0, 0.0], velocity=[1.0, 1.0], effort=[0.0, 0.0])
                m.header.stamp = lis.node.get_clock().now().to_msg()
                n = len(comp)
                states.publish(m)
                assert lis.wait_for(lambda: len(comp) > n, 10, g)
                return list(comp[-1].data)

            def estimate(joint, fc, converged):
                model, names, values = to_fields({"model": "coulomb_viscous", "fc": fc, "fv": 0.0})
                msg = FrictionEstimate(
                    joint_name=joint, model=model, coefficient_names=names, coefficients=values
                )
                msg.converged = converged
                estimates.publish(msg)
                time.sleep(0.3)

            def output_becomes(expected, timeout=10.0):
                """The output once it equals ``expected`` (a loaded machine delivers the reference or
                an estimate late), or the last one after ``timeout`` s."""
                end = time.monotonic() + timeout
                while True:
                    got = output()
                    if got == pytest.approx(expected, abs=1e-9) or time.monotonic() > end:
                        return got
                    time.sleep(0.05)

            assert output_becomes([1.5, 1.5]) == pytest.approx([1.5, 1.5], abs=1e-9)  # fc + fv * 1 rad/s
            estimate("b", 3.0, converged=False)
            assert output() == pytest.approx([1.5, 1.5], abs=1e-9)  # not converged: not adopted
            estimate("b", 3.0, converged=True)
            estimate("a", 3.0, converged=True)
            assert output_becomes([1.5, 3.0]) == pytest.approx([1.5, 3.0], abs=1e-9)
