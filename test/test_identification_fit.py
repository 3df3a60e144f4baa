"""Parameter recovery on simulator bags with known truth (encoder quantisation + current noise),
the ABB M19-S paper Table 1 ordering, outputs (JSON / YAML) and the fit -> controller round trip."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
import yaml

from friction_ros.core.identification import fit_bag, fit_records, prepare
from friction_ros.core.identification.data.plateau_detection import find_plateaus
from friction_ros.core.synthetic import plant_runs

NOISY = {"current_noise_std": 0.005}  # 2.5 mN*m torque noise on top of the 1.05e-4 rad encoder


@pytest.fixture(scope="module")
def gms_fit(tmp_path_factory):
    """ABB M19-S paper excitation on the ABB M19-S preset (GMS-4 truth): 10 s train + 6 s validation.

    Envelope high level 5 rad/s (peaks ~12 rad/s; the paper gives no amplitude): the identification
    must cover the velocities of the round-trip benchmark (its large stroke reaches 10-15 rad/s).
    With the default 1 rad/s (peaks 2.6 rad/s) the viscous coefficient was extrapolated ~6x and
    alone cost the large-stroke round trip a factor 2-4."""
    d = tmp_path_factory.mktemp("gms")
    rec = plant_runs.abb_m19s_excitation_experiment(16.0, low=0.05, high=5.0, overrides=NOISY)
    bag = plant_runs.write_bag(d / "bag", rec)
    res = fit_bag(
        bag,
        "/joint_states",
        "joint1",
        ["coulomb", "stribeck", "lugre", "gms4", "gms10"],
        d / "out",
        maxiter={"gms10": 5},
        plant_preset="abb_m19s",
        train_window="first",  # ABB M19-S paper's protocol: the first 10 s train, the rest validates
    )
    return rec, res, d / "out"


def test_gms4_nmse_at_or_below_table1(gms_fit):
    _, res, _ = gms_fit
    m = res.models["gms4"].metrics
    assert m["nmse_high_percent"] <= 0.40, m
    assert m["nmse_low_percent"] <= 1.39, m
    c = res.models["gms4"].coefficients
    assert abs(c["J"] / 0.0012 - 1) < 0.10  # ABB M19-S paper: identified J within 10 %


def test_abb_m19s_ordering_low_velocity(gms_fit):
    _, res, _ = gms_fit
    low = {n: r.metrics["nmse_low_percent"] for n, r in res.models.items()}
    assert low["coulomb"] > low["stribeck"] > low["lugre"] > low["gms4"], low
    # GMS-10 no better than GMS-4 by more than a small margin (paper: 1.39 -> 1.19 %)
    assert low["gms10"] >= 0.8 * low["gms4"] - 0.05, low
    assert res.recommended == "gms4"  # fewer parameters for (almost) the same fit


def test_outputs_json_yaml_report(gms_fit):
    rec, res, out = gms_fit
    js = json.loads((out / "summary.json").read_text())
    assert js["recommended"] == "gms4"
    for m in js["models"].values():
        ss = m["steady_state"]
        v = np.array(ss["velocity"])
        assert (v > 0).any() and (v < 0).any() and len(v) == len(ss["friction"])
        assert m["metrics"]["nmse_low_percent"] is not None and m["coefficients"]["J"] >= 0
    vmax = np.abs(rec.velocity).max()
    assert np.abs(js["models"]["gms4"]["steady_state"]["velocity"]).max() >= 0.9 * vmax
    doc = yaml.safe_load((out / "friction_params.yaml").read_text())
    assert set(doc) == {"compensating_controller", "friction_estimator", "plant_simulator"}
    from friction_ros.core.control.controller import CompensatingController
    from friction_ros.core.control.controller_config import config_from_ros_parameters
    from friction_ros.core.estimation.estimator import OnlineFrictionEstimator
    from friction_ros.core.friction import model_from_config
    from friction_ros.core.presets import preset_from_config

    cfg = doc["compensating_controller"]["ros__parameters"]["friction"]
    assert model_from_config(cfg).name == "gms"
    ctrl_cfg, _ = config_from_ros_parameters(doc["compensating_controller"]["ros__parameters"])
    assert CompensatingController(ctrl_cfg).friction.model.name == "gms"
    est = doc["friction_estimator"]["ros__parameters"]
    assert est.pop("joint_type") == "revolute"  # the node's; the rest is the estimator's config
    OnlineFrictionEstimator(est)
    pre = preset_from_config({"plant_simulator": doc["plant_simulator"]})
    assert pre.params.friction_motor.name == "gms"
    text = (out / "report.md").read_text()
    assert "Recommended model: gms4" in text and "Table 1" in text
    for png in ("friction_velocity", "presliding", "validation", "residuals"):
        assert (out / "plots" / f"{png}.png").stat().st_size > 5000


REFERENCE_SEEDS = (1, 2, 3, 4, 5)


def _round_trip(out):
    """ABB M19-S paper Table 2/3 analogue (PD Kp = 200, Kd = 0.15, 1 kHz, ABB M19-S, GMS-4 truth): RMS
    tracking error of 4 s band-limited random references (small and large stroke) with the true,
    the fitted (from the parameter file) and no friction feed-forward, per reference seed."""
    from friction_ros.core.harness import run_closed_loop
    from friction_ros.core.presets import make_plant

    doc = yaml.safe_load((out / "friction_params.yaml").read_text())
    from friction_ros.core.control.controller_config import config_from_ros_parameters

    fitted, _ = config_from_ros_parameters(doc["compensating_controller"]["ros__parameters"])
    truth = make_plant("abb_m19s").params.friction_motor.to_config()
    pd = {"p": 200.0, "d": 0.15}
    results = {}
    for amp, dur in ((0.005, 4.0), (math.pi, 4.0)):
        per_seed = {}
        for seed in REFERENCE_SEEDS:
            ref = {"type": "band_limited_random", "amplitude": amp, "duration": dur, "seed": seed}
            rms = {}
            for label, ctrl in (
                ("truth", {"mode": "pid", "pid": pd, "inertia": 0.0012, "friction": {"model": truth}}),
                ("fitted", {"mode": "pid", "pid": pd, **fitted}),
                ("none", {"mode": "pid", "pid": pd, "inertia": 0.0012}),
            ):
                plant = make_plant("abb_m19s", current_time_constant=1e-4)
                rms[label] = run_closed_loop(plant, ctrl, ref, dur).metrics["rms_error"]
            per_seed[seed] = rms
        mean = {k: float(np.mean([r[k] for r in per_seed.values()])) for k in ("truth", "fitted", "none")}
        results[amp] = {"seed1": per_seed[1], "mean": mean, "per_seed": per_seed}
    return results


@pytest.fixture(scope="module")
def round_trip(gms_fit):
    return _round_trip(gms_fit[2])


def test_round_trip_parameter_file_drives_the_controller(round_trip):
    """fit -> parameter file -> controller loads it -> ABB M19-S paper Table 2/3 analogue: the fitted
    feed-forward clearly beats no compensation at low and high stroke."""
    low, high = round_trip[0.005]["mean"], round_trip[math.pi]["mean"]
    assert low["truth"] < low["none"] and high["truth"] < high["none"]
    assert low["fitted"] < 0.7 * low["none"], low
    assert high["fitted"] < 0.1 * high["none"], high


def _round_trip_benchmark_length(
    out, truth: dict | None = None, seed: int = 1, duration: float = 40.0, none: bool = False
) -> dict:
    """As :func:`_round_trip` on one reference of the benchmark's length (bench/compensation.py
    Tables 2/3: 40 s, seed 1) instead of five 4 s ones: RMS error with the true (J = 0.0012,
    ``truth``) and the fitted (parameter file) feed-forward, on the plant with friction ``truth``
    (default: the preset's) and a 0.1 ms current loop; ``none``: also without friction feed-forward."""
    from friction_ros.core.control.controller_config import config_from_ros_parameters
    from friction_ros.core.harness import run_closed_loop
    from friction_ros.core.presets import make_plant

    doc = yaml.safe_load((out / "friction_params.yaml").read_text())
    fitted, _ = config_from_ros_parameters(doc["compensating_controller"]["ros__parameters"])
    if truth is None:
        truth = make_plant("abb_m19s").params.friction_motor.to_config()
    pd = {"p": 200.0, "d": 0.15}
    results = {}
    for amp in (0.005, math.pi):
        ref = {"type": "band_limited_random", "amplitude": amp, "duration": duration, "seed": seed}
        rms = {}
        ctrls = {
            "truth": {"mode": "pid", "pid": pd, "inertia": 0.0012, "friction": {"model": truth}},
            "fitted": {"mode": "pid", "pid": pd, **fitted},
        }
        if none:
            ctrls["none"] = {"mode": "pid", "pid": pd, "inertia": 0.0012}
        for label, ctrl in ctrls.items():
            plant = make_plant("abb_m19s", friction_motor=truth, current_time_constant=1e-4)
            rms[label] = run_closed_loop(plant, ctrl, ref, duration).metrics["rms_error"]
        results[amp] = rms
    return results


def test_round_trip_within_10_percent_of_truth(gms_fit):
    """Issue 8 goal: the fitted feed-forward's RMS error within 10 % of the true-coefficient one on
    one reference of the benchmark's length (40 s, seed 1), at both strokes. (A single 4 s reference
    is too short: at small stroke its ratio is chaotic, 0.78-1.27 over seeds; see below.)"""
    for amp, rms in _round_trip_benchmark_length(gms_fit[2]).items():
        assert abs(rms["fitted"] / rms["truth"] - 1) <= 0.10, (amp, rms)


def test_round_trip_within_10_percent_of_truth_over_references(round_trip):
    """The same on the mean RMS over five reference seeds. At small stroke one 4 s reference is
    ill-conditioned: the joint stick-slips inside the presliding zone and 1 % random coefficient
    errors move its RMS ratio anywhere in 0.9-1.5 (seed 1) or 0.5-1.0 (seed 3); the mean over five
    references varies by < 7 % for the same errors, so it measures the fit, not the luck."""
    for amp, r in round_trip.items():
        rms = r["mean"]
        assert abs(rms["fitted"] / rms["truth"] - 1) <= 0.10, (amp, rms, r["per_seed"])


def _benchmark_damped_truth() -> dict:
    """The ABB M19-S paper truth of the compensation benchmark (bench/compensation.py
    ABB_M19S_DAMPED_TRUTH): the preset's GMS-4 with presliding micro-damping sigma1 = 0.86 N*m*s/rad."""
    from friction_ros.core.presets import load_preset

    return dict(load_preset("abb_m19s").friction.to_config(), sigma1=0.86)


def _round_trip_damped(out) -> dict:
    """bench/compensation.py Tables 2/3 exactly: the damped truth plant (ABB_M19S_DAMPED_TRUTH, 0.1 ms
    current loop), PD Kp = 200, Kd = 0.15, 1 kHz, 40 s band-limited random reference seed 1."""
    return _round_trip_benchmark_length(out, _benchmark_damped_truth(), none=True)


@pytest.fixture(scope="module")
def damped_fit(tmp_path_factory):
    """As ``gms_fit`` (16 s, 10 s train) but recorded from the benchmark's damped truth and fitted
    with the damped GMS-4 (``gms4d``); the parameter file carries sigma1."""
    d = tmp_path_factory.mktemp("gms_damped")
    truth = _benchmark_damped_truth()
    rec = plant_runs.abb_m19s_excitation_experiment(16.0, low=0.05, high=5.0, friction=truth, overrides=NOISY)
    bag = plant_runs.write_bag(d / "bag", rec)
    res = fit_bag(
        bag,
        "/joint_states",
        "joint1",
        ["gms4d"],
        d / "out",
        plots=False,
        plant_preset="abb_m19s",
        train_window="first",  # ABB M19-S paper's protocol
    )
    return res, d / "out", _round_trip_damped(d / "out")


def test_damped_gms_fit_recovers_presliding_damping(damped_fit):
    """gms4d on the damped truth: sigma1 (= s sum k) and the presliding stiffness recovered, the
    parameter file carries sigma1 and the controller's GMS loads it."""
    res, out, _ = damped_fit
    c = res.models["gms4d"].coefficients
    truth = _benchmark_damped_truth()
    assert abs(c["sigma1"] / truth["sigma1"] - 1) < 0.20, c  # measured -13 %
    assert abs(sum(c["k"]) / sum(truth["k"]) - 1) < 0.10, c  # measured -3 %
    assert abs(c["J"] / 0.0012 - 1) < 0.05, c
    doc = yaml.safe_load((out / "friction_params.yaml").read_text())
    cfg = doc["compensating_controller"]["ros__parameters"]["friction"]
    assert cfg["sigma1"] == pytest.approx(c["sigma1"])
    from friction_ros.core.control.controller import CompensatingController
    from friction_ros.core.control.controller_config import config_from_ros_parameters

    ctrl_cfg, _ = config_from_ros_parameters(doc["compensating_controller"]["ros__parameters"])
    assert CompensatingController(ctrl_cfg).friction.model["sigma1"] == pytest.approx(c["sigma1"])


def test_round_trip_damped_truth_large_stroke_within_10_percent(damped_fit):
    """Issue 8 round trip against the compensation benchmark's own truth (damped GMS-4, Table 3:
    pi rad stroke): fitted feed-forward RMS within 10 % of the true-coefficient one."""
    rms = damped_fit[2][math.pi]
    assert abs(rms["fitted"] / rms["truth"] - 1) <= 0.10, rms


def test_round_trip_damped_truth_small_stroke(damped_fit):
    """The same at the 0.005 rad stroke (Table 2). The 10 % goal is NOT met there (README, goals):
    with the damped truth the true-coefficient RMS is 0.075 mrad (below one 0.105 mrad encoder
    count), and the RMS is set by the feed-forward's static error over Kp = 200: the truth with fs off
    by +-0.5 % gives ratios 0.88/0.99, by +-1 % 0.75/1.38, with k -5 % 1.6; the truth's Stribeck curve
    with the fitted k and alpha still 1.75. This 10 s training record identifies fc to 0.3 %, sum k to
    3 % and sigma1 to -13 %, but fs only to +10 % (vs, delta traded against it): ratio 3-5 over five
    reference seeds (2.1-3.3 two-stage with a plateau run added, bench/fitting.py), 0.67 even when
    fitted with the true (noise-free) velocity (fs -2 %). What holds, and is asserted: the fitted
    feed-forward removes most of the error (true-coefficient: -95 %), and stays within 5x of the
    truth's RMS."""
    rms = damped_fit[2][0.005]
    assert rms["fitted"] < 0.35 * rms["none"], rms
    assert rms["fitted"] < 5.0 * rms["truth"], rms


def test_static_recovery_on_plateaus():
    """Plateaus on the ABB preset (GMS-4 truth: steady state = Stribeck fc 0.8, fs 0.95, vs 0.05,
    delta 2, fv 0.01), fitted per direction. Experiment: descending speeds (each slow plateau entered
    from steady sliding, not through a break-away) under a PD position loop on the ramp with
    stiffness 150 N*m/rad (stable sliding on the Stribeck slope through the friction lag), see
    ``plant_runs.plateau_experiment``; 24 speeds 0.005-2 rad/s, 1 s each.

    fc, fs, vs, fv within 3 % in both directions, delta within 20 %. At and below ~0.024 rad/s the
    joint still stick-slips on the 1.05e-4 rad encoder: the slowest plateaus fail the velocity
    scatter test, the 0.024 rad/s pair (true velocity reversing, mean torque -10 mN*m, its halves
    -3 and -17 mN*m) fails the steady-torque test of ``find_plateaus``; kept, it pulled vs to +10 %
    and fs to -2 %. In the knee the quantisation-driven velocity jitter of the loop (0.010-0.021
    rad/s RMS true velocity) biases the plateau means by 0.5 F'' sigma^2 (+1.7 / +6.0 / +2.7 mN*m
    at 0.11 / 0.088 / 0.068 rad/s), flattening the knee. Measured (34 plateaus kept, identical with
    numba or FRICTION_ROS_NO_NUMBA=1, any thread count; sensor-noise seeds 0-3): fc 0.0 %, fs +1.1
    to +1.2 %, vs -2.5 to -2.8 %, fv +0.1 to +0.3 %, delta -16.3 to -17.2 % (the report of issue 8
    gave delta -10 %, vs +0.8 %, not reproducible from any commit since the test was added: the
    simulated record is bit-identical from 233f5b3 on). Without encoder quantisation all five come
    out within 0.6 % (see the report of issue 8)."""
    truth = {"fc": 0.8, "fs": 0.95, "vs": 0.05, "delta": 2.0, "fv": 0.01}
    rec = plant_runs.plateau_experiment(np.geomspace(0.005, 2.0, 24), hold=1.0, overrides=NOISY)
    d = prepare(rec.t, rec.position, rec.velocity, rec.effort, events=rec.events)
    pl = find_plateaus(d)
    assert 30 <= len(pl) <= 48 and all(p.source == "events" for p in pl)
    # plateaus kept in the Stribeck knee (0.02-0.1 rad/s), per direction
    for sgn in (1, -1):
        assert sum(0.02 < sgn * p.velocity < 0.1 for p in pl) >= 5
    res = fit_records(d, ["stribeck"], train_seconds=1000.0, identifiability_check=False)
    m = res.models["stribeck"]
    assert m.method == "plateaus" and m.seconds < 1.0
    for direction in ("positive", "negative"):
        c = m.identifiability["per_direction"][direction]
        for k, tol in (("fc", 0.03), ("fs", 0.03), ("vs", 0.03), ("fv", 0.03), ("delta", 0.20)):
            assert abs(c[k] / truth[k] - 1) < tol, (direction, k, c[k], truth[k])


def test_lugre_sigma_recovery_within_15_percent():
    truth = {
        "model": "lugre",
        "sigma0": 300.0,
        "sigma1": 1.2,
        "fv": 0.01,
        "fc": 0.8,
        "fs": 0.95,
        "vs": 0.05,
        "delta": 2.0,
    }
    rec = plant_runs.abb_m19s_excitation_experiment(11.5, low=0.05, friction=truth, overrides=NOISY)
    d = prepare(rec.t, rec.position, rec.velocity, rec.effort)
    res = fit_records(
        d, ["lugre"], identifiability_check=False, train_window="first"
    )  # ABB M19-S paper's protocol
    c = res.models["lugre"].coefficients
    assert abs(c["sigma0"] / truth["sigma0"] - 1) < 0.15, c
    assert abs(c["sigma1"] / truth["sigma1"] - 1) < 0.15, c
    assert res.models["lugre"].seconds < 30.0
