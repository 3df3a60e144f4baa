"""Issue 17: compensating_controller with load and residual sections, over DDS and in process."""

from __future__ import annotations

import math

import numpy as np
import pytest
from ros_graph import Graph, Listener, stamp_s, write_params

from friction_ros.cli.bringup import NodeSpec
from friction_ros.core.harness import run_closed_loop
from friction_ros.core.presets import load_preset
from friction_ros.nodes.qos import RECORDED_QOS

pytestmark = pytest.mark.ros

# abb_m19s with a constant gravity torque towards -q and a spring to ground (plant section)
PLANT = {"gravity_force": 2.0, "load_stiffness": 3.0}
LOAD = {"offset": 2.0, "spring": 3.0}  # what the fitter identifies: tau_load(q) = 2 + 3 q
REFERENCE = {"type": "step", "amplitude": 0.3, "rise_time": 0.3}  # move to 0.3 rad, then hold
PD = {"p": 200.0, "d": 0.15}
CV = {"model": "coulomb_viscous", "fc": 0.8, "fv": 0.01}
REF_SINE = {"type": "sinusoid", "amplitude": 0.2, "frequency": 0.5}


def test_load_section_is_fed_forward_and_holds_against_gravity(tmp_path):
    from friction_msgs.msg import ControllerState

    params = write_params(
        tmp_path / "ctrl.yaml",
        {
            "compensating_controller": {
                "ros__parameters": {
                    "mode": "pid",
                    "effort_limit": 4.9,
                    "pid": PD,
                    "inertia": 0.0012,
                    "compensation": {"source": "feedforward", "gain": 1.0},
                    "friction": CV,
                    "load": LOAD,
                    "reference": REFERENCE,
                }
            }
        },
    )
    sim_end = 1.5
    plant_overrides = {"preset": "abb_m19s", "mode": "lockstep"}
    plant_overrides.update({f"plant.{k}": v for k, v in PLANT.items()})
    with Listener() as lis:
        states = lis.subscribe(ControllerState, "controller_state", RECORDED_QOS)
        ctrl = [NodeSpec("compensating_controller", "", [params], {"use_sim_time": True})]
        with Graph(ctrl) as g:
            assert lis.wait_for(lambda: lis.matched("controller_state"), 60, g), "listener not matched"
            with Graph([NodeSpec("plant_simulator", "", [], plant_overrides)]) as gp:
                ok = lis.wait_for(lambda: states and stamp_s(states[-1]) >= sim_end, 120, gp)
                g.assert_alive()
                assert ok, "graph did not run"
    by_k = {round(stamp_s(m) * 1000): m for m in states}
    n = int(sim_end * 1000)
    ks = np.array([k for k in range(1, n + 1) if k in by_k])
    assert len(ks) >= 0.9 * n, f"received only {len(ks)} of {n} controller states"
    msgs = [by_k[k] for k in ks]
    q = np.array([m.position for m in msgs])
    tau_l = np.array([m.load_feedforward for m in msgs])
    # the load term is published: tau_load(q) = offset + spring q at the measured position
    assert np.allclose(tau_l, 2.0 + 3.0 * q, rtol=0, atol=1e-12)
    assert all(m.learned_feedforward == 0.0 for m in msgs)
    assert np.allclose(
        [m.command_unlimited for m in msgs],
        [
            m.p_term
            + m.i_term
            + m.d_term
            + m.velocity_feedforward
            + m.inertia_feedforward
            + m.friction_feedforward
            + m.friction_feedback
            + m.load_feedforward
            + m.learned_feedforward
            for m in msgs
        ],
        rtol=0,
        atol=1e-12,
    )
    node_err = np.array([m.error for m in msgs])

    # the same loop in the pure harness, with and without the load section
    preset = load_preset("abb_m19s").override({"plant": PLANT})
    base = {"mode": "pid", "pid": PD, "inertia": 0.0012, "friction": {"model": CV, "source": "feedforward"}}
    with_load = run_closed_loop(preset, {**base, "load": LOAD}, REFERENCE, n / 1000.0, 1e-3)
    without = run_closed_loop(preset, base, REFERENCE, n / 1000.0, 1e-3)

    def errors(res):
        return (res.reference[:, 0] - res.position)[ks - 1]

    assert np.max(np.abs(node_err - errors(with_load))) < 1e-9  # lockstep: the harness's numbers
    hold = ks > 800  # the move ends at 0.3 s: holding 0.3 rad against 2 + 3 * 0.3 = 2.9 N*m
    rms = {k: math.sqrt(np.mean(e[hold] ** 2)) for k, e in (("node", node_err), ("off", errors(without)))}
    # PD alone sags by (2.9 N*m - what static friction holds) / 200 N*m/rad: measured 15.4 mrad RMS;
    # with the load term 1.28 mrad (what is left sits in the static-friction band fs / Kp = 4.75 mrad)
    assert rms["off"] > 0.01
    assert rms["node"] < rms["off"] / 8, rms


