"""One command source per joint (pure core): sources told apart by header.frame_id."""

from __future__ import annotations

from friction_ros.core.command_sources import CommandSources


def test_two_sources_on_one_joint_conflict_until_one_is_alone_for_the_window():
    s = CommandSources(["j1", "j2"], window=0.5)
    assert s.admit("/ctrl_a", [0], 0.0) == set()
    assert s.admit("/ctrl_b", [0], 0.01) == {0}
    assert s.started == [("j1", ["/ctrl_a", "/ctrl_b"])] and s.in_conflict(0) and not s.in_conflict(1)
    s.started.clear()
    for k in range(1, 50):  # ctrl_b stopped at 0.01 s; ctrl_a goes on
        t = 0.01 + 0.02 * k
        conflicted = s.admit("/ctrl_a", [0], t)
        assert conflicted == ({0} if t - 0.01 <= 0.5 else set()), t
    assert s.cleared == [("j1", "/ctrl_a")]


def test_controllers_of_different_joints_on_one_topic_are_no_conflict():
    s = CommandSources(["j1", "j2", "j3"])
    for k in range(100):
        t = 1e-3 * k
        assert s.admit("/arm/ctrl_j1", [0], t) == set()
        assert s.admit("/arm/ctrl_j23", [1, 2], t) == set()
    assert s.started == [] and s.sources(1) == ["/arm/ctrl_j23"]


def test_a_silent_rival_expires_on_the_timer():
    s = CommandSources(["j1"], window=0.5)
    s.admit("", [0], 0.0)
    s.admit("/ctrl", [0], 0.1)
    assert s.in_conflict(0)
    s.expire(0.55)  # "" last seen at 0.0
    assert not s.in_conflict(0) and s.cleared == [("j1", "/ctrl")]
