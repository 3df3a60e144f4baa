"""Experiments and gains sized to the joint: every preset in params/ and a user-written preset."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest
import yaml

from friction_ros.core.excitation import ABORT, END, make_program
from friction_ros.core.harness import command_scale, make_plant, run_closed_loop
from friction_ros.core.joint_sizing import (
    JointScale,
    crossover,
    experiment_config,
    tracking_gains,
    tracking_reference,
)
from friction_ros.core.presets import PRESET_NAMES, load_preset, preset_from_config
from friction_ros.core.validation import ParameterError


def run_program(preset, profile="quick"):
    """The sized program on the preset's plant, fed the *measured* state as the ROS node does."""
    scale = JointScale.from_preset(preset)
    cfg = experiment_config(scale, profile)
    prog = make_program(cfg)
    plant = preset.make_plant()
    k = command_scale(plant)
    plant.reset()
    pos = vel = t = 0.0
    events, v_meas = [], []
    for _ in range(int(prog.total_duration / scale.period) + 10):
        tau, ev = prog.update(t, pos, vel)
        events += ev
        m = plant.step(tau * k, scale.period)
        pos, vel = m.position, m.velocity
        v_meas.append(m.velocity)  # measured: what the experiment node and the fitter see
        t += scale.period
        if prog.done:
            break
    return scale, cfg, prog, events, np.array(v_meas)


@pytest.fixture(scope="module", params=PRESET_NAMES)
def preset_run(request):
    preset = load_preset(request.param)
    return (preset, *run_program(preset))


def test_the_sized_program_completes_on_every_preset(preset_run):
    preset, scale, cfg, prog, events, v = preset_run
    aborts = [(e.segment, e.note) for e in events if e.event == ABORT]
    assert prog.done and not prog.aborted and not aborts, (preset.name, aborts)
    ends = [e for e in events if e.event == END and e.program == "breakaway"]
    assert {int(np.sign(e.target)) for e in ends} == {1, -1}, preset.name  # breakaway both ways
    assert all(abs(e.target) >= 0.5 * scale.breakaway for e in ends)
    s = np.sign(v[np.abs(v) > 1e-9])
    assert int(np.sum(s[1:] != s[:-1])) >= 10, preset.name  # many reversals


def test_plateaus_reach_their_speeds_and_start_below_the_stribeck_velocity(preset_run):
    preset, scale, cfg, prog, events, v = preset_run
    p = cfg["plateaus"]
    assert p["v_max"] < cfg["limits"]["max_velocity"]
    if math.isfinite(scale.stribeck_velocity):
        assert p["v_min"] < scale.stribeck_velocity
    assert p["v_min"] * p["hold"] >= 19.9 * scale.resolution  # the encoder resolves the lowest plateau
    starts = {e.segment: e.time for e in events if e.program == "plateaus" and e.event == 0}
    ends = {e.segment: e.time for e in events if e.program == "plateaus" and e.event == END}
    fastest = max(starts, key=lambda s: abs(float(s.replace("plateau", ""))))
    target = float(fastest.replace("plateau", ""))
    i0 = int((starts[fastest] + p["settle"]) / scale.period)
    i1 = int(ends[fastest] / scale.period)
    # within 20 %; a joint with gear backlash on a compliant coupling (seed000) rings under the
    # velocity loop and its fastest plateau reads about 25 % low (measured), so 30 % there
    tol = 0.3 if preset.params.backlash > 0 else 0.2
    assert abs(np.mean(v[i0:i1]) - target) < tol * abs(target), (preset.name, np.mean(v[i0:i1]), target)


def test_tracking_gains_are_stable_without_friction_and_track_with_it(preset_run):
    preset = preset_run[0]
    scale = preset_run[1]
    gains = tracking_gains(scale)
    ref = tracking_reference(scale, 4.0)
    assert 0 < ref["amplitude"] <= 0.2 * scale.travel
    ctrl = {"mode": "pid", "pid": gains, "load_feedforward": -scale.load}
    free = run_closed_loop(
        make_plant(preset.name, friction_motor={"model": "none"}, friction_load={"model": "none"}),
        ctrl,
        ref,
        4.0,
    )
    e = free.reference[:, 0] - free.true_position
    ref_rms = float(np.std(free.reference[:, 0]))
    # stable and tracking: no growth, error well below the motion it tracks
    assert np.sqrt(np.mean(e[-1000:] ** 2)) < 2.0 * np.sqrt(np.mean(e[:1000] ** 2)) + 1e-9
    assert np.sqrt(np.mean(e**2)) < 0.5 * ref_rms, preset.name
    with_friction = run_closed_loop(preset.name, ctrl, ref, 4.0)
    assert np.all(np.isfinite(with_friction.true_position))


def test_the_tuning_rule_meets_its_phase_margin():
    # pure inertia 1/(J s^2), lag tau, delay T: the phase at w_c is -180 + atan(4) - atan(w tau) - w T
    for lag, delay in ((0.0005, 0.0015), (0.005, 0.0045), (0.0, 0.0105)):
        wc = crossover(lag, delay, 45.0)
        pm = 180 + math.degrees(math.atan(4.0) - math.atan(wc * lag) - wc * delay) - 180
        assert pm == pytest.approx(45.0, abs=0.01)
    s = JointScale(0.95, 0.0012, 5.0, 100.0, 10.0, 1e-4, current_lag=0.0013)
    g = tracking_gains(s)
    wc = 4.0 * g["p"] / g["d"]
    lag_gain = 1 / math.hypot(1, wc * s.current_lag)
    loop = g["d"] * wc * math.sqrt(1 + 1 / 16) * lag_gain / (s.inertia * wc**2)
    assert loop == pytest.approx(1.0, rel=1e-6)  # |L(j w_c)| = 1


def test_a_user_written_preset_is_sized_too(tmp_path):
    doc = yaml.safe_load(yaml.safe_dump(load_preset("abb_m19s").to_config()))
    sec = doc["plant_simulator"]["ros__parameters"]
    sec["preset"] = "my_joint"
    sec["plant"]["motor_inertia"] = 0.02  # 16x the inertia
    sec["plant"]["encoder_cpr"] = 4096
    sec["plant"]["gear_ratio"] = 50.0
    sec["friction_motor"] = {"model": "stribeck", "fc": 0.02, "fs": 0.03, "vs": 1.0, "delta": 2.0, "fv": 1e-4}
    preset = preset_from_config(doc, "user")
    scale, cfg, prog, events, v = run_program(preset)
    assert not prog.aborted, [e.note for e in events if e.event == ABORT]
    assert scale.breakaway == pytest.approx(50.0 * 0.03, rel=0.05)  # reflected through the gear
    assert cfg["plateaus"]["v_min"] < scale.stribeck_velocity
    assert {int(np.sign(e.target)) for e in events if e.event == END and e.program == "breakaway"} == {1, -1}


def test_a_probe_scale_is_validated():
    with pytest.raises(ParameterError, match="inertia"):
        JointScale.from_probe(0.5, -1.0, 5.0, 10.0, 3.0, 1e-4)
    with pytest.raises(ParameterError, match="torque_limit"):
        JointScale.from_probe(0.5, 0.01, 0.4, 10.0, 3.0, 1e-4)
    s = JointScale.from_probe(0.5, 0.01, 5.0, 10.0, 3.0, 1e-4)
    cfg = experiment_config(replace(s, load=-1.0))
    assert cfg["bias"] == pytest.approx(1.0)  # open-loop torques centred on the holding torque
    make_program(cfg)
