"""The plant_simulator's core bookkeeping (core.plant.stepping) without ROS: lockstep answers per
joint, command admission, realtime ticks and the /clock schedule."""

from __future__ import annotations

import math
from types import SimpleNamespace

from friction_ros.core.plant.stepping import PlantStepper
from friction_ros.core.presets import load_preset

DT = 1e-3
JOINTS = ["a", "b"]
PRESETS = ["abb_m19s", "seed004_dc_motor"]


def _stepper(joints=JOINTS, presets=PRESETS, x0=0.1):
    plants = [load_preset(p).make_plant() for p in presets]
    return PlantStepper(joints, plants, DT, x0, log_period=1.0)


def _reference(presets=PRESETS, x0=0.1):
    plants = [load_preset(p).make_plant() for p in presets]
    for pl in plants:
        pl.reset(position=x0)
    return plants


def _cmd(names, efforts):
    return SimpleNamespace(name=list(names), effort=list(efforts), position=[], velocity=[])


def test_lockstep_merges_partial_answers_and_steps_every_plant_once():
    s = _stepper()
    ref = _reference()
    assert s.pending == (0.1, 0.1, 0.0, 0.0, 0.0, 0.0)
    efforts, events = s.select(_cmd(["b"], [0.002]), 1e3, 0.0)
    assert efforts == {1: 0.002} and events == []
    assert not s.answer(0, efforts)  # j1 has not answered yet
    assert not s.answer(0, {1: 0.5}) and s.commands_ignored == 1  # b again: a duplicate
    assert s.answer(0, {0: 3.0}) and s.steps == 1 and s.t_ns == 1_000_000
    ma = ref[0].step(3.0 * ref[0].command_scale, DT)
    mb = ref[1].step(0.002 * ref[1].command_scale, DT)
    assert s.pending == (ma.position, mb.position, ma.velocity, mb.velocity, ma.effort, mb.effort)
    assert not s.answer(0, {0: 1.0, 1: 1.0}) and s.commands_ignored == 2  # stale stamp
    assert s.answers == [None, None] and s.steps == 1


def test_implausible_efforts_become_zero_and_foreign_messages_are_ignored():
    s = _stepper()
    efforts, events = s.select(_cmd(["a", "b"], [math.nan, 1.0]), 1e3, 0.0)
    assert efforts == {0: 0.0, 1: 1.0} and s.commands_rejected == 1 and s.rejected_by_joint == [1, 0]
    assert [lvl for lvl, _ in events] == [1] and events[0][1].endswith("applying zero torque instead")
    efforts, events = s.select(_cmd(["a"], [20.0]), 10.0, 0.5)  # |effort| > max_effort
    assert efforts == {0: 0.0} and s.rejected_by_joint == [2, 0] and "out_of_range" in events[0][1]
    efforts, events = s.select(_cmd(["x", "y"], [1.0, 1.0]), 1e3, 0.6)
    assert efforts is None and s.commands_ignored == 1 and s.unknown_names == 2
    assert events[0][1].endswith("; ignored")
    _, again = s.select(_cmd(["a"], [math.inf]), 1e3, 0.1)  # same reason within log_period: no line
    assert again == [] and s.rejections.counts["not_finite"] == 2


def test_one_joint_uses_its_plant_range_as_the_bound_and_names_the_joint():
    s = _stepper(["j"], ["seed004_dc_motor"])
    limit = s.limit(s.scales[0], 1e30)
    assert limit == 1e9 / abs(s.scales[0]) and s.limit(0.0, 5.0) == 5.0
    efforts, events = s.select(_cmd(["j"], [limit * 1.5]), 1e30, 0.0)
    assert efforts == {0: 0.0} and "joint_commands for j" in events[0][1]
    efforts, events = s.select(_cmd(["k"], [0.1]), 1e30, 0.0)
    assert efforts is None and s.commands_ignored == 1


def test_realtime_ticks_apply_fresh_commands_zero_when_stale_and_count_missed_answers():
    s = _stepper()
    ref = _reference()
    s.hold(0, {0: 2.0, 1: 0.001}, now=10.0)
    clock = iter([5_000_000, 6_000_000])
    s.tick(10.05, 0.1, lambda: next(clock))
    ma = ref[0].step(2.0 * ref[0].command_scale, DT)
    mb = ref[1].step(0.001 * ref[1].command_scale, DT)
    assert s.pending[:2] == (ma.position, mb.position) and s.t_ns == 5_000_000 and s.missed == 0
    s.hold(5_000_000, {0: 2.0}, now=10.2)  # b does not answer and its command grows stale
    assert s.fresh(10.21, 0.1) == [True, False]
    s.tick(10.21, 0.1, lambda: next(clock))
    ma = ref[0].step(2.0 * ref[0].command_scale, DT)
    mb = ref[1].step(0.0, DT)
    assert s.pending[:2] == (ma.position, mb.position) and s.missed == 1 and s.steps == 2


def test_clock_is_due_every_clock_period_of_simulated_time():
    s = _stepper(["j"], ["seed004_dc_motor"])
    due = []
    for _ in range(25):
        due.append(s.clock_due(10_000_000))  # 10 ms
        s.answer(s.t_ns, {0: 0.0})
    assert [i for i, d in enumerate(due) if d] == [0, 10, 20]
    every = _stepper(["j"], ["seed004_dc_motor"])  # clock_period 0: every state
    due = []
    for _ in range(3):
        due.append(every.clock_due(0))
        every.answer(every.t_ns, {0: 0.0})
    assert due == [True, True, True]
