"""Validation names a parameter as the user wrote it, per joint, with no renaming of messages: the
core objects (plant preset, excitation program, online estimator, controller) take a joint's
JointNames and their own messages carry the per-joint name of a value the joint gave and the
node-level name of a value every joint shares; the node adds ``joint <name>:`` only then."""

from __future__ import annotations

import pytest

from friction_ros.core.config import Schema, within
from friction_ros.core.control.controller import controller_from_ros_parameters
from friction_ros.core.estimation.estimator import ESTIMATOR_SCHEMA, OnlineFrictionEstimator
from friction_ros.core.experiment.excitation import ExcitationProgram
from friction_ros.core.experiment.experiment_run import arm_experiment, program_config
from friction_ros.core.joint_config import JointLayout, JointNames, joint_errors
from friction_ros.core.plant.multi_joint import PRESET_SECTIONS, resolve_joint_presets
from friction_ros.core.presets import resolve_preset
from friction_ros.core.validation import ParameterError
from friction_ros.nodes.controller_parameters import build_controller
from friction_ros.nodes.controller_parameters import parameter_schema as controller_schema
from friction_ros.nodes.estimator_parameters import PLAIN_KEYS, joint_names
from friction_ros.nodes.estimator_parameters import parameter_schema as estimator_schema
from friction_ros.nodes.experiment_parameters import PER_JOINT_PLAIN_KEYS
from friction_ros.nodes.experiment_parameters import parameter_schema as experiment_schema
from friction_ros.nodes.joint_parameters import layout_for, values_of_joint
from friction_ros.nodes.plant_parameters import parameter_schema as plant_schema

JOINTS = ["j1", "j2"]


def _raises(fn, *args, **kw) -> ParameterError:
    with pytest.raises(ParameterError) as info:
        fn(*args, **kw)
    return info.value


# ------------------------------------------------------------------------------- the names
def test_joint_names_per_joint_for_own_keys_node_level_for_shared_ones():
    layout = JointLayout(JOINTS, ["pid", "friction", "limits"], "pid", ["p", "d"], ["inertia"])
    own = JointNames(layout, "j2", {"pid.p": 1.0, "inertia": 2.0, "limits.max_travel": 3.0})
    assert own("pid.p") == "gains.j2.p" and own("inertia") == "gains.j2.inertia"
    assert own("limits.max_travel") == "limits.j2.max_travel"
    assert own("pid.d") == "pid.d" and own("limits.max_torque") == "limits.max_torque"
    assert own("friction.fc") == "friction.fc" and own("friction") == "friction"
    assert own("limits") == "limits.j2" and own("pid") == "gains.j2"  # sections holding own keys
    replaced = JointNames(layout, "j1", {"friction.model": "stribeck", "friction.fc": 0.3})
    # a section the joint replaces (its own model): every key is the joint's, given or default
    assert replaced("friction.fs") == "friction.j1.fs" and replaced("friction") == "friction.j1"
    assert replaced.owns("friction.j1.fs") and replaced.owns("presliding.j1.amplitudes[0]")
    assert not replaced.owns("friction.fs") and not replaced.owns("friction.j2.fs")
    assert within(replaced, "friction")("fc") == "friction.j1.fc"


def test_the_schema_call_itself_returns_the_ros_name():
    layout = JointLayout(JOINTS, ["input_gate"], None, (), PLAIN_KEYS)
    own = JointNames(layout, "j2", {"min_velocity": -1.0})
    err = _raises(ESTIMATOR_SCHEMA.validate, {"min_velocity": -1.0}, names=own)
    assert str(err).startswith("gains.j2.min_velocity = -1 is out of range: must be >= 0")
    assert err.parameter == "gains.j2.min_velocity"
    shared = JointNames(layout, "j2", {})
    assert str(_raises(ESTIMATOR_SCHEMA.validate, {"min_velocity": -1.0}, names=shared)).startswith(
        "min_velocity = -1 is out of range"
    )
    typed = Schema("x", list(ESTIMATOR_SCHEMA)).typed({"min_samples": 5}, names=own)
    assert typed.path("min_velocity") == "gains.j2.min_velocity" and typed.path("vs") == "vs"


# --------------------------------------------------------------------------------- the plant
def test_plant_names_the_override_and_the_shared_value():
    values = {**plant_schema().defaults(), "joints": JOINTS}
    layout = JointLayout(JOINTS, PRESET_SECTIONS)
    own = {"plant.gear_ratio": -2.0}
    names = JointNames(layout, "j2", own)
    # the core call itself: no renaming step
    err = _raises(resolve_preset, "abb_m19s", {"plant": {"gear_ratio": -2.0}}, names=names)
    assert str(err).startswith("plant.j2.gear_ratio = -2 is out of range")
    err = _raises(resolve_preset, "abb_m19s", {"friction_motor": {"fc": -1.0}}, names=names)
    assert str(err).startswith("friction_motor.fc = -1 is out of range")  # shared: node-level name
    names = JointNames(layout, "j2", {"friction_motor.fc": 2.0})
    err = _raises(resolve_preset, "abb_m19s", {"friction_motor": {"fc": 2.0}}, names=names)
    # a rule across two coefficients: the joint's fc, the preset's (shared) fs
    assert str(err).startswith(
        "friction_motor.fs = 0.95 is out of range: must be >= friction_motor.j2.fc = 2"
    )
    # the node's path: the joint named only for a shared value
    err = _raises(resolve_joint_presets, values, JOINTS, {"j2": own})
    assert str(err).startswith("plant.j2.gear_ratio = -2 is out of range")
    err = _raises(resolve_joint_presets, {**values, "plant": {"gear_ratio": -2.0}}, JOINTS, {})
    assert str(err).startswith("joint j1: plant.gear_ratio = -2 is out of range")


