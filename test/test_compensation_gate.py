"""Compensation safety gate, feedback stability bound and the run-time limit-cycle detector (pure core)."""

from __future__ import annotations

import time

import numpy as np
import pytest

from friction_ros.core.control.compensation_gate import gate_modes, perturbations
from friction_ros.core.control.controller import CompensatingController
from friction_ros.core.harness import run_closed_loop
from friction_ros.core.identification.export import compensation_section, parameter_document
from friction_ros.core.joint_sizing import JointScale, tracking_gains, tracking_reference
from friction_ros.core.presets import load_preset
from friction_ros.core.validation import ParameterError

# the known bad case of issue 14: a fitted LuGre with sigma1 = 0.9 N*m*s/rad (6x the PD's Kd)
BAD_LUGRE = {
    "model": "lugre",
    "sigma0": 1e5,
    "sigma1": 0.9,
    "fv": 0.0,
    "fc": 0.8,
    "fs": 0.95,
    "vs": 0.05,
    "delta": 2.0,
}
SEED003_PD = {"p": 200.0, "d": 0.15}
REF = {"type": "band_limited_random", "amplitude": 0.05, "cutoff": 1.0, "duration": 10.0, "seed": 1}


@pytest.fixture(scope="module")
def abb():
    preset = load_preset("abb_m19s")
    assert preset.params.current_time_constant == pytest.approx(0.0005)  # the 0.5 ms preset
    return preset, JointScale.from_preset(preset)


def _gate(model, gains, scale, **kw):
    return gate_modes(
        model,
        scale.inertia,
        gains=gains,
        reference=tracking_reference(scale, 4.0),
        current_lag=0.0005,
        resolution=scale.resolution,
        velocity_filter_hz=200.0,
        **kw,
    )


def test_the_known_bad_case_is_refused_with_a_reason(abb):
    _, scale = abb
    t0 = time.perf_counter()
    v = _gate(BAD_LUGRE, SEED003_PD, scale)
    seconds = time.perf_counter() - t0
    assert not v["feedback"].enabled
    assert v["feedback"].reason.startswith("refused: ")
    assert any(w in v["feedback"].reason for w in ("limit cycle", "worse than no compensation", "unstable"))
    assert seconds < 10.0  # measured ~1.3 s for 3 modes x 5 cases on the development VM


def test_a_good_model_is_enabled_and_the_file_carries_the_verdicts(abb):
    preset, scale = abb
    truth = preset.friction.to_config()
    v = _gate(truth, tracking_gains(scale), scale)
    assert all(x.enabled for x in v.values()), {m: x.reason for m, x in v.items()}
    for x in v.values():
        assert x.worst_ratio < 0.9 and len(x.cases) == 5  # nominal + forces +-20 % + presliding +-20 %
    bad = _gate(BAD_LUGRE, tracking_gains(scale), scale)
    sec = compensation_section(bad)
    refused = [m for m, x in bad.items() if not x.enabled]
    assert refused and sec.get("refused") == refused
    assert sec["source"] in ("none", *[m for m, x in bad.items() if x.enabled])
    doc = parameter_document(BAD_LUGRE, 0.0012, gate=bad, gains=tracking_gains(scale))
    comp = doc["compensating_controller"]["ros__parameters"]["compensation"]
    cfg = {"friction": {"model": BAD_LUGRE, **{k: v for k, v in comp.items() if k != "source"}}}
    with pytest.raises(ParameterError, match="refused by the safety gate"):
        CompensatingController({**cfg, "friction": {**cfg["friction"], "source": refused[0]}})
    ok = CompensatingController(
        {**cfg, "friction": {**cfg["friction"], "source": refused[0], "allow_refused": True}}
    )
    assert ok.friction.source == refused[0]


def test_perturbation_cases_scale_forces_and_presliding_separately():
    cases = dict(perturbations(BAD_LUGRE))
    assert cases["forces x0.8"]["fc"] == pytest.approx(0.64) and cases["forces x0.8"]["vs"] == 0.05
    assert cases["presliding x1.2"]["sigma1"] == pytest.approx(1.08) and cases["presliding x1.2"]["fc"] == 0.8


def _run(model, source, gains, ref=REF, duration=6.0, detect=True):
    cfg = {"mode": "pid", "pid": gains, "inertia": 0.0012, "limit_cycle_detection": detect}
    if source != "none":
        cfg["friction"] = {"model": model, "source": source}
    ctrl = CompensatingController(cfg)
    res = run_closed_loop("abb_m19s", ctrl, ref, duration, record_terms=True)
    return res, ctrl


def test_the_run_time_detector_catches_the_bad_case_within_0_1_s():
    base, _ = _run(None, "none", SEED003_PD)
    bad, _ = _run(BAD_LUGRE, "feedback", SEED003_PD, detect=False)
    assert bad.metrics["rms_error"] > 5 * base.metrics["rms_error"]  # the 9x-worse limit cycle
    e = bad.reference[:, 0] - bad.true_position
    # onset: the first time the error oscillation exceeds 4 encoder counts at high frequency
    hp = e - np.convolve(e, np.ones(20) / 20, mode="same")
    onset = float(bad.t[np.nonzero(np.abs(hp) > 4 * 1.047e-4)[0][0]])
    caught, ctrl = _run(BAD_LUGRE, "feedback", SEED003_PD)
    assert ctrl.compensation_fallback and "limit cycle" in ctrl.fallback_reason
    assert ctrl.limit_cycle.fired_at - onset < 0.1, (onset, ctrl.limit_cycle.fired_at)
    fric = caught.terms["friction_feedback"]
    k = int(round(ctrl.limit_cycle.fired_at / 1e-3))
    assert np.all(fric[k + 2 :] == 0.0)  # compensation off, latched
    assert caught.metrics["rms_error"] < 1.5 * base.metrics["rms_error"]


@pytest.mark.parametrize(
    "ref",
    [
        REF,
        {"type": "band_limited_random", "amplitude": 0.05, "cutoff": 1.0, "duration": 10.0, "seed": 7},
        {"type": "sinusoid", "amplitude": 0.05, "frequency": 2.0},
        {"type": "step", "amplitude": 0.05, "start_time": 0.5},
    ],
)
def test_the_detector_does_not_fire_on_normal_tracking(abb, ref):
    preset, scale = abb
    gains = tracking_gains(scale)
    for source in ("none", "feedforward", "feedback", "blended"):
        _, ctrl = _run(preset.friction.to_config(), source, gains, ref)
        assert not ctrl.compensation_fallback, (source, ref, ctrl.fallback_reason)


def test_the_feedback_micro_damping_is_bounded_by_the_loop_damping():
    ctrl = CompensatingController(
        {"mode": "pid", "pid": {"p": 5.0, "d": 0.2}, "friction": {"model": BAD_LUGRE, "source": "feedback"}}
    )
    assert "limited" in ctrl.feedback_bound_note
    assert ctrl.friction._fb_model.to_config()["sigma1"] == pytest.approx(0.1)  # Kd / 2
    assert ctrl.friction._ff_model.to_config()["sigma1"] == pytest.approx(0.9)  # feedforward untouched
    ff = CompensatingController(
        {
            "mode": "pid",
            "pid": {"p": 5.0, "d": 0.2},
            "friction": {"model": BAD_LUGRE, "source": "feedforward"},
        }
    )
    assert ff.feedback_bound_note == ""