def test_residual_section_over_dds_adds_the_residual_step(tmp_path):
    """A residual section in the parameter file (int and float lists as ROS parameters): the node
    publishes the learned term the core controller computes, residual.step(q, v, previous command)."""
    from friction_msgs.msg import ControllerState
    from test_control_load import tiny_residual

    from friction_ros.core.friction.learned_residual import LearnedResidual

    section = tiny_residual()
    params = write_params(
        tmp_path / "ctrl.yaml",
        {
            "compensating_controller": {
                "ros__parameters": {
                    "mode": "pid",
                    "effort_limit": 4.9,
                    "pid": PD,
                    "friction": CV,
                    "residual": section,
                    "reference": REF_SINE,
                }
            }
        },
    )
    sim_end = 0.5
    with Listener() as lis:
        states = lis.subscribe(ControllerState, "controller_state", RECORDED_QOS)
        ctrl = [NodeSpec("compensating_controller", "", [params], {"use_sim_time": True})]
        with Graph(ctrl) as g:
            assert lis.wait_for(lambda: lis.matched("controller_state"), 60, g), "listener not matched"
            plant = [NodeSpec("plant_simulator", "", [], {"preset": "abb_m19s", "mode": "lockstep"})]
            with Graph(plant) as gp:
                ok = lis.wait_for(lambda: states and stamp_s(states[-1]) >= sim_end, 120, gp)
                g.assert_alive()
                assert ok, "graph did not run"
            assert "learned residual mlp" in g.output("compensating_controller")
    by_k = {round(stamp_s(m) * 1000): m for m in states}
    n = int(sim_end * 1000)
    ks = np.array([k for k in range(n) if k in by_k])
    assert len(ks) >= 0.9 * n, f"received only {len(ks)} of {n} controller states"
    got = np.array([by_k[k].learned_feedforward for k in ks])
    # the lockstep graph is the harness (test_nodes_ros), whose controller adds exactly
    # residual.step(q, v, previous command) (test_control_load): the same numbers here
    cfg = {"mode": "pid", "pid": PD, "friction": {"model": CV}, "residual": section}
    res = run_closed_loop("abb_m19s", cfg, REF_SINE, n / 1000.0, 1e-3, record_terms=True)
    want = res.terms["learned_feedforward"][ks]
    assert np.max(np.abs(got - want)) < 1e-9
    assert np.count_nonzero(got) == len(ks) and np.max(np.abs(got)) <= 0.3
    # and the first period, from the map's fresh history, by the map itself
    if 0 in by_k:
        m = by_k[0]
        assert m.learned_feedforward == LearnedResidual.from_config(section).step(m.position, m.velocity, 0.0)


def test_load_and_residual_parameters_change_at_run_time(tmp_path):
    """In-process node: the load.* parameters (empty ripple lists declared by type) change at run time,
    a bad value is refused with its name, and a learned residual's kind is read-only."""
    import rclpy
    from rclpy.parameter import Parameter

    from friction_ros.nodes.compensating_controller import CompensatingControllerNode

    params = write_params(
        tmp_path / "ctrl.yaml",
        {
            "compensating_controller": {
                "ros__parameters": {"effort_limit": 4.9, "pid": PD, "load": {"gravity": 1.0}}
            }
        },
    )
    rclpy.init(args=["--ros-args", "--params-file", params])
    try:
        node = CompensatingControllerNode()
        try:
            assert node.controller.load.load.gravity == 1.0 and node.controller.residual is None
            ok = node.set_parameters([Parameter("load.spring", value=2.5)])[0]
            assert ok.successful, ok.reason
            assert (node.controller.load.load.gravity, node.controller.load.load.spring) == (1.0, 2.5)
            bad = node.set_parameters([Parameter("load.ripple_cos", value=[0.1])])[0]
            assert not bad.successful
            assert bad.reason.startswith("load.ripple_sin has 0 values: must have as many as load.ripple_cos")
            both = node.set_parameters_atomically(
                [Parameter("load.ripple_cos", value=[0.1]), Parameter("load.ripple_sin", value=[0.0])]
            )
            assert both.successful, both.reason
            jl = node.controller.load.load
            assert (jl.ripple_cos, jl.ripple_sin, jl.ripple_period) == ([0.1], [0.0], 2.0 * math.pi)
            kind = node.set_parameters([Parameter("residual.kind", value="mlp")])[0]
            assert not kind.successful and "read-only" in kind.reason
        finally:
            node.destroy_node()
    finally:
        rclpy.try_shutdown()


def test_fitted_file_with_load_terms_and_no_ripple_starts_the_node(tmp_path):
    """friction-fit writes a load section with gravity but no ripple: the node must start from it
    (rcl cannot type ``ripple_cos: []``; the export leaves empty lists out)."""
    import rclpy

    from friction_ros.core.friction.joint_load import JointLoad
    from friction_ros.core.identification.report.export import dump_yaml, parameter_document
    from friction_ros.nodes.compensating_controller import CompensatingControllerNode

    load = JointLoad(gravity=2.0, gravity_phase=0.1).to_config()
    assert load["ripple_cos"] == []
    doc = parameter_document(
        {"model": "coulomb_viscous", "fc": 0.5, "fv": 0.1}, 0.01, load=load, effort_limit=5.0
    )
    path = tmp_path / "fit.yaml"
    path.write_text(dump_yaml(doc))
    assert "ripple_cos" not in path.read_text()
    rclpy.init(args=["--ros-args", "--params-file", str(path)])
    try:
        node = CompensatingControllerNode()
        try:
            jl = node.controller.load.load
            assert (jl.gravity, jl.gravity_phase, jl.ripple_cos) == (2.0, 0.1, [])
        finally:
            node.destroy_node()
    finally:
        rclpy.try_shutdown()
