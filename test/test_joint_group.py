"""Multi-joint control without ROS: the JointGroup (the compensating_controller node's per-sample
path) through the N-joint lockstep harness, and the estimator's group. A missing joint gets zero
torque after the state timeout while the others stay controlled; a clock jump or a re-homing is
re-synchronised; the compensation fallback switches off one joint's compensation only."""

from __future__ import annotations

import numpy as np
import pytest

from friction_ros.core.estimation.estimator import OnlineFrictionEstimator
from friction_ros.core.estimation.joint_estimators import EstimatorGroup
from friction_ros.core.experiment.joint_scale import JointScale
from friction_ros.core.experiment.references import reference_from_config
from friction_ros.core.experiment.tracking_design import tracking_gains, tracking_reference
from friction_ros.core.harness import run_closed_loop, run_closed_loop_group
from friction_ros.core.input_gate import JointInputGate
from friction_ros.core.joint_channel import ERROR, WARN, JointChannel
from friction_ros.core.joint_group import COMPUTED, IDLE, RESEND, JointGroup
from friction_ros.core.joint_group_inputs import control_channel
from friction_ros.core.presets import load_preset
from friction_ros.core.validation import ParameterError
from friction_ros.core.wire import DecodedJointState

DT = 1e-3


def _joint(name: str, coulomb: float = 1.0, gain: float = 1.0, duration: float = 3.0):
    """(preset, controller config, reference) of a preset's joint with its tracking gains and its
    own friction model (Coulomb/static friction x ``coulomb``, compensation gain ``gain``)."""
    preset = load_preset(name)
    scale = JointScale.from_preset(preset, period=DT)
    g = tracking_gains(scale)
    model = preset.friction.to_config()
    for key in ("fc", "fs"):
        if key in model:
            model[key] *= coulomb
    cfg = {
        "mode": "pid",
        "effort_limit": scale.torque_limit,
        "pid": {"p": g["p"], "d": g["d"]},
        "inertia": scale.inertia,
        "friction": {"model": model, "source": "blended", "gain": gain},
    }
    return preset, cfg, tracking_reference(scale, duration=duration)


def _arm(duration: float = 2.0, **a_kwargs):
    return {
        "a": _joint("abb_m19s", duration=duration, **a_kwargs),
        "b": _joint("seed001_harmonic_drive", duration=duration),
    }


def test_one_joint_group_is_the_single_joint_loop():
    preset, cfg, ref = _joint("abb_m19s", duration=1.0)
    single = run_closed_loop(preset, cfg, ref, 1.0, DT)
    group = run_closed_loop_group({"a": (preset, cfg, ref)}, 1.0, DT)
    # the same controller, reference and plant; t from stamps differs from k*dt by rounding only
    np.testing.assert_allclose(group.torque[:, 0], single.torque, rtol=1e-9, atol=1e-12)
    assert group.metrics["a"]["rms_error"] == pytest.approx(single.metrics["rms_error"], rel=1e-9)
    assert group.received.all() and not group.timed_out.any() and group.events == []


def test_a_missing_joint_holds_then_gets_zero_torque_and_the_other_stays_controlled():
    clean = run_closed_loop_group(_arm(), 2.0, DT)
    res = run_closed_loop_group(_arm(), 2.0, DT, missing={"b": (1.0, 1.5)}, state_timeout=0.05)
    t, b = np.arange(len(res.t)) * DT, res.column("b")  # the harness's period starts
    gone, held = (t >= 1.0) & (t < 1.5), (t >= 1.0) & (t < 1.045)
    assert not res.received[gone, b].any() and res.received[~gone, b].all()
    # held at the last command until the timeout, then exactly zero until b is back
    last = res.torque[np.flatnonzero(t < 1.0)[-1], b]
    assert last != 0.0 and np.all(res.torque[held, b] == last)
    zero = gone & (t > 1.055)
    assert np.all(res.torque[zero, b] == 0.0) and res.timed_out[zero, b].all()
    assert not res.timed_out[t >= 1.5, b].any() and np.all(res.torque[t >= 1.5, b] != 0.0)
    # joint a is computed exactly as without the fault
    np.testing.assert_array_equal(res.torque[:, 0], clean.torque[:, 0])
    assert res.metrics["a"]["rms_error"] == clean.metrics["a"]["rms_error"]
    texts = [text for _, _, text in res.events]
    assert any(x.startswith("b: no valid joint state for 0.05 s") for x in texts)
    assert "b: joint states valid again: controlling" in texts
    assert not any(x.startswith("a:") for x in texts)


