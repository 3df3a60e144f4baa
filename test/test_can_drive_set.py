"""Several drives on one bus (core): routing of joint_commands, per-joint values, run-time changes
and the DriveSet a node steps (cycle, fault lines, bus failures, reconfiguration, health)."""

from __future__ import annotations

import pytest

from friction_ros.core.can import odrive as od
from friction_ros.core.can.axis_config import AXIS_SCHEMA
from friction_ros.core.can.axis_health import ERROR, WARN
from friction_ros.core.can.drive_set import (
    AXIS_KEYS,
    DriveSet,
    axis_param_specs,
    axis_values,
    changed_values,
    check_joint_names,
)
from friction_ros.core.can.faults import FAULT_BUS, FAULT_COMMAND_WATCHDOG
from friction_ros.core.can.joint_commands import route_efforts
from friction_ros.core.config import flatten
from friction_ros.core.validation import ParameterError

JOINTS = ["a", "b"]


def test_route_efforts_by_name_by_position_and_ignored_messages():
    assert route_efforts(["b"], [2.0], JOINTS) == ([(1, 2.0)], "", "")
    assert route_efforts(["x", "a", "b"], [9.0, 1.0, 2.0], JOINTS)[0] == [(0, 1.0), (1, 2.0)]
    assert route_efforts([], [1.0, 2.0], JOINTS)[0] == [(0, 1.0), (1, 2.0)]
    routed, kind, why = route_efforts(["x"], [1.0], JOINTS)
    assert (routed, kind) == ([], "foreign") and "this node drives ['a', 'b']" in why
    routed, kind, why = route_efforts(["a", "b"], [1.0], JOINTS)
    assert (routed, kind) == ([], "length") and "2 names but 1 efforts" in why
    routed, kind, why = route_efforts([], [1.0], JOINTS)
    assert (routed, kind) == ([], "length") and "exactly 2 efforts" in why


def test_per_joint_values_and_run_time_changes():
    v = {"node_id": 0, "torque_limit": 1.0, "command_timeout": 0.1}
    per = {"a.node_id": 1, "b.node_id": 2, "a.torque_limit": 1.0, "b.torque_limit": 3.0}
    keys = ("node_id", "torque_limit")
    vals = axis_values(JOINTS, v, per, keys)
    assert [(x["joint_name"], x["node_id"], x["torque_limit"]) for x in vals] == [
        ("a", 1, 1.0),
        ("b", 2, 3.0),
    ]
    assert axis_values([], v, {}, keys) == [v]
    new, shared = changed_values(JOINTS, vals, {"b.torque_limit": 2.5, "command_timeout": 0.05}, keys, True)
    assert shared == {"command_timeout": 0.05}
    assert [x["torque_limit"] for x in new] == [1.0, 2.5] and all(x["command_timeout"] == 0.05 for x in new)
    with pytest.raises(ParameterError, match="<joint>.torque_limit"):
        changed_values(JOINTS, vals, {"torque_limit": 3.0}, keys, True)


@pytest.mark.parametrize(
    "joints,message", [(["1a"], "must start with a letter"), (["a", "a"], "twice"), (["channel"], "clashes")]
)
def test_joint_names_are_checked(joints, message):
    with pytest.raises(ParameterError, match=message):
        check_joint_names(joints, {"channel"})


# ---- DriveSet: the drives of one node --------------------------------------------------------------
NODE_VALUES = {**flatten(AXIS_SCHEMA.defaults()), "joint_name": "joint1", "control_period": 0.001}


def drive_set(ids=(1, 2), **per_joint) -> DriveSet:
    """Two ODrive drives 'a', 'b' with node ids ``ids`` and ``<joint>.<key>`` values ``per_joint``."""
    per = {f"{j}.{k}": NODE_VALUES[k] for j in JOINTS for k in AXIS_KEYS}
    per.update({"a.node_id": ids[0], "b.node_id": ids[1]}, **per_joint)
    return DriveSet(axis_values(JOINTS, NODE_VALUES, per, AXIS_KEYS), multi=True)


def feed_odrive(axis, node_id: int, t: float, state: int = 8) -> None:
    for f in (
        od.encode_encoder_estimates(node_id, 0.5, 0.0),
        od.encode_iq(node_id, 0.0, 0.0),
        od.encode_heartbeat(node_id, 0, state),
    ):
        axis.on_frame(f.arbitration_id, f.data, False, False, False, t)


