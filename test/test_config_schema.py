"""The declarative configuration schema (core/config.py): one field spec, one validation path."""

import pytest

from friction_ros.core.config import Field, Schema
from friction_ros.core.plant import PLANT_SCHEMA
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