def test_a_clock_jump_is_resynchronised_and_the_time_base_continues():
    clean = run_closed_loop_group(_arm(), 2.0, DT)
    res = run_closed_loop_group(_arm(), 2.0, DT, stamp_jump=(1.0, 3.0))
    group = res.group
    n = group.channels[0].gate.resync_samples
    for ch in group.channels:
        assert ch.gate.counts["resyncs"] == 1 and ch.gate.log.counts["future_stamp"] == n - 1
    # the controller's time continues one period after the last accepted: it lags by the n - 1
    # rejected periods, not by the 3 s of the jump
    assert group.last_t == pytest.approx(2.0 - DT - (n - 1) * DT, abs=1e-9)
    # after the jump each joint tracks its reference delayed by those periods as well as before
    lag, late = (n - 1) * DT, res.t > 1.2
    for i, j in enumerate(("a", "b")):
        ref = reference_from_config(_arm()[j][2])
        err = ref.arrays(res.t[late] - lag)[0] - res.true_position[late, i]
        assert np.sqrt(np.mean(err**2)) < 1.5 * clean.metrics[j]["rms_error"]
    assert sum("re-synchronised" in text and level == WARN for _, level, text in res.events) == 2


def test_a_rehomed_joint_is_resynchronised_alone():
    gate = {"max_velocity": 10.0}  # a jump is > 10 rad/s x 1 ms
    clean = run_closed_loop_group(_arm(), 2.0, DT, input_gate=gate)
    res = run_closed_loop_group(_arm(), 2.0, DT, input_gate=gate, position_offset={"b": (1.0, 0.5)})
    a, b = res.group.channels
    assert b.gate.counts["resyncs"] == 1 and b.gate.resync_reason == "jump"
    assert b.gate.log.counts["jump"] == b.gate.resync_samples - 1
    assert a.gate.counts["resyncs"] == 0 and a.gate.log.total == 0
    np.testing.assert_array_equal(res.torque[:, 0], clean.torque[:, 0])
    assert res.group.last_t == pytest.approx(2.0 - DT, abs=1e-9)  # a jump keeps the time base
    # b moves 0.5 rad to its reference in the new frame (reported = measured + 0.5) and tracks it
    late = res.t > 1.8
    err = res.reference[late, 1] - (res.position[late, 1] + 0.5)
    assert np.sqrt(np.mean(err**2)) < 2.0 * clean.metrics["b"]["rms_error"] + 1e-4


def test_the_compensation_fallback_switches_off_one_joint_only():
    clean = run_closed_loop_group(_arm(3.0), 3.0, DT)
    res = run_closed_loop_group(_arm(3.0, coulomb=4.0, gain=2.0), 3.0, DT)  # a over-compensates
    a, b = res.group.channels
    assert a.controller.compensation_fallback and "over-compensation" in a.controller.fallback_reason
    assert not b.controller.compensation_fallback and not res.fallback[:, 1].any()
    fired = res.t[np.argmax(res.fallback[:, 0])]
    assert 1.0 < fired < 3.0
    np.testing.assert_array_equal(res.torque[:, 1], clean.torque[:, 1])
    errors = [text for _, level, text in res.events if level == ERROR]
    assert len(errors) == 1 and errors[0].startswith("a: over-compensation")
    assert res.group.fallback_fired
    status = dict((j, (lvl, text)) for j, lvl, text, _ in res.group.statuses({}))
    assert status["a"][0] == ERROR and status["b"][0] != ERROR


def _sample(stamp_ns: int, names, pos, vel=None, eff=None) -> DecodedJointState:
    n = len(names)
    return DecodedJointState(
        stamp_ns // 10**9,
        stamp_ns % 10**9,
        "",
        tuple(names),
        tuple(pos),
        tuple(vel or [0.0] * n),
        tuple(eff or [0.0] * n),
    )


