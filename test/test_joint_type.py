"""Revolute and prismatic joints: units of every setting, the drive's lead, joint-type detection and
the fitter's outputs in the joint's units."""

from __future__ import annotations

import json
import math
import re
from pathlib import Path

import pytest
import yaml

from friction_ros.core.config import Field, Schema
from friction_ros.core.joint_type import (
    JOINT_TYPES,
    check_joint_type,
    detect_joint_type,
    joint_schema,
    joint_text,
    joint_unit,
    quantity_units,
    units_of,
)
from friction_ros.core.validation import ParameterError, check_real

ROOT = Path(__file__).resolve().parents[1]

#: every unit string of the schemas and the fitter -> the same quantity on a prismatic joint
PRISMATIC = {
    "": "",
    "1/s": "1/s",
    "1/rad": "1/m",
    "A": "A",
    "A/V": "A/V",
    "B": "B",
    "H": "H",
    "Hz": "Hz",
    "Hz (0 = off)": "Hz (0 = off)",
    "N*m": "N",
    "N*m or N": "N",
    "N*m*s/rad": "N*s/m",
    "N*m*s/rad or N*s/m": "N*s/m",
    "N*m/(rad*s)": "N/(m*s)",
    "N*m/A": "N/A",
    "N*m/rad": "N/m",
    "N*m/rad or N/m": "N/m",
    "N*m/s": "N/s",
    "Ohm": "Ohm",
    "V": "V",
    "V*s/rad": "V*s/m",
    "bit/s": "bit/s",
    "counts/rev": "counts/rev",
    "degC": "degC",
    "kg*m^2": "kg",
    "kg*m^2 or kg": "kg",
    "m": "m",
    "m/rev": "m/rev",
    "motor rev / joint rev": "motor rev / joint rev",
    "rad": "m",
    "rad or m": "m",
    "rad/s": "m/s",
    "rad/s or m/s": "m/s",
    "rad/s^2": "m/s^2",
    "s": "s",
    "s (0 = automatic)": "s (0 = automatic)",
    "s per time unit": "s per time unit",
    "s/rad": "s/m",
}


def _schema_units() -> set[str]:
    from friction_ros.core.friction import MODEL_CLASSES
    from friction_ros.core.plant.params import PLANT_SCHEMA
    from friction_ros.nodes import (
        compensating_controller,
        drive_interface,
        friction_estimator,
        identification_experiment,
        plant_simulator,
    )

    schemas = [m.parameter_schema() for m in (plant_simulator, compensating_controller, friction_estimator)]
    schemas += [
        identification_experiment.parameter_schema(),
        drive_interface.parameter_schema(),
        PLANT_SCHEMA,
    ]
    schemas += [Schema(n, c.COEFS) for n, c in MODEL_CLASSES.items()]
    return {f.unit for s in schemas for _, f in s.fields()}


def _source_units() -> set[str]:
    """``unit="..."`` in the package and the bracketed units of the fitter's outputs."""
    out = set()
    for p in (ROOT / "friction_ros").rglob("*.py"):
        out.update(re.findall(r'unit="([^"]*)"', p.read_text()))
    return out


def test_every_unit_of_the_schemas_and_the_fitter_maps_to_its_prismatic_unit():
    found = _schema_units() | _source_units() | set(quantity_units("revolute").values())
    missing = sorted(found - set(PRISMATIC))
    assert not missing, f"add these units to PRISMATIC (and check joint_unit): {missing}"
    for unit, prismatic in PRISMATIC.items():
        assert joint_unit(unit, "prismatic") == prismatic, unit
        assert joint_unit(unit, "revolute") == unit.split(" or ")[0], unit


def test_joint_type_check_is_one_line_naming_the_choices():
    assert JOINT_TYPES == ("revolute", "prismatic")
    assert check_joint_type("prismatic") == "prismatic"
    for bad in ("rotary", "", 3, None):
        with pytest.raises(ParameterError) as e:
            check_joint_type(bad)
        text = str(e.value)
        assert "\n" not in text and "revolute, prismatic" in text and text.startswith("joint_type = ")


