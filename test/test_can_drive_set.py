"""Several drives on one bus (core): routing of joint_commands, per-joint values, run-time changes."""

from __future__ import annotations

import pytest

from friction_ros.core.can.drive_set import axis_values, changed_values, check_joint_names
from friction_ros.core.can.joint_commands import route_efforts
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