def test_drive_set_cycles_every_drive_and_names_the_drive_in_its_fault_lines():
    ds = drive_set(**{"a.gear_ratio": 2.0})
    assert ds.joints == ["a", "b"] and ds.describe() == "'a' (id 1), 'b' (id 2)"
    ds.request_enable()
    feed_odrive(ds.axes[0], 1, 0.0)  # only drive a answers: motor at 0.5 rad
    frames, samples, lines = ds.cycle(0.001)
    assert samples[0].position == pytest.approx(0.25, rel=1e-6)  # its own gear ratio 2
    assert samples[1] is None  # no telemetry from b: no sample made up
    assert {f.arbitration_id >> 5 for f in frames} == {1}  # enable sequence + torque of drive a only
    assert ds.axes[0].enabled and not ds.axes[1].enabled
    assert [p.flags for p in ds.ports] == [FAULT_COMMAND_WATCHDOG, 0]
    assert lines == [
        ("warning", "drive 'a' (id 1): command_watchdog: no joint_commands received yet: zero torque")
    ]
    ds.send_failed()
    assert [p.flags & FAULT_BUS for p in ds.ports] == [FAULT_BUS, FAULT_BUS]


def test_drive_set_failure_and_shutdown_leave_every_drive_disabled():
    ds = drive_set()
    ds.request_enable()
    for axis, node_id in zip(ds.axes, (1, 2)):
        feed_odrive(axis, node_id, 0.0)
    ds.cycle(0.001)
    assert all(a.enabled for a in ds.axes)
    frames = ds.fail("internal error: boom")
    assert sorted({f.arbitration_id >> 5 for f in frames}) == [1, 2] and not any(a.enabled for a in ds.axes)
    _, _, lines = ds.cycle(0.002)
    errors = [text for level, text in lines if level == "error"]
    assert [t.split(":")[0] for t in errors] == ["drive 'a' (id 1)", "drive 'b' (id 2)"]
    assert all("internal error: boom" in t for t in errors)
    level, message, values = ds.health(0.003)
    assert level == ERROR and message == "a: fault: internal error: boom; b: fault: internal error: boom"
    assert values["a.enabled"] is False and values["b.fault_reason"] == "internal error: boom"
    ds.request_enable()  # clears the latched faults of both
    assert [a.latched for a in ds.axes] == [0, 0]
    assert {f.arbitration_id >> 5 for f in ds.disable_frames()} == {1, 2}
    assert {f.arbitration_id >> 5 for f in ds.shutdown_frames()} == {1, 2}


def test_drive_set_reconfigures_all_or_nothing():
    ds = drive_set(**{"b.torque_limit": 3.0})
    assert [a.cfg.torque_limit for a in ds.axes] == [NODE_VALUES["torque_limit"], 3.0]
    assert ds.reconfigure({"b.torque_limit": 2.5, "command_timeout": 0.05}) == {"command_timeout": 0.05}
    assert [a.cfg.torque_limit for a in ds.axes] == [NODE_VALUES["torque_limit"], 2.5]
    assert [a.cfg.command_timeout for a in ds.axes] == [0.05, 0.05]
    with pytest.raises(ParameterError, match="direction"):  # b refuses: a keeps its config too
        ds.reconfigure({"a.torque_limit": 0.5, "b.direction": 0})
    assert [a.cfg.torque_limit for a in ds.axes] == [NODE_VALUES["torque_limit"], 2.5]
    assert ds.ports[0].values["torque_limit"] == NODE_VALUES["torque_limit"]


def test_drive_set_health_of_one_drive_is_its_own_report():
    ds = DriveSet([dict(NODE_VALUES)], multi=False)
    level, message, values = ds.health(0.0)
    assert (level, message) == (WARN, "disabled, no telemetry yet") and "enabled" in values


def test_drive_set_refuses_one_node_id_twice():
    with pytest.raises(ParameterError, match="a.node_id = 3, b.node_id = 3"):
        drive_set(ids=(3, 3))


def test_per_joint_parameters_default_to_the_node_and_carry_each_joints_units():
    v = {**NODE_VALUES, "torque_limit": 2.0}
    specs = {f.name: f for f in axis_param_specs(JOINTS, v, {"b": "prismatic"})}
    assert set(specs) == {f"{j}.{k}" for j in JOINTS for k in AXIS_KEYS}
    assert specs["a.torque_limit"].default == 2.0 and specs["b.torque_limit"].default == 2.0
    assert (specs["a.torque_limit"].unit, specs["b.torque_limit"].unit) == ("N*m", "N")
    assert (specs["a.velocity_limit"].unit, specs["b.velocity_limit"].unit) == ("rad/s", "m/s")
    assert specs["b.node_id"].doc.startswith("b: ")