def test_schema_and_messages_in_the_joint_units():
    s = Schema(
        "x",
        [
            Field("fc", 1.0, "Coulomb level", lo=0.0, lo_open=True, unit="N*m"),
            Schema("est", [Field("observer_bandwidth", 200.0, "bandwidth", unit="rad/s")]),
            Field("vs", 0.1, "Stribeck velocity", lo=0.0, lo_open=True, unit="rad/s"),
        ],
    )
    p = joint_schema(s, "prismatic")
    assert joint_schema(s, "revolute") is s
    units = {n: f.unit for n, f in p.fields()}
    assert units == {"fc": "N", "est.observer_bandwidth": "rad/s", "vs": "m/s"}  # a frequency stays
    with pytest.raises(ParameterError, match=re.escape("lugre.fc = 0 is out of range: must be > 0 [N]")):
        with units_of("prismatic"):
            check_real("lugre.fc", 0.0, 0.0, lo_open=True, unit="N*m")
    with pytest.raises(ParameterError, match=re.escape("must be > 0 [N*m]")):
        with units_of("revolute"):
            check_real("lugre.fc", 0.0, 0.0, lo_open=True, unit="N*m")
    assert joint_text("est.observer_bandwidth = -1 must be > 0 [rad/s]", "prismatic").endswith("[rad/s]")


def test_prismatic_friction_model_error_names_newtons():
    from friction_ros.core.friction import model_from_config

    with pytest.raises(ParameterError) as e:
        with units_of("prismatic"):
            model_from_config(
                {"model": "lugre", "fc": 0.0, "fs": 1.0, "vs": 0.1, "sigma0": 1e4, "sigma1": 1.0}
            )
    assert "[N]" in str(e.value) and "N*m" not in str(e.value)


# -------------------------------------------------------------------------------- drive conversion
def test_prismatic_drive_converts_motor_turns_to_metres_with_the_lead():
    from friction_ros.core.can.axis_config import AXIS_SCHEMA, axis_config
    from friction_ros.core.config import flatten

    v = flatten(AXIS_SCHEMA.validate({}, ""))
    v.update(joint_type="prismatic", lead=0.005, torque_constant=0.1)
    conv = axis_config(v, 1000.0).conversion
    assert conv.ratio == pytest.approx(2 * math.pi / 0.005)
    assert conv.joint_position(2 * math.pi) == pytest.approx(0.005)  # one motor turn = one lead
    assert conv.joint_velocity(2 * math.pi * 10) == pytest.approx(0.05)  # 10 turns/s = 50 mm/s
    # ideal screw: F = 2 pi tau / lead
    assert conv.joint_torque(0.1) == pytest.approx(2 * math.pi * 0.1 / 0.005)
    assert conv.motor_position(conv.joint_position(1.234)) == pytest.approx(1.234)
    assert conv.motor_current(conv.joint_torque_from_current(2.0)) == pytest.approx(2.0)
    with pytest.raises(ParameterError, match=r"needs lead > 0 \[m/rev\]") as e:
        axis_config({**v, "lead": 0.0}, 1000.0)
    assert "\n" not in str(e.value)
    with pytest.raises(ParameterError, match="prismatic"):
        axis_config({**v, "joint_type": "revolute"}, 1000.0)
    with pytest.raises(ParameterError, match=re.escape("torque_limit = -1 is out of range: must be > 0 [N]")):
        axis_config({**v, "torque_limit": -1.0}, 1000.0)
    with pytest.raises(ParameterError, match="leave gear_ratio at 1"):
        axis_config({**v, "gear_ratio": 3.0}, 1000.0)
    revolute = axis_config({**v, "joint_type": "revolute", "lead": 0.0, "gear_ratio": 3.0}, 1000.0)
    assert revolute.conversion.joint_position(3.0) == pytest.approx(1.0)


# -------------------------------------------------------------------------------- detection
def test_detect_joint_type_from_csv_headers():
    assert detect_joint_type(columns=["time", "position_m", "velocity_m_s", "force_N"])[0] == "prismatic"
    assert detect_joint_type(columns=["t", "pos", "force"])[0] == "prismatic"
    assert detect_joint_type(columns=["time [s]", "position [m]", "effort"])[0] == "prismatic"
    assert detect_joint_type(columns=["time", "position_rad", "torque_Nm"])[0] == "revolute"
    assert detect_joint_type(columns=["time", "position", "effort"]) == (None, "CSV columns name no unit")
    found, why = detect_joint_type(columns=["time", "position_m", "torque"])
    assert found is None and "mix" in why


