"""Every command is finite and inside the joint's limits, whatever comes in (pure core): absurd and
non-finite references, references beyond the limits, gains at the edge of float range, a friction
model whose state would be poisoned. The ROS side (references over DDS, run-time parameters, a node
without a limit) is in test_command_safety_ros.py."""

from __future__ import annotations

import math

import numpy as np
import pytest

from friction_ros.core.control.command_safety import JointLimits, check_reference_sample, check_trajectory
from friction_ros.core.control.controller import CompensatingController
from friction_ros.core.validation import ParameterError

GMS = {
    "model": "gms",
    "fc": 0.8,
    "fs": 0.95,
    "vs": 0.05,
    "delta": 2.0,
    "fv": 0.01,
    "attraction": 10.0,
    "k": [1e3, 2e3, 3e3, 4e3],
    "alpha": [0.1, 0.2, 0.3, 0.4],
}
LIMIT = 2.5


def _ctrl(**extra) -> CompensatingController:
    cfg = {
        "mode": "pid",
        "pid": {"p": 200.0, "i": 5.0, "d": 0.15},
        "effort_limit": LIMIT,
        "inertia": 0.0012,
        "friction": {"model": dict(GMS), "source": "feedforward"},
    }
    cfg.update(extra)
    return CompensatingController(cfg)


def _run(ctrl, refs, dt=1e-3, pos=0.0):
    out = []
    for k, ref in enumerate(refs):
        out.append(ctrl.compute(k * dt, ref, (pos, 0.0), dt).command)
    return np.array(out)


def test_an_absurd_reference_velocity_never_poisons_the_feedforward():
    """A finite reference velocity of 1e308 used to make every later command NaN (the GMS
    feedforward state overflowed). Now the sample is refused, held, recorded once; the friction
    feedforward keeps working on the next sane reference: the same commands as a fresh controller."""
    sane = [(0.01 * math.sin(k * 1e-3), 0.01 * math.cos(k * 1e-3), 0.0) for k in range(200)]
    attacked = _ctrl()
    cmds = _run(attacked, [(0.0, 1e308, 0.0)] * 5 + sane)
    assert np.all(np.isfinite(cmds)) and np.all(np.abs(cmds) <= LIMIT)
    assert 0.0 < attacked.terms.friction_feedforward <= GMS["fs"] + GMS["fv"] * 0.01  # a friction level again
    fresh = _ctrl()
    _run(fresh, sane)
    # the spline of a trajectory with such a velocity has an infinite acceleration: refused, held
    spline = _ctrl()
    cmds = _run(spline, [(9.98e304, 9.96e307, -math.inf)] * 5 + sane)
    assert np.all(np.isfinite(cmds)) and spline.guard.counts == {"reference": 5}
    assert spline.guard.take_new() == ["reference acceleration -inf is not finite"]
    assert spline.terms.friction_feedforward == pytest.approx(fresh.terms.friction_feedforward, rel=1e-9)
    # with a velocity limit the sample is refused at the reference check
    limited = _ctrl(velocity_limit=10.0)
    assert np.all(np.isfinite(_run(limited, [(0.0, 1e308, 0.0)] * 5)))
    assert limited.guard.counts == {"reference": 5}


def test_a_friction_term_that_goes_non_finite_is_dropped_and_its_state_reset():
    ctrl = _ctrl()
    real_update = ctrl.friction.update
    calls = {"n": 0}

    def poisoned(*a, **k):  # the model's state overflowing, as a NaN observer would
        calls["n"] += 1
        return (math.nan, 0.0) if calls["n"] <= 3 else real_update(*a, **k)

    ctrl.friction.update = poisoned
    cmds = _run(ctrl, [(0.0, 0.01, 0.0)] * 10)
    assert np.all(np.isfinite(cmds))
    assert ctrl.guard.counts == {"friction compensation": 3}
    assert ctrl.guard.take_new() == ["friction compensation was nan/0.0"]
    assert math.isfinite(ctrl.terms.friction_feedforward) and ctrl.terms.friction_feedforward != 0.0


