"""The parameter files shipped in params/ load into the core objects the nodes build from them."""

from pathlib import Path

import yaml

from friction_ros.cli.bringup import specs_from_config
from friction_ros.core.control.controller import CompensatingController
from friction_ros.core.control.controller_config import config_from_ros_parameters
from friction_ros.core.estimation.estimator import OnlineFrictionEstimator
from friction_ros.core.experiment.references import reference_from_config

PARAMS = Path(__file__).resolve().parents[1] / "params"


def test_example_controller_file_builds_controller_estimator_and_reference():
    doc = yaml.safe_load((PARAMS / "controller_abb_m19s.yaml").read_text())
    ctrl = doc["/**/compensating_controller"]["ros__parameters"]
    cfg, ref = config_from_ros_parameters(ctrl)
    c = CompensatingController(cfg)
    assert c.friction.model.name == "gms" and c.pid.p == 200.0 and c.inertia == 0.0012
    assert reference_from_config(ref).sample(1.0)[0] != 0.0
    est = dict(doc["/**/friction_estimator"]["ros__parameters"])
    est.pop("joint_name")
    assert OnlineFrictionEstimator(est).model_name == "stribeck"


def test_cartesian_bringup_file_starts_three_namespaced_joints():
    specs = specs_from_config(str(PARAMS / "bringup_cartesian_xyz.yaml"))
    assert [(s.namespace, s.node) for s in specs] == [
        (a, n) for a in "xyz" for n in ("plant_simulator", "compensating_controller")
    ]
    for s in specs:
        cmd = s.command()  # parameter files exist, node names valid
        assert f"__ns:=/{s.namespace}" in cmd
        assert any(c.endswith("controller_seed002_xyz.yaml") for c in cmd)
    assert specs[0].overrides == {"preset": "seed002_x", "joint_name": "x_joint"}


def test_pin_latency_chain_puts_plant_and_controller_on_one_cpu():
    from friction_ros.cli.bringup import NodeSpec, pin_latency_chain

    specs = [NodeSpec(n) for n in ("plant_simulator", "compensating_controller", "friction_estimator")]
    specs.append(NodeSpec("bag_recorder"))
    assert pin_latency_chain(specs, cpus=[2, 5])
    assert [s.overrides.get("cpu_affinity") for s in specs] == [2, 2, 5, None]
    assert "cpu_affinity:=2" in " ".join(specs[0].command())
    kept = [NodeSpec("plant_simulator", overrides={"cpu_affinity": 7}), NodeSpec("compensating_controller")]
    assert pin_latency_chain(kept, cpus=[0, 1]) and kept[0].overrides["cpu_affinity"] == 7
    one_cpu = [NodeSpec("plant_simulator")]
    assert not pin_latency_chain(one_cpu, cpus=[0]) and one_cpu[0].overrides == {}
    # several joints: no single chain to pin
    multi = specs_from_config(str(PARAMS / "bringup_cartesian_xyz.yaml"))
    assert not pin_latency_chain(multi, cpus=[0, 1])
    assert all("cpu_affinity" not in s.overrides for s in multi)


def test_a_fitted_parameter_file_without_a_plant_preset_is_a_whole_plant():
    """friction-fit without --plant-preset: the plant_simulator section runs as it is (issue 15)."""
    from friction_ros.core.identification.report.export import parameter_document
    from friction_ros.core.presets import resolve_preset

    cfg = {"model": "coulomb_viscous", "fc": 0.3, "fv": 0.01}
    sec = parameter_document(cfg, 0.002)["plant_simulator"]["ros__parameters"]
    preset = resolve_preset(sec["preset"], {k: sec[k] for k in ("plant", "friction_motor")})
    plant = preset.make_plant()
    assert preset.params.motor_inertia == 0.002 and preset.params.torque_constant == 1.0
    m = plant.step(1.0, 0.1)  # 1 N*m against 0.3 N*m of Coulomb friction: the joint moves forward
    assert m.position > 0.1 and m.velocity > 1.0