# ---------------------------------------------------------------------------- the experiment
def _arm(node_given: dict, overrides: dict):
    schema = experiment_schema("default", arm=True)
    values = schema.defaults()
    for section, keys in node_given.items():
        values[section] = {**values[section], **keys}
    layout = layout_for(schema, JOINTS, None, PER_JOINT_PLAIN_KEYS)
    ov = {j: overrides.get(j, {}) for j in JOINTS}
    per_joint = {j: values_of_joint(values, ov[j], j, single=False) for j in JOINTS}
    return arm_experiment(JOINTS, per_joint, values, layout, ov), values, layout


def test_experiment_names_the_override_and_the_shared_value():
    err = _raises(_arm, {}, {"j2": {"plateaus.v_min": -1.0}})
    assert str(err).startswith("plateaus.j2.v_min = -1 is out of range")
    err = _raises(_arm, {"plateaus": {"v_min": -1.0}}, {})
    assert str(err).startswith("joint j1: plateaus.v_min = -1 is out of range")
    # one message, two origins: the joint's v_max, the shared velocity limit
    err = _raises(_arm, {}, {"j2": {"plateaus.v_max": 50.0}})
    assert "plateaus.j2.v_max = 50 is out of range: must be < limits.max_velocity = 40" in str(err)
    # the program itself names them (no renaming step); so do its run-time limit messages
    arm, values, layout = _arm({}, {"j2": {"limits.max_travel": 0.01}})
    names = JointNames(layout, "j2", {"plateaus.v_min": -1.0})
    cfg = program_config(values_of_joint(values, {"plateaus.v_min": -1.0}, "j2", False), values)
    assert str(_raises(ExcitationProgram, cfg, names)).startswith("plateaus.j2.v_min = -1")
    prog = arm.programs[1]
    prog.update(0.0, 0.0, 0.0)
    assert prog._check_limits(0.02, 0.0).endswith("exceeds limits.j2.max_travel = 0.01 rad")
    assert arm.programs[0]._check_limits(200.0, 0.0).endswith("exceeds limits.max_travel = 100 rad")


# ----------------------------------------------------------------------------- the estimator
def test_estimator_names_the_override_and_the_shared_value():
    schema = estimator_schema(with_joints=False)
    layout = layout_for(schema, JOINTS, None, PLAIN_KEYS)
    own = joint_names(layout, "j2", {"forgetting_factor": 2.0})
    err = _raises(OnlineFrictionEstimator, {"forgetting_factor": 2.0}, own)
    assert str(err).startswith("gains.j2.forgetting_factor = 2 is out of range: must be in (0.5, 1]")
    err = _raises(OnlineFrictionEstimator, {"forgetting_factor": 2.0}, joint_names(layout, "j2", {}))
    assert str(err).startswith("forgetting_factor = 2 is out of range")
    own = joint_names(layout, "j1", {"initial.fz": 1.0})
    err = _raises(OnlineFrictionEstimator, {"initial": {"fz": 1.0}}, own)
    assert str(err).startswith("initial.j1: unknown parameter(s) 'fz'")
    # the node's build: the joint named for a shared value only
    shared = joint_names(layout, "j1", {})
    with pytest.raises(ParameterError, match=r"^joint j1: forgetting_factor = 2 is out of range"):
        with joint_errors(shared):
            OnlineFrictionEstimator({"forgetting_factor": 2.0}, shared)
    single = joint_names(None, "joint1", {})
    assert str(_raises(OnlineFrictionEstimator, {"forgetting_factor": 2.0}, single)).startswith(
        "forgetting_factor = 2"
    )
    assert str(_raises(OnlineFrictionEstimator, {"forgetting_factor": 2.0})).startswith(
        "estimator.forgetting_factor = 2"  # the core's own names without a node
    )


# ---------------------------------------------------------------------------- the controller
def test_controller_names_the_override_and_the_shared_value():
    schema = controller_schema()
    layout = layout_for(schema, JOINTS, "pid", ["effort_limit", "inertia"])
    values = {**schema.defaults(), "effort_limit": 5.0}
    bad = {"friction.model": "stribeck", "friction.fc": -0.5}
    jv = values_of_joint(values, bad, "j2", single=False)
    err = _raises(controller_from_ros_parameters, jv, JointNames(layout, "j2", bad))
    assert str(err).startswith("friction.j2.fc = -0.5 is out of range")
    err = _raises(build_controller, jv, layout, "j2", bad, False)
    assert str(err).startswith("friction.j2.fc = -0.5 is out of range")
    shared = {**values, "pid": {**values["pid"], "d": -1.0}}
    jv = values_of_joint(shared, {}, "j1", single=False)
    assert str(_raises(controller_from_ros_parameters, jv, JointNames(layout, "j1", {}))).startswith(
        "pid.d = -1 is out of range"
    )
    assert str(_raises(build_controller, jv, layout, "j1", {}, False)).startswith(
        "joint j1: pid.d = -1 is out of range"
    )
