"""The declarative configuration schema (core/config.py): one field spec, one validation path."""

import pytest

from friction_ros.core.config import Field, Schema
from friction_ros.core.plant.params import PLANT_SCHEMA
from friction_ros.core.validation import ParameterError

SCHEMA = Schema(
    "ctl",
    [
        Field("mode", "pid", "controller mode", choices=("pid", "dnpf")),
        Field("gain", 1.0, "gain", lo=0.0, hi=2.0, lo_open=True),
        Field("k", None, "stiffnesses", lo=0.0, lo_open=True, unit="N*m/rad", is_list=True),
        Schema("pid", [Field("p", 10.0, "P gain", lo=0.0), Field("n", 3, "count", lo=1)]),
    ],
)


def test_schema_validates_a_nested_config_once_filling_defaults():
    cfg = SCHEMA.validate({"k": (1, 2), "pid": {"n": 4.0}})
    assert cfg == {"mode": "pid", "gain": 1.0, "k": [1.0, 2.0], "pid": {"p": 10.0, "n": 4}}
    assert SCHEMA.defaults() == {"mode": "pid", "gain": 1.0, "pid": {"p": 10.0, "n": 3}}
    assert [n for n, _ in SCHEMA.fields()] == ["mode", "gain", "k", "pid.p", "pid.n"]


@pytest.mark.parametrize(
    "cfg, message",
    [
        ({"k": [1.0], "gain": 0.0}, r"ctl\.gain = 0 is out of range: must be in \(0, 2\]"),
        ({"k": [1.0], "mode": "x"}, r"ctl\.mode = 'x' is not allowed: must be one of pid, dnpf"),
        ({}, r"ctl\.k is missing: required \(stiffnesses, > 0 \[N\*m/rad\]\)"),
        ({"k": []}, r"ctl\.k is empty"),
        ({"k": [1.0, -1.0]}, r"ctl\.k\[1\] = -1 is out of range: must be > 0 \[N\*m/rad\]"),
        ({"k": [1.0], "pid": {"p": -1.0}}, r"ctl\.pid\.p = -1 is out of range: must be >= 0"),
        ({"k": [1.0], "pid": {"q": 1.0}}, r"ctl\.pid: unknown parameter\(s\) 'q'"),
    ],
)
def test_schema_errors_are_one_line_naming_the_parameter(cfg, message):
    with pytest.raises(ParameterError, match=message):
        SCHEMA.validate(cfg)


def test_open_section_passes_its_extra_keys_to_the_object_built_from_it():
    s = Schema.from_defaults("friction", {"model": "none"}, "friction model")
    assert s.validate({"model": "gms", "fc": 0.1}) == {"model": "gms", "fc": 0.1}


def test_plant_schema_documents_every_plant_parameter_with_its_unit():
    names = dict(PLANT_SCHEMA.fields())
    assert names["motor_inertia"].required and names["motor_inertia"].unit == "kg*m^2"
    assert names["gear_efficiency"].range_text().startswith("in (0, 1]")
    assert all(f.doc for f in names.values())


def test_every_key_of_the_shipped_parameter_files_is_declared_by_its_nodes_schema():
    """The YAML layout is the schema's: each key is a field, or lies in an open section (friction
    model coefficients, preset sections) whose object checks it."""
    from pathlib import Path

    import yaml

    from friction_ros.core.config import flatten
    from friction_ros.nodes import (
        compensating_controller,
        drive_interface,
        friction_estimator,
        identification_experiment,
        plant_simulator,
    )

    schemas = {
        m.parameter_schema().name: m.parameter_schema()
        for m in (
            compensating_controller,
            friction_estimator,
            identification_experiment,
            plant_simulator,
            drive_interface,
        )
    }
    checked = 0
    for path in sorted((Path(__file__).resolve().parents[1] / "params").glob("*.yaml")):
        for node, body in (yaml.safe_load(path.read_text()) or {}).items():
            schema = schemas.get(node.rsplit("/", 1)[-1])
            if schema is None or not isinstance(body, dict):
                continue
            names = {n for n, _ in schema.fields()}
            opens = [p for p, s in schema.sections() if s.open]
            for key in flatten(body.get("ros__parameters") or {}):
                assert key in names or any(key.startswith(p + ".") for p in opens), (path.name, node, key)
                checked += 1
    assert checked > 50
