"""Experiments and gains sized to the joint: every preset in params/ and a user-written preset."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest
import yaml

from friction_ros.core.experiment.events import ABORT, END, START
from friction_ros.core.experiment.excitation import make_program
from friction_ros.core.experiment.experiment_sizing import experiment_config
from friction_ros.core.experiment.joint_scale import JointScale
from friction_ros.core.experiment.tracking_design import (
    ENCODER_TORQUE_SHARE,
    crossover,
    tracking_crossover,
    tracking_gains,
    tracking_reference,
)
from friction_ros.core.harness import run_closed_loop
from friction_ros.core.presets import load_preset, make_plant, params_dir, preset_from_config
from friction_ros.core.validation import ParameterError


def plant_presets() -> list[str]:
    """Every YAML in params/ whose top key is ``plant_simulator`` (controller/bringup files skipped)."""
    names = []
    for f in sorted(params_dir().glob("*.yaml")):
        doc = yaml.safe_load(f.read_text())
        if isinstance(doc, dict) and next(iter(doc), None) == "plant_simulator":
            names.append(f.stem)
    return names


PRESETS = plant_presets()


def run_program(preset, profile="quick"):
    """The sized program on the preset's plant at the preset's control period, fed the *measured*
    state as the ROS node is (joint_states -> program -> command * command_scale -> plant)."""
    scale = JointScale.from_preset(preset)
    cfg = experiment_config(scale, profile)
    prog = make_program(cfg)
    plant = preset.make_plant()
    k = plant.command_scale
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


def plateau_means(events, v, period):
    """(target, mean measured velocity over the hold) per plateau; the settle from the START note."""
    start = {
        (e.segment, e.index): e.time + float(e.note.split("settle=")[1].split()[0])
        for e in events
        if e.program == "plateaus" and e.event == START
    }
    end = {(e.segment, e.index): e.time for e in events if e.program == "plateaus" and e.event == END}
    out = []
    for key, t0 in start.items():
        i0, i1 = int(round(t0 / period)), int(round(end[key] / period))
        out.append((float(key[0].replace("plateau", "")), float(np.mean(v[i0:i1]))))
    return out


def check_run(name, scale, cfg, prog, events, v, tol=0.2):
    aborts = [(e.segment, e.note) for e in events if e.event == ABORT]
    assert prog.done and not prog.aborted and not aborts, (name, aborts)
    ends = [e for e in events if e.event == END and e.program == "breakaway"]
    assert {int(np.sign(e.target)) for e in ends} == {1, -1}, name  # breakaway found both ways
    assert all(0.5 * scale.breakaway <= abs(e.target) <= 3.0 * scale.breakaway for e in ends), name
    s = np.sign(v[np.abs(v) > 1e-9])
    assert int(np.sum(s[1:] != s[:-1])) >= 20, name  # many reversals
    means = plateau_means(events, v, scale.period)
    assert len(means) == 2 * cfg["plateaus"]["count"] * cfg["plateaus"]["repeats"]
    for target, mean in means:  # every plateau, both directions, reaches its speed
        assert abs(mean - target) < tol * abs(target), (name, target, mean)
    return means


def test_the_plant_presets_are_found():
    assert {"abb_m19s", "seed002_z", "seed004_dc_motor", "seed001_harmonic_drive"} <= set(PRESETS)
    assert not any(n.startswith(("controller_", "bringup_", "fitted_")) for n in PRESETS)


@pytest.fixture(scope="module", params=PRESETS)
def preset_run(request):
    preset = load_preset(request.param)
    return (preset, *run_program(preset))


def test_the_sized_program_completes_and_every_plateau_reaches_its_speed(preset_run):
    preset, scale, cfg, prog, events, v = preset_run
    assert scale.period == preset.control_period  # the program runs at the plant's period
    check_run(preset.name, scale, cfg, prog, events, v)


def test_plateaus_span_the_low_speed_range_and_the_encoder_resolves_them(preset_run):
    preset, scale, cfg, prog, events, v = preset_run
    p = cfg["plateaus"]
    assert p["v_max"] < cfg["limits"]["max_velocity"]
    assert p["v_max"] <= 0.4 * scale.speed_limit
    if math.isfinite(scale.stribeck_velocity):
        assert p["v_min"] < scale.stribeck_velocity  # the lowest plateaus see the Stribeck drop
    hold = max(p["hold"], p["hold_travel"] / p["v_min"])
    assert p["v_min"] * hold >= 9.99 * scale.resolution  # >= 10 counts in the lowest hold
    assert p["v_max"] / p["v_min"] >= 10.0  # at least a decade of speeds
    b = cfg["breakaway"]
    assert b["max"] == pytest.approx(
        min(3.0 * scale.breakaway, cfg["limits"]["max_torque"] - abs(scale.load))
    )
    assert b["resolution"] == scale.resolution
    assert cfg["bias"] == pytest.approx(-scale.load)  # open-loop torques centred on the load


def test_tracking_gains_are_stable_without_friction_and_track_with_it(preset_run):
    preset, scale = preset_run[0], preset_run[1]
    gains = tracking_gains(scale)
    ref = tracking_reference(scale, 6.0)
    assert 0 < ref["amplitude"] <= 0.2 * scale.travel
    assert ref["amplitude"] >= 2.99 * scale.breakaway / gains["p"]  # beyond the PD's dead band
    ctrl = {"mode": "pid", "pid": gains, "load_feedforward": -scale.load}
    free_plant = make_plant(preset.name, friction_motor={"model": "none"}, friction_load={"model": "none"})
    free = run_closed_loop(free_plant, ctrl, ref, 6.0, dt=scale.period)
    e = free.error
    ref_rms = float(np.std(free.reference[:, 0]))
    n = e.size // 3
    rms = [float(np.sqrt(np.mean(x**2))) for x in (e[:n], e[n : 2 * n], e[2 * n :])]
    assert rms[2] < 2.0 * max(rms[0], rms[1]) + scale.resolution, (preset.name, rms)  # no growth
    assert np.sqrt(np.mean(e**2)) < 0.15 * ref_rms, preset.name
    # with 1.5x the gains (3.5 dB) the frictionless loop is still stable: a margin, not an edge
    hot = {"p": 1.5 * gains["p"], "d": 1.5 * gains["d"]}
    e2 = run_closed_loop(free_plant, dict(ctrl, pid=hot), ref, 6.0, dt=scale.period).error
    assert np.sqrt(np.mean(e2**2)) < 0.3 * ref_rms, preset.name
    # with the preset's friction: bounded, the joint moves (error below the motion it tracks)
    fr = run_closed_loop(preset.name, ctrl, ref, 6.0, dt=scale.period)
    assert np.all(np.isfinite(fr.true_position))
    assert np.sqrt(np.mean(fr.error**2)) < 0.7 * ref_rms, preset.name


def test_the_tuning_rule_meets_its_phase_margin():
    # pure inertia 1/(J s^2), lag tau, delay T: the phase at w_c is -180 + atan(4) - atan(w tau) - w T
    for lag, delay in ((0.0005, 0.0015), (0.005, 0.0045), (0.0, 0.0105)):
        for pm in (45.0, 60.0):
            wc = crossover(lag, delay, pm)
            margin = math.degrees(math.atan(4.0) - math.atan(wc * lag) - wc * delay)
            assert margin == pytest.approx(pm, abs=0.01)
    s = JointScale(0.95, 0.0012, 5.0, 100.0, 10.0, 1e-4, current_lag=0.0013)
    g = tracking_gains(s)
    wc = 4.0 * g["p"] / g["d"]
    assert wc == pytest.approx(tracking_crossover(s))
    lag_gain = 1 / math.hypot(1, wc * s.current_lag)
    loop = g["d"] * wc * math.sqrt(1 + 1 / 16) * lag_gain / (s.inertia * wc**2)
    assert loop == pytest.approx(1.0, rel=1e-6)  # |L(j w_c)| = 1
    # more margin asked, lower crossover
    assert tracking_crossover(s, 60.0) < tracking_crossover(s, 45.0)


def test_a_coarse_encoder_bounds_the_derivative_gain():
    fine = JointScale(0.05, 0.0014, 2.4, 10.0, 100.0, 1e-5, current_lag=0.008, velocity_filter=0.008)
    coarse = replace(fine, resolution=2 * math.pi / 20)
    gf, gc = tracking_gains(fine), tracking_gains(coarse)
    assert gf["d"] * fine.count_velocity < ENCODER_TORQUE_SHARE * fine.torque_limit  # not binding
    assert gc["d"] * coarse.count_velocity == pytest.approx(ENCODER_TORQUE_SHARE * coarse.torque_limit)
    assert gc["p"] / gc["d"] == pytest.approx(gf["p"] / gf["d"])  # same zero
    wc = tracking_crossover(coarse)
    assert wc < tracking_crossover(fine)
    gain = gc["d"] * math.hypot(wc, gc["p"] / gc["d"]) / (coarse.inertia * wc * wc)
    assert gain == pytest.approx(1.0, rel=1e-6)  # the lowered crossover is where |L| = 1


def test_slow_plateaus_cover_a_distance():
    cfg = {
        "program": "plateaus",
        "plateaus": {"v_min": 0.01, "v_max": 1.0, "count": 3, "repeats": 1, "settle": 0.2, "hold": 0.5},
    }
    base = make_program(cfg)
    cfg["plateaus"].update(settle_travel=0.01, hold_travel=0.05)
    longer = make_program(cfg)
    # 1.0 and 0.1 rad/s keep 0.2 + 0.5 s; 0.01 rad/s settles 1 s and holds 5 s, both directions
    assert base.total_duration == pytest.approx(6 * 0.7)
    assert longer.total_duration == pytest.approx(4 * 0.7 + 2 * 6.0)
    low = [s for s in longer.segments if abs(s.target) < 0.02]
    assert [s.start_note for s in low] == ["settle=1", "settle=1"]


def test_the_default_profile_on_two_presets():
    for name in ("abb_m19s", "seed002_z"):
        preset = load_preset(name)
        scale, cfg, prog, events, v = run_program(preset, "default")
        assert cfg["plateaus"]["repeats"] == 2 and cfg["breakaway"]["repeats"] == 3
        check_run(name, scale, cfg, prog, events, v)


def test_a_user_written_preset_is_sized_too():
    doc = yaml.safe_load(yaml.safe_dump(load_preset("abb_m19s").to_config()))
    sec = doc["plant_simulator"]["ros__parameters"]
    sec["preset"] = "my_joint"
    sec["control_period"] = 0.002
    sec["plant"]["motor_inertia"] = 0.02  # 16x the inertia
    sec["plant"]["encoder_cpr"] = 4096
    sec["plant"]["gear_ratio"] = 50.0
    sec["friction_motor"] = {"model": "stribeck", "fc": 0.02, "fs": 0.03, "vs": 1.0, "delta": 2.0, "fv": 1e-4}
    preset = preset_from_config(doc, "user")
    scale, cfg, prog, events, v = run_program(preset)
    assert scale.period == 0.002 and cfg["control_period"] == 0.002
    eta = preset.params.gear_efficiency
    assert scale.breakaway == pytest.approx(50.0 * eta * 0.03, rel=0.05)  # reflected through the gear
    assert cfg["plateaus"]["v_min"] < scale.stribeck_velocity
    check_run("my_joint", scale, cfg, prog, events, v)
    gains = tracking_gains(scale)
    free = run_closed_loop(
        make_plant(
            {"plant": sec["plant"], "friction_motor": {"model": "none"}, "friction_load": {"model": "none"}}
        ),
        {"mode": "pid", "pid": gains},
        tracking_reference(scale, 4.0),
        4.0,
        dt=scale.period,
    )
    assert np.sqrt(np.mean(free.error**2)) < 0.15 * np.std(free.reference[:, 0])


def test_a_probe_scale_is_validated_and_sized():
    with pytest.raises(ParameterError, match="inertia"):
        JointScale.from_probe(0.5, -1.0, 5.0, 10.0, 3.0, 1e-4)
    with pytest.raises(ParameterError, match="torque_limit"):
        JointScale.from_probe(0.5, 0.01, 0.4, 10.0, 3.0, 1e-4)
    s = JointScale.from_probe(0.5, 0.01, 5.0, 10.0, 3.0, 1e-4)
    cfg = experiment_config(replace(s, load=-1.0))
    assert cfg["bias"] == pytest.approx(1.0)  # open-loop torques centred on the holding torque
    assert cfg["breakaway"]["start"] == pytest.approx(0.25) and cfg["breakaway"]["max"] == pytest.approx(1.5)
    assert cfg["limits"]["max_travel"] == 3.0 and cfg["limits"]["max_torque"] <= 5.0
    assert cfg["presliding"]["amplitudes"] == pytest.approx([0.2, 0.4])
    make_program(cfg)
    # a linear axis is the same arithmetic in m and N
    lin = JointScale.from_probe(20.0, 30.0, 1000.0, 0.2, 0.3, 1.25e-6)
    cl = experiment_config(lin)
    assert cl["breakaway"]["max"] == pytest.approx(60.0) and cl["plateaus"]["v_max"] <= 0.4 * 0.2 + 1e-12
    make_program(cl)
