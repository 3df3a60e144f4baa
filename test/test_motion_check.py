"""The excitation program's motion check (pure core): a joint that does not move, cannot reach its
speeds or never reverses ends the program with ABORT and a reason (``not_excited``); a joint that
follows the program passes untouched."""

from __future__ import annotations

import numpy as np
import pytest

from friction_ros.core.experiment.events import ABORT, END
from friction_ros.core.experiment.excitation import make_program
from friction_ros.core.presets import load_preset


def run_stuck(config, position=lambda t: 0.0, limit=200.0):
    """Feed the program a joint whose position is ``position(t)`` whatever the torque."""
    prog = make_program(config)
    dt = prog.config["control_period"]
    events, torques, t, last = [], [], 0.0, None
    while not prog.done and t < limit:
        pos = position(t)
        vel = 0.0 if last is None else (pos - last) / dt
        tau, ev = prog.update(t, pos, vel)
        events += ev
        torques.append(tau)
        last = pos
        t += dt
    return prog, events, np.array(torques), t


def run_plant(config, preset="abb_m19s"):
    p = load_preset(preset)
    plant = p.make_plant()
    scale = plant.command_scale
    prog = make_program(config)
    dt = prog.config["control_period"]
    t, pos, vel, events = 0.0, 0.0, 0.0, []
    while not prog.done and t < prog.total_duration + 1.0:
        tau, ev = prog.update(t, pos, vel)
        events += ev
        m = plant.step(tau * scale, dt)
        pos, vel = m.position, m.velocity
        t += dt
    return prog, events, t


def test_a_stuck_joint_stops_the_plateaus_after_max_failures_with_the_reason():
    prog, events, tau, t = run_stuck({"program": "plateaus", "profile": "quick"})
    aborts = [e for e in events if e.event == ABORT]
    assert not [e for e in events if e.event == END]
    # three plateaus (0.7 s each) fail, then the program stops: ~2.1 s instead of the planned 5.6 s
    assert [a.segment for a in aborts] == ["plateau+5", "plateau-5", "plateau+1.71", "program"]
    assert "held +0 rad/s on average" in aborts[0].note and "motion_check.fraction" in aborts[0].note
    assert "torque limit" in aborts[0].note  # the velocity loop saturated the whole hold
    assert prog.done and prog.not_excited == aborts[-1].note
    assert "3 segments in a row" in prog.not_excited and "max_failures = 3" in prog.not_excited
    assert t == pytest.approx(3 * 0.7, abs=0.01) and prog.total_duration == pytest.approx(5.6)
    assert tau[-1] == 0.0  # zero torque once stopped


def test_a_stuck_joint_fails_the_whole_sequence_early():
    prog, events, tau, t = run_stuck({"program": "sequence", "profile": "quick"})
    assert prog.not_excited is not None
    # the breakaway ramps cannot move it, then the first plateau fails: three in a row
    aborts = [e.segment for e in events if e.event == ABORT]
    assert aborts == ["breakaway+", "breakaway-", "plateau+5", "program"]
    assert t < 0.5 * prog.total_duration


def test_a_torque_limit_below_friction_is_named_as_saturation():
    # velocity loop limited to 0.5 N*m on a joint with 0.95 N*m static friction: plateaus never move
    prog, events, _ = run_plant(
        {"program": "plateaus", "profile": "quick", "velocity_loop": {"torque_limit": 0.5}}
    )
    aborts = [e for e in events if e.event == ABORT]
    assert prog.not_excited is not None and len(aborts) == 4
    assert "torque limit 0.5 N*m for 100 % of it" in aborts[0].note


def test_a_joint_that_moves_one_way_only_is_not_excited():
    # the random program with its RMS check off, on a joint creeping one way: it moves, never reverses
    prog, events, _, _ = run_stuck(
        {"program": "random", "profile": "quick", "motion_check": {"fraction": 0.0}},
        position=lambda t: 0.01 * t,
        limit=20.0,
    )
    assert prog.not_excited is not None
    assert "reversed 0 time(s)" in prog.not_excited and "motion_check.reversals = 1" in prog.not_excited
    assert events[-1].event == ABORT and events[-1].segment == "program"


def test_open_loop_programs_alone_are_not_checked_and_checks_can_be_turned_off():
    # presliding stays below a count by design, a chirp may on a coarse encoder
    for program in ("presliding", "chirp"):
        prog, events, _, _ = run_stuck({"program": program, "profile": "quick"})
        assert prog.done and prog.not_excited is None and not [e for e in events if e.event == ABORT]
    off = {"fraction": 0.0, "max_failures": 0, "travel_counts": 0}
    prog, events, _, _ = run_stuck({"program": "plateaus", "profile": "quick", "motion_check": off})
    assert prog.done and prog.not_excited is None and not [e for e in events if e.event == ABORT]


@pytest.mark.parametrize("program", ["sequence", "plateaus"])
def test_a_joint_that_follows_the_program_passes(program):
    prog, events, _ = run_plant({"program": program, "profile": "quick"})
    assert prog.done and prog.not_excited is None and not prog.aborted
    assert not [e for e in events if e.event == ABORT]
    assert prog.reversals >= 4