def _group(joints=("a", "b"), mode="pid", reference=True):
    _, cfg, ref = _joint("abb_m19s", duration=1.0)
    cfg = {**cfg, "mode": mode}
    from friction_ros.core.control.controller import CompensatingController

    return JointGroup(
        [
            control_channel(
                j,
                CompensatingController(cfg),
                reference_from_config(ref),
                JointInputGate(j, period=DT),
                has_reference=reference,
            )
            for j in joints
        ],
        DT,
    )


def test_duplicates_ask_for_a_resend_and_an_unknown_sample_changes_nothing():
    g = _group()
    msg = _sample(10**9, ["a", "b"], [0.0, 0.0])
    assert g.step(msg, 10**9, 0.0) == COMPUTED and [ch.joint for ch in g.computed] == ["a", "b"]
    before = g.commands
    assert g.step(msg, 10**9 + 10**6, 0.001) == RESEND and g.commands == before
    assert g.step(_sample(10**9 + 2 * 10**6, ["x"], [0.0]), 10**9 + 2 * 10**6, 0.002) == IDLE
    assert g.counts["cycles"] == 1 and g.commands == before
    rejected = [text for level, text in g.take_events() if level == WARN]
    assert len(rejected) == 2 and all("holding the last command" in x for x in rejected)


def test_an_addon_without_a_reference_outputs_zero_and_a_mixed_addon_is_refused():
    g = _group(mode="compensation_only", reference=False)
    assert g.addon and g.step(_sample(10**9, ["a", "b"], [0.1, 0.2]), 10**9, 0.0) == COMPUTED
    assert g.commands == [0.0, 0.0] and g.computed == []
    assert sum("no desired trajectory yet" in text for _, text in g.take_events()) == 2
    assert g.set_desired(["b"], [0.1], [0.5]) == []
    g.step(_sample(10**9 + 10**6, ["a", "b"], [0.1, 0.2]), 10**9 + 10**6, 0.001)
    assert g.commands[0] == 0.0 and g.commands[1] != 0.0
    refused = g.set_desired(["a"], [float("nan")], [0.0])
    assert len(refused) == 1 and refused[0].startswith("a: rejected desired_joint_states")
    assert g.counts["rejected_references"] == 1
    mixed = _group(joints=("a",))
    with pytest.raises(ParameterError, match="compensation_only must be the mode of every joint"):
        JointGroup([*mixed.channels, *_group(joints=("b",), mode="compensation_only").channels], DT)


def test_a_trajectory_beyond_the_limits_is_refused_whole():
    g = _group()
    g.step(_sample(10**9, ["a", "b"], [0.0, 0.0]), 10**9, 0.0)
    why = g.set_trajectory(["a", "b"], [0.0, 1.0], 0, [[0.0, 0.0], [0.1, 1e12]], [[], []], [[], []])
    assert why.startswith("b: ") and g.counts["rejected_references"] == 1
    assert all(ch.trajectory is None for ch in g.channels)
    assert g.set_trajectory(["a"], [0.0, 1.0], 0, [[0.0], [0.1]], [[], []], [[], []]) == ""
    assert g.channels[0].trajectory is not None and g.channels[1].trajectory is None


def test_the_estimator_group_skips_a_missing_joint_only():
    def channel(j):
        ch = JointChannel(j, JointInputGate(j, period=DT, need_velocity=True, need_effort=True))
        ch.estimator = OnlineFrictionEstimator({"model": "coulomb_viscous"})
        return ch

    g = EstimatorGroup([channel("a"), channel("b")], DT, publish_every=5)
    due = []
    for k in range(20):
        names = ["a", "b"] if not 5 <= k < 10 else ["a"]
        v = 0.1 * np.sin(k * 0.3)
        msg = _sample(10**9 + k * 10**6, names, [0.0] * len(names), [v] * len(names), [0.5 * v] * len(names))
        due.append([ch.joint for ch in g.step(msg, 10**9 + k * 10**6)])
    a, b = g.channels
    assert a.counts["samples"] == 20 and b.counts["samples"] == 15
    assert sum(x.count("a") for x in due) == 4 and sum(x.count("b") for x in due) == 3
    assert b.gate.log.counts["wrong_joint"] == 5
    fields = EstimatorGroup.estimate(a)
    assert fields[0] == "coulomb_viscous" and len(fields[5]) == len(fields[6]) >= 2
    status = {j: lvl for j, lvl, _, _ in g.statuses()}
    assert status["b"] == WARN  # rejections since the last status