def test_a_reference_beyond_the_limits_is_held_and_the_command_is_bounded():
    ctrl = _ctrl(position_min=-1.0, position_max=1.0, velocity_limit=2.0, acceleration_limit=50.0)
    cmds = _run(ctrl, [(0.2, 0.0, 0.0)] * 50 + [(1e300, 0.0, 0.0)] * 50 + [(0.2, 3.0, 0.0)] * 10)
    assert np.all(np.abs(cmds) <= LIMIT)
    assert ctrl.guard.counts["reference"] == 60
    assert ctrl.terms.reference_position == 0.2 and ctrl.terms.reference_velocity == 0.0
    why = ctrl.guard.take_new()
    assert len(why) == 1 and "outside the joint's limits [-1, 1]" in why[0]


@pytest.mark.parametrize(
    "ref",
    [(1e300, 0.0, 0.0), (1e6, 1e6, 0.0), (0.0, 0.0, 1e300), (-1e300, -1e300, -1e300)],
)
def test_without_position_limits_an_absurd_finite_reference_gives_at_most_the_effort_limit(ref):
    """A desired position of 1e300 rad used to command 1e6 N*m (the default clamp)."""
    ctrl = _ctrl()
    cmds = _run(ctrl, [ref] * 20)
    assert np.all(np.isfinite(cmds))
    assert np.max(np.abs(cmds)) == pytest.approx(LIMIT)


def test_non_finite_references_are_dropped_and_the_joint_holds():
    ctrl = _ctrl()
    cmds = _run(ctrl, [(0.1, 0.0, 0.0)] * 100 + [(math.nan, 0.0, 0.0), (0.0, math.inf, 0.0)] * 10)
    assert np.all(np.isfinite(cmds)) and np.all(np.abs(cmds) <= LIMIT)
    assert ctrl.terms.reference_position == 0.1  # the last good reference, at rest
    assert ctrl.guard.active and ctrl.guard.clear_quiet(100.0, 1.0) == ["reference"]


def test_gains_and_limits_are_checked_against_physical_ranges():
    for key, value, words in [
        ("pid", {"p": 1e308}, "pid.p = 1e+308 is out of range"),
        ("pid", {"d": math.inf}, "pid.d = inf"),
        ("effort_limit", 0.0, "effort_limit = 0 is out of range"),
        ("effort_limit", 1e9, "effort_limit = 1e+09 is out of range"),
        ("effort_limit", math.nan, "effort_limit = nan"),
        ("position_min", 2.0, "position_min = 2.0 is out of range: must be < position_max"),
    ]:
        extra = {key: value}
        if key == "position_min":
            extra["position_max"] = 1.0
        with pytest.raises(ParameterError) as e:
            _ctrl(**extra)
        assert words in str(e.value), str(e.value)
    ctrl = _ctrl()
    with pytest.raises(ParameterError):
        ctrl.set_pid_gains(p=1e308)
    assert ctrl.pid.p == 200.0  # unchanged


def test_an_infinite_clamp_still_leaves_the_effort_limit():
    ctrl = _ctrl(u_clamp_max=math.inf, u_clamp_min=-math.inf, pid={"p": 1e12, "d": 0.0})
    cmds = _run(ctrl, [(1.0, 0.0, 0.0)] * 10)
    assert np.all(np.abs(cmds) == LIMIT)
    assert (ctrl.u_clamp_min, ctrl.u_clamp_max) == (-LIMIT, LIMIT)
    tighter = _ctrl(u_clamp_max=1.0, u_clamp_min=-0.5)
    assert (tighter.u_clamp_min, tighter.u_clamp_max) == (-0.5, 1.0)


def test_a_controller_without_any_limit_is_flagged_for_the_node():
    assert _ctrl().limits_given
    assert not CompensatingController({"mode": "pid"}).limits_given
    assert CompensatingController({"u_clamp_max": 3.0, "u_clamp_min": -3.0}).limits_given
    assert not CompensatingController({"u_clamp_max": 3.0}).limits_given


def test_an_overflowing_feedback_law_is_reset_and_the_last_command_held():
    """Gains at the edge of the allowed range times an error at the edge of float: p e = inf, and
    inf - inf = nan in the sum; the command stays the last finite one."""
    ctrl = _ctrl(pid={"p": 1e12, "i": 0.0, "d": 1e12}, friction={"model": None})
    ctrl.compute(0.0, (0.0, 0.0, 0.0), (0.0, 0.0), 1e-3)
    t = ctrl.compute(1e-3, (1e300, -1e300, 0.0), (-1e300, 1e300), 1e-3)
    assert math.isfinite(t.command) and abs(t.command) <= LIMIT
    assert ctrl.guard.total >= 1