def test_detect_joint_type_from_bag_metadata(tmp_path):
    bag = tmp_path / "run"
    bag.mkdir()
    info = {"rosbag2_bagfile_information": {"version": 9, "custom_data": {"joint_type": "prismatic"}}}
    (bag / "metadata.yaml").write_text(yaml.safe_dump(info))
    found, why = detect_joint_type(path=bag)
    assert found == "prismatic" and "custom_data" in why
    per_joint = {"rosbag2_custom_data": {"joint_type.x": "prismatic", "joint_type": "revolute"}}
    assert detect_joint_type(metadata=per_joint, joint="x")[0] == "prismatic"
    assert detect_joint_type(metadata=per_joint, joint="wrist")[0] == "revolute"
    assert detect_joint_type(metadata={"friction_ros": {"preset": "x"}}) == (
        None,
        "the log states no joint type",
    )


# -------------------------------------------------------------------------------- fitter outputs
@pytest.fixture(scope="module")
def prismatic_fit(tmp_path_factory):
    from friction_ros.core.identification.data.csv_loading import load_csv
    from friction_ros.core.identification.fit.pipeline import fit_records
    from friction_ros.core.identification.report.report import write_outputs

    rec = load_csv(ROOT / "test" / "data" / "dfki_pendulum" / "control_method_pd_system_identification.csv")
    res = fit_records([rec], ["coulomb_viscous"], identifiability_check=False, train_seconds=1.5, load="none")
    res.options["joint_type"] = "prismatic"
    out = tmp_path_factory.mktemp("prismatic_fit")
    write_outputs(res, out, plots=False, sources=["log.csv"])
    return res, out


def test_report_summary_and_parameter_file_of_a_prismatic_fit(prismatic_fit):
    res, out = prismatic_fit
    js = json.loads((out / "summary.json").read_text())
    assert js["joint_type"] == "prismatic"
    assert js["units"] == {
        "position": "m",
        "velocity": "m/s",
        "acceleration": "m/s^2",
        "friction": "N",
        "effort": "N",
        "J": "kg",
    }
    report = (out / "report.md").read_text()
    assert (
        "- joint type: prismatic (positions in m, velocities in m/s, friction in N, inertia in kg)" in report
    )
    assert "| fc |" in report and re.search(r"\| fc \| [^|]+ \| N \|", report)
    assert re.search(r"\| fv \| [^|]+ \| N\*s/m \|", report) and re.search(r"\| J \| [^|]+ \| kg \|", report)
    assert "N*m" not in report and "rad/s" not in report and "kg*m^2" not in report
    text = (out / "friction_params.yaml").read_text()
    assert "coefficients SI (N, m/s, kg)" in text and "N*m" not in text
    doc = yaml.safe_load(text)
    for node in ("compensating_controller", "friction_estimator", "plant_simulator"):
        assert doc[node]["ros__parameters"]["joint_type"] == "prismatic", node


def test_a_fit_without_joint_type_stays_revolute(prismatic_fit):
    from friction_ros.core.identification.report.export import fit_parameter_document
    from friction_ros.core.identification.report.report import summary

    res, _ = prismatic_fit
    rev = dict(res.options)
    rev.pop("joint_type")
    res.options, saved = rev, res.options
    try:
        js = summary(res)
        doc = fit_parameter_document(res)
    finally:
        res.options = saved
    assert js["joint_type"] == "revolute" and js["units"]["friction"] == "N*m"
    assert doc["compensating_controller"]["ros__parameters"]["joint_type"] == "revolute"


