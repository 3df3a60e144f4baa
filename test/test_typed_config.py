"""Typed configs (Schema.typed): frozen, nested, validated once, errors named by the ROS path."""

from __future__ import annotations

import dataclasses

import pytest

from friction_ros.core.config import Field, Schema
from friction_ros.core.control.controller import controller_from_ros_parameters
from friction_ros.core.control.controller_config import ros_controller_config
from friction_ros.core.joint_type import joint_schema
from friction_ros.core.validation import ParameterError

SCHEMA = Schema(
    "ctrl",
    [
        Field("u_clamp_max", 2.5, "limit", lo=0.0, unit="N*m"),
        Field("ks", [1.0, 2.0], "list"),
        Schema(
            "friction", [Field("fc", 0.1, "Coulomb", lo=0.0, unit="N*m"), Schema("inner", [Field("n", 3)])]
        ),
        Schema("sliding_mode", [Field("lambda", 50.0, lo=0.0)]),
    ],
)


def test_typed_config_is_frozen_nested_and_keeps_dict_access():
    cfg = SCHEMA.typed({"friction": {"fc": 0.3, "inner": {"n": 7}}, "ks": (4, 5)}, prefix="gains.joint2")
    assert cfg.friction.fc == 0.3 and cfg.friction.inner.n == 7 and cfg.u_clamp_max == 2.5
    assert cfg.ks == (4.0, 5.0) and isinstance(cfg.ks[0], float)  # normalised once, lists frozen
    assert cfg.sliding_mode.lambda_ == 50.0  # a Python keyword as attribute
    with pytest.raises(dataclasses.FrozenInstanceError):
        cfg.friction.fc = 1.0
    d = cfg.as_dict()
    assert d == {
        "u_clamp_max": 2.5,
        "ks": [4.0, 5.0],
        "friction": {"fc": 0.3, "inner": {"n": 7}},
        "sliding_mode": {"lambda": 50.0},
    }
    d["friction"]["fc"] = 9.0  # a copy: the typed config does not change
    assert cfg.friction.fc == 0.3 and cfg["friction"]["fc"] == 0.3
    assert cfg.friction.path("fc") == "gains.joint2.friction.fc" and cfg.friction.inner.path() == (
        "gains.joint2.friction.inner"
    )
    assert type(SCHEMA.typed({})) is type(cfg)  # one class per schema


@pytest.mark.parametrize(
    "values, text",
    [
        ({"friction": {"fc": -1.0}}, "gains.joint2.friction.fc = -1 is out of range: must be >= 0 [N*m]"),
        ({"friction": {"inner": {"n": 1.5}}}, "gains.joint2.friction.inner.n = 1.5 must be an integer"),
        ({"friction": {"fcc": 1.0}}, "gains.joint2.friction: unknown parameter(s) 'fcc'"),
        ({"ks": [1.0, "x"]}, "gains.joint2.ks[1] = 'x' has type str"),
    ],
)
def test_errors_name_the_full_ros_parameter(values, text):
    with pytest.raises(ParameterError) as ei:
        SCHEMA.typed(values, prefix="gains.joint2")
    assert str(ei.value).startswith(text) and "\n" not in str(ei.value), str(ei.value)


def test_names_map_each_key_and_prismatic_units():
    prismatic = joint_schema(SCHEMA, "prismatic")
    with pytest.raises(
        ParameterError, match=r"^friction\.j3\.fc = -0\.2 is out of range: must be >= 0 \[N\]$"
    ):
        prismatic.typed(
            {"friction": {"fc": -0.2}}, names=lambda rel: rel.replace("friction.", "friction.j3.")
        )
    cfg = ros_controller_config(
        {"friction": {"model": "coulomb", "fc": 0.4}, "inertia": 3.0, "joint_name": "x"},
        joint_type="prismatic",
    )
    assert cfg.friction.fc == 0.4 and cfg.inertia == 3.0 and cfg.compensation.gain == 1.0
    with pytest.raises(ParameterError, match=r"^friction\.fc = -1 is out of range: must be >= 0 \[N\]"):
        ros_controller_config({"friction": {"model": "coulomb", "fc": -1.0}}, joint_type="prismatic")


@pytest.mark.parametrize(
    "values, text",
    [
        ({"friction": {"model": "coulomb", "fc": -1.0}}, "friction.fc = -1 is out of range"),
        (
            {"friction": {"model": "stribeck", "fc": 0.5, "fs": 0.2, "vs": 0.01}},
            "friction.fs = 0.2 is out of range",
        ),
        ({"friction": {"model": "coulomb", "fc": 0.1, "fv": 1.0}}, "friction: unknown parameter(s) 'fv'"),
        ({"compensation": {"gain": 3.0}}, "compensation.gain = 3 is out of range"),
        ({"u_clamp_max": 1.0, "u_clamp_min": 2.0}, "u_clamp_min = 2 is out of range"),
    ],
)
def test_controller_errors_name_the_ros_parameter_without_rewriting(values, text):
    """Range (typed config) and cross-field (the core objects) refusals both name the ROS key."""
    with pytest.raises(ParameterError) as ei:
        controller_from_ros_parameters(values)
    assert str(ei.value).startswith(text), str(ei.value)


def test_typed_controller_carries_the_coefficient():
    ctrl, ref = controller_from_ros_parameters(
        {"friction": {"model": "coulomb", "fc": 0.25}, "compensation": {"gain": 0.5}, "pid": {"p": 10.0}}
    )
    assert ctrl.friction.model.coefficients["fc"] == 0.25 and ctrl.friction.gain == 0.5
    assert ctrl.pid.config()["p"] == 10.0 and ref == {"type": "constant"}
    assert ctrl.friction.model.steady_state(-2.0) == -0.25