def test_trajectory_check_names_the_first_bad_point():
    lim = JointLimits(effort_limit=2.0, position_min=-1.0, position_max=1.0, velocity_limit=1.0)
    check_trajectory(lim, [0.0, 1.0, 2.0], [0.0, 0.5, 0.9], [0.0, 0.5, 0.0])
    cases = [
        (([0.0, 1.0], [0.0, math.nan], None), "point 1 (t = 1 s): reference position nan is not finite"),
        (([0.0, 1.0], [0.0, 0.5], [0.0, 1e308]), "point 1 (t = 1 s): reference velocity 1e+308 exceeds"),
        (([0.0, 1.0], [0.0, 1e6], None), "point 1 (t = 1 s): reference position 1e+06 is outside"),
        (([0.0, 0.1], [0.0, 0.5], None), "points 0-1: moving 0.5 in 0.1 s needs 5"),
        (([0.0, math.inf], [0.0, 0.5], None), "point 1: time_from_start inf is not finite"),
    ]
    for (times, pos, vel), words in cases:
        with pytest.raises(ParameterError) as e:
            check_trajectory(lim, times, pos, vel)
        assert words in str(e.value), str(e.value)
    assert check_reference_sample(JointLimits(), 1e300, 0.0, 0.0) == ""
    assert "acceleration" in check_reference_sample(JointLimits(acceleration_limit=1.0), 0.0, 0.0, 2.0)


def test_an_unstable_loop_is_stopped_and_the_joint_damped_to_rest():
    """PID p x200 with blended compensation: the watch first switches compensation off; the loop
    still oscillates (the gains), so position feedback stops and the loop's damping alone brings the
    joint to rest: the command was +-limit before, it is 0 at rest at the end."""
    from friction_ros.core.experiment.arm_example import stribeck_map
    from friction_ros.core.experiment.joint_scale import JointScale
    from friction_ros.core.experiment.tracking_design import tracking_gains, tracking_reference
    from friction_ros.core.harness import run_closed_loop
    from friction_ros.core.presets import load_preset

    for name in ("abb_m19s", "seed001_harmonic_drive"):
        preset = load_preset(name)
        scale = JointScale.from_preset(preset, period=1e-3)
        g = tracking_gains(scale)
        ref = tracking_reference(scale, duration=3.0)
        model = stribeck_map(preset, 1.0)
        cfg = {
            "mode": "pid",
            "effort_limit": scale.torque_limit,
            "pid": {"p": 200.0 * g["p"], "d": g["d"]},
            "friction": {"model": model, "source": "blended"},
        }
        ctrl = CompensatingController(cfg)
        res = run_closed_loop(preset, ctrl, ref, 3.0, 1e-3)
        assert ctrl.compensation_fallback and ctrl.loop_unstable, name
        assert "gains make it unstable" in ctrl.fallback_reason
        assert np.max(np.abs(res.torque)) <= scale.torque_limit * (1 + 1e-12)
        last = res.t > 2.5
        assert np.ptp(res.true_position[last]) < 1e-6 * max(1.0, scale.travel), name
        assert np.max(np.abs(res.torque[last])) < 1e-3 * scale.torque_limit, name
        # the same gains without the feedback path: the unwatched PID alone is what oscillates
        ok = CompensatingController({**cfg, "pid": {"p": g["p"], "d": g["d"]}})
        run_closed_loop(preset, ok, ref, 3.0, 1e-3)
        assert not ok.loop_unstable


def test_the_watch_is_armed_only_after_its_averages_settle():
    """A start-up transient (a first error sample far from zero, chatter in the first periods) used to
    fire the watch at t = 0.053 s on a fitted file in realtime mode."""
    from friction_ros.core.control.limit_cycle import LimitCycleDetector

    det = LimitCycleDetector(window=0.04, hold=0.03)

    def sample(k: int) -> bool:  # a 50 Hz oscillation about a reference at rest, from the first sample
        e = 0.01 * math.sin(2 * math.pi * 50 * k * 1e-3 + 0.3)
        return det.update(k * 1e-3, e, 10 * e, 0.0, -e, 1e-3, 0.0)

    assert not any(sample(k) for k in range(68))  # armed after one window, then the hold
    assert any(sample(k) for k in range(68, 200))
    assert det.fired_at >= 0.04 + 0.03 - 2e-3