def test_prismatic_parameter_file_loads_into_the_nodes_config_objects(prismatic_fit):
    """What the nodes build from the exported file: the controller, the estimator, the plant."""
    from friction_ros.core.control.controller import controller_from_ros_parameters
    from friction_ros.core.identification.report.export import parameter_document
    from friction_ros.core.presets import preset_from_config
    from friction_ros.nodes import compensating_controller, friction_estimator, plant_simulator

    res, out = prismatic_fit
    doc = yaml.safe_load((out / "friction_params.yaml").read_text())
    cc = doc["compensating_controller"]["ros__parameters"]
    schema = joint_schema(compensating_controller.parameter_schema(lambda p: cc.get(p, {})), cc["joint_type"])
    values = schema.validate(cc, "")
    assert values["joint_type"] == "prismatic"
    ctrl, _ = controller_from_ros_parameters(values)
    assert ctrl.friction.model.name == res.models[res.recommended].config["model"]
    fields = dict(schema.fields())
    assert fields["inertia"].unit == "kg" and fields["u_clamp_max"].unit == "N"
    est = doc["friction_estimator"]["ros__parameters"]
    est_fields = dict(joint_schema(friction_estimator.parameter_schema(), est["joint_type"]).fields())
    assert est_fields["joint_type"].default == "revolute" and est_fields["min_velocity"].unit == "m/s"
    est_values = friction_estimator.parameter_schema().validate(est, "")
    from friction_ros.core.estimation.estimator import OnlineFrictionEstimator

    OnlineFrictionEstimator(friction_estimator.core_config(est_values))
    assert doc["plant_simulator"]["ros__parameters"]["joint_type"] == "prismatic"
    plant_fields = dict(joint_schema(plant_simulator.parameter_schema(), "prismatic").fields())
    assert plant_fields["initial_position"].unit == "m" and plant_fields["max_effort"].unit == "N"
    # the plant section as a preset (a fitted file given as preset: path), with a plant inertia
    cfg = {"model": "coulomb_viscous", "fc": 5.0, "fv": 1.0}
    plant = parameter_document(cfg, 12.0, joint_type="prismatic")["plant_simulator"]["ros__parameters"]
    preset = preset_from_config(plant)
    assert preset.params.motor_inertia == 12.0 and preset.make_plant().step(10.0, 0.1).position > 0


def test_multi_joint_document_keeps_each_joints_type():
    from friction_ros.core.identification.report.multi_joint import JointFit, joint_parameter_document

    def doc(jt):
        from friction_ros.core.identification.report.export import parameter_document

        return parameter_document({"model": "coulomb_viscous", "fc": 1.0, "fv": 0.1}, 0.5, joint_type=jt)

    fits = [
        JointFit("x", "ok", document=doc("prismatic"), joint_type="prismatic"),
        JointFit("wrist", "ok", document=doc("revolute"), joint_type="revolute"),
        JointFit("z", "fit failed", joint_type="prismatic"),
    ]
    cc = joint_parameter_document(fits)["compensating_controller"]["ros__parameters"]
    assert cc["gains"]["x"]["joint_type"] == "prismatic" and cc["gains"]["wrist"]["joint_type"] == "revolute"
    assert cc["gains"]["z"]["joint_type"] == "prismatic"
    same = joint_parameter_document(fits[:1] + fits[2:])["compensating_controller"]["ros__parameters"]
    assert same["joint_type"] == "prismatic"


def test_detect_joint_type_from_embedded_parameter_files_and_urdf():
    params = "plant_simulator:\n  ros__parameters:\n    joint_type: prismatic\n    preset: seed002_x\n"
    meta = {"friction_ros": {"preset": "seed002_x", "parameter_file:/p/plant.yaml": params}}
    found, why = detect_joint_type(metadata=meta)
    assert found == "prismatic" and "parameter_file:/p/plant.yaml" in why
    urdf = (
        '<robot name="gantry"><joint name="x" type="prismatic"><axis xyz="1 0 0"/></joint>'
        "<joint name='wrist' type='continuous'/></robot>"
    )
    meta = {"rosbag2_custom_data": {"robot_description": urdf}}
    assert detect_joint_type(metadata=meta, joint="x")[0] == "prismatic"
    assert detect_joint_type(metadata=meta, joint="wrist")[0] == "revolute"
    assert detect_joint_type(metadata=meta)[0] is None  # the joints differ and none was named


def test_a_prismatic_csv_log_loads_and_tells_its_joint_type(tmp_path):
    import numpy as np

    from friction_ros.core.identification.data.csv_loading import load_csv

    t = np.arange(0.0, 2.0, 0.001)
    v = 0.05 * np.sin(2 * np.pi * t)
    rows = np.column_stack([t, np.cumsum(v) * 1e-3, v, 20 * np.sign(v) + 5 * v])
    header = ["time", "position_m", "velocity_m_s", "force_N"]
    path = tmp_path / "axis.csv"
    np.savetxt(path, rows, delimiter=",", header=",".join(header), comments="")
    data = load_csv(path)
    assert data.meta["columns"] == dict(zip(("time", "position", "velocity", "effort"), header))
    assert detect_joint_type(columns=header)[0] == "prismatic"
