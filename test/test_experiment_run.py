"""The identification_experiment's per-state bookkeeping (core.experiment.experiment_run) without
ROS: re-sends, stale states, the end tail on joint time, exit codes, rejected states, diagnostics."""

from __future__ import annotations

import math
from types import SimpleNamespace

from friction_ros.core.experiment.excitation import EXIT_ABORTED, EXIT_NOT_EXCITED, ExcitationProgram
from friction_ros.core.experiment.excitation_config import profile_defaults
from friction_ros.core.experiment.experiment_run import (
    COMPUTED,
    IGNORED,
    RESEND,
    ExperimentRun,
    program_config,
)
from friction_ros.core.joint_channel import ERROR, OK, WARN
from friction_ros.core.presets import load_preset

MS = 1_000_000
T0 = 1_700_000_000 * 10**9  # a wall-clock-like first stamp: joint time starts at 0 there


def _values(program: str, **limits) -> dict:
    v = profile_defaults("quick")
    v["limits"] = {**v["limits"], **limits}
    v.update(profile="quick", program=program, bias=0.0, control_period=1e-3)
    return v


def _run(program: str = "chirp", end_tail: float = 0.2, **limits) -> ExperimentRun:
    v = _values(program, **limits)
    return ExperimentRun(ExcitationProgram(program_config(v, v)), "j", [], end_tail)


def _state(names, positions, velocities=None):
    return SimpleNamespace(
        name=list(names), position=list(positions), velocity=list(velocities or []), effort=[]
    )


def test_states_are_answered_once_resent_when_repeated_and_match_the_program():
    run = _run()
    twin = ExcitationProgram(program_config(_values("chirp"), _values("chirp")))
    for k in range(3):
        action, torque, _, _ = run.step(T0 + k * MS, [(0.01 * k, 0.2, None)], can_resend=True)
        expected, _ = twin.update(k * 1e-3, 0.01 * k, 0.2)
        assert action == COMPUTED and torque == expected
    assert run.step(T0 + 2 * MS, [(0.0, 0.0, None)], can_resend=True)[0] == RESEND
    assert run.step(T0 + 2 * MS, [(0.0, 0.0, None)], can_resend=False)[0] == IGNORED
    assert run.step(T0 + MS, [(0.0, 0.0, None)], can_resend=True)[0] == IGNORED  # older
    assert run.counts["cycles"] == 3 and run.counts["duplicates"] == 1
    _, nan_torque, _, _ = run.step(T0 + 3 * MS, [(0.03, None, None)], True)  # no velocity: NaN
    assert nan_torque == twin.update(3e-3, 0.03, math.nan)[0]


def test_a_completed_program_is_answered_for_the_tail_then_no_more():
    plant = load_preset("abb_m19s").make_plant()  # the quick profile's scale
    run = _run("chirp", end_tail=0.05)
    k, pos, vel = 0, 0.0, 0.0
    while not run.program.done:
        action, torque, _, _ = run.step(T0 + k * MS, [(pos, vel, None)], True)
        assert action == COMPUTED
        m = plant.step(torque * plant.command_scale, 1e-3)
        pos, vel, k = m.position, m.velocity, k + 1
    ((level, line),) = run.finish(T0 + (k - 1) * MS, wall=1.5)
    assert run.code == 0 and level == OK and line.startswith("[100%] program chirp complete")
    assert run.end_ns == T0 + (k - 1) * MS + 50 * MS
    answered = [run.step(T0 + (k + i) * MS, [(pos, 0.0, None)], True)[0] for i in range(60)]
    assert answered == [COMPUTED] * 50 + [IGNORED] * 10  # stamps up to end_ns only
    assert run.diagnostics()[:2] == (OK, "complete")


def test_a_joint_that_does_not_move_ends_the_run_with_the_not_excited_code():
    run = _run("plateaus")  # checked segments (a chirp is not checked on its own)
    k = 0
    while not run.program.done and k < 20_000:
        run.step(T0 + k * MS, [(0.0, 0.0, None)], True)
        k += 1
    assert run.program.not_excited is not None
    ((level, line),) = run.finish(T0 + k * MS, wall=1.0)
    assert run.code == EXIT_NOT_EXCITED and level == ERROR and run.program.not_excited in line
    assert run.diagnostics()[:2] == (ERROR, run.program.not_excited)


def test_a_safety_limit_stops_the_run_with_the_aborted_code_and_counts_the_abort():
    run = _run("chirp", max_travel=0.5)
    start = run.step(T0, [(0.0, 0.0, None)], True)
    assert start[0] == COMPUTED and start[2]  # the START event, joint '' (one joint)
    _, torque, events, _ = run.step(T0 + MS, [(0.6, 0.0, None)], True)
    for _, e in events:
        run.count_event(e)
    assert run.program.done and torque == 0.0 and run.counts["aborts"] == 1
    ((level, line),) = run.finish(T0 + MS, wall=0.1)
    assert run.code == EXIT_ABORTED and level == ERROR and "safety limit" in line and "max_travel" in line
    level, text, values = run.diagnostics()
    assert level == ERROR and text.startswith("segment aborted") and values["aborts"] == 1


def test_states_without_the_joint_are_counted_and_logged_at_most_every_10_s():
    run = _run()
    samples, lines = run.select(_state(["a", "b"], [0.0, 0.0]), now=100.0)
    assert samples is None and [lvl for lvl, _ in lines] == [WARN]
    assert "carry no joint 'j' (they carry: a, b); set joint_name" in lines[0][1]
    assert run.select(_state(["a"], [0.0]), now=105.0) == (None, [])  # within 10 s: counted only
    _, lines = run.select(_state(["a"], [0.0]), now=110.5)
    assert "(3 state(s) ignored so far)" in lines[0][1] and run.counts["rejected_states"] == 3
    samples, lines = run.select(_state(["a", "j"], [0.0, 0.25], [0.0, 1.5]), now=111.0)
    assert samples == [(0.25, 1.5, None)] and lines == []
    level, text, values = run.diagnostics()
    assert (level, text) == (OK, "waiting for joint states") and values["rejected_states"] == 3
