"""Compensation safety gate, feedback stability bound and the run-time limit-cycle detector (pure core)."""

from __future__ import annotations

import pytest

from friction_ros.core.compensation_gate import gate_modes, perturbations
from friction_ros.core.control.compensation import FrictionCompensator
from friction_ros.core.control.controller import CompensatingController
from friction_ros.core.experiment.joint_scale import JointScale
from friction_ros.core.experiment.tracking_design import tracking_gains, tracking_reference
from friction_ros.core.harness import run_closed_loop
from friction_ros.core.identification.report.export import compensation_section, parameter_document
from friction_ros.core.presets import load_preset
from friction_ros.core.validation import ParameterError

# the known bad case: a fitted LuGre with sigma1 = 0.9 N*m*s/rad (6x the PD's Kd) and stiff bristles
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
# a static fit of the same levels: nothing to bound, the full Coulomb level switches on the velocity
BAD_STRIBECK = {"model": "stribeck", "fc": 0.8, "fs": 0.95, "vs": 0.05, "delta": 2.0}
ABB_M19S_PD_GAINS = {"p": 200.0, "d": 0.15}
REF = {"type": "band_limited_random", "amplitude": 0.05, "cutoff": 1.0, "duration": 10.0, "seed": 1}


@pytest.fixture(scope="module")
def abb():
    preset = load_preset("abb_m19s")
    assert preset.params.current_time_constant == pytest.approx(0.0005)  # the 0.5 ms preset
    return preset, JointScale.from_preset(preset)


def _gate(model, gains, scale, reference=None, **kw):
    return gate_modes(
        model,
        scale.inertia,
        gains=gains,
        reference=reference or tracking_reference(scale, 4.0),
        current_lag=0.0005,
        resolution=scale.resolution,
        velocity_filter_hz=200.0,
        **kw,
    )


@pytest.fixture
def unbounded(monkeypatch):
    """The controller as it was before the feedback-path bound (the bound is a no-op)."""
    monkeypatch.setattr(FrictionCompensator, "_apply_bound", lambda self, kp, kd: "")


def _summary(v):
    return {m: (x.enabled, round(x.worst_ratio, 3), x.reason) for m, x in v.items()}


def test_the_known_bad_case_is_refused_with_a_reason(abb, unbounded):
    _, scale = abb
    v = _gate(BAD_LUGRE, ABB_M19S_PD_GAINS, scale, reference=REF)
    assert not v["feedback"].enabled, _summary(v)
    assert v["feedback"].reason.startswith("refused: unstable: the error grows without bound")
    assert v["feedback"].reason.endswith("(+4 more cases)")  # every perturbed plant fails too
    assert v["feedforward"].enabled and v["feedforward"].worst_ratio < 0.8, _summary(v)


def test_with_the_bound_the_bad_case_is_stable_and_better_than_none(abb):
    """The stability bound limits sigma1 to Kd/2 and sigma0 to Kp/2 in the feedback path: on the
    real preset (GMS bristles, 0.5 ms lag) LuGre feedback goes from a 9x-worse limit cycle to
    ~2.4x better than no compensation (measured 0.0290 -> 0.00136 rad RMS, none 0.00328)."""
    _, scale = abb
    runs = {}
    for name, model, src in (("none", None, "none"), ("fb", BAD_LUGRE, "feedback")):
        cfg = {"mode": "pid", "pid": ABB_M19S_PD_GAINS, "inertia": 0.0012, "limit_cycle_detection": False}
        if model:
            cfg["friction"] = {"model": model, "source": src}
        ctrl = CompensatingController(cfg)
        runs[name] = run_closed_loop("abb_m19s", ctrl, REF, 10.0).metrics["rms_error"]
    assert "sigma1 0.9 -> 0.075" in ctrl.feedback_bound_note
    assert "presliding stiffness 1e+05 -> 100" in ctrl.feedback_bound_note
    assert runs["none"] == pytest.approx(0.00328, rel=0.05)
    assert runs["fb"] < 0.5 * runs["none"], runs
    v = _gate(BAD_LUGRE, ABB_M19S_PD_GAINS, scale, reference=REF)
    assert v["feedback"].enabled and "limited for loop stability" in v["feedback"].reason, _summary(v)
    assert v["feedback"].worst_ratio < 0.95


def test_the_bound_applies_to_each_direction_of_an_asymmetric_model():
    """An asymmetric (direction-dependent) LuGre in feedback: both directions' presliding terms are
    bounded, the sliding levels of each direction kept."""
    body = {k: v for k, v in BAD_LUGRE.items() if k != "model"}
    asym = {
        "model": "asymmetric",
        "base": "lugre",
        "positive": body,
        "negative": {**body, "fc": 0.8 * body["fc"]},
    }
    cfg = {
        "mode": "pid",
        "pid": ABB_M19S_PD_GAINS,
        "inertia": 0.0012,
        "friction": {"model": asym, "source": "feedback"},
    }
    ctrl = CompensatingController(cfg)
    note = ctrl.feedback_bound_note
    assert "positive sigma1 0.9 -> 0.075" in note and "negative sigma1 0.9 -> 0.075" in note, note
    assert "negative presliding stiffness 1e+05 -> 100" in note, note
    fb = ctrl.friction._fb_model.to_config()
    assert fb["negative"]["fc"] == pytest.approx(0.8 * body["fc"]) and fb["positive"][
        "sigma0"
    ] == pytest.approx(100)


def test_a_static_fit_in_feedback_is_refused(abb):
    """The same Coulomb level as a static model (no presliding term to bound) switched on the
    measured velocity: refused, feed-forward of it enabled only if it is not worse in any case."""
    _, scale = abb
    v = _gate(BAD_STRIBECK, ABB_M19S_PD_GAINS, scale, reference=REF)
    assert not v["feedback"].enabled and v["feedback"].reason.startswith("refused: unstable"), _summary(v)
    assert len(v["feedback"].cases) == 3  # static: nominal + forces +-20 %


def test_a_good_model_is_enabled_and_the_file_carries_the_verdicts(abb):
    preset, scale = abb
    truth = preset.friction.to_config()
    v = _gate(truth, tracking_gains(scale), scale)
    assert all(len(x.cases) == 5 for x in v.values())  # nominal + forces +-20 % + presliding +-20 %
    # the soft tuned loop (Kp ~11 N*m/rad): feed-forward is enabled and helps in every case; the
    # feedback path's stiffness is bounded to Kp/2 (truth 617.5 N*m/rad), which leaves pure feedback
    # without benefit (measured 0.93-1.07 of the uncompensated RMS: refused when above 1.02)
    assert v["feedforward"].enabled and v["feedforward"].worst_ratio < 0.8, _summary(v)
    assert v["feedback"].worst_ratio > 0.9 and "limited for loop stability" in v["feedback"].reason
    assert compensation_section(v)["source"] == "feedforward"
    # the stiffer ABB M19-S paper PD: every mode helps in every case (measured worst 0.58, 0.72, 0.36)
    v = _gate(truth, ABB_M19S_PD_GAINS, scale, reference=REF)
    assert all(x.enabled and x.worst_ratio < 0.8 for x in v.values()), _summary(v)
    assert compensation_section(v)["source"] == "blended" and "refused" not in compensation_section(v)
    bad = _gate(BAD_STRIBECK, ABB_M19S_PD_GAINS, scale, reference=REF)
    sec = compensation_section(bad)
    refused = [m for m, x in bad.items() if not x.enabled]
    assert refused and sec.get("refused") == refused
    assert sec["source"] in ("none", *[m for m, x in bad.items() if x.enabled])
    doc = parameter_document(BAD_STRIBECK, 0.0012, gate=bad, gains=ABB_M19S_PD_GAINS, effort_limit=4.9)
    comp = doc["compensating_controller"]["ros__parameters"]["compensation"]
    cfg = {"friction": {"model": BAD_STRIBECK, **{k: v for k, v in comp.items() if k != "source"}}}
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


def test_the_feedback_path_bound_limits_damping_and_stiffness():
    pd = {"p": 5.0, "d": 0.2}
    ctrl = CompensatingController(
        {"mode": "pid", "pid": pd, "friction": {"model": BAD_LUGRE, "source": "feedback"}}
    )
    fb, ff = ctrl.friction._fb_model.to_config(), ctrl.friction._ff_model.to_config()
    assert fb["sigma1"] == pytest.approx(0.1) and fb["sigma0"] == pytest.approx(2.5)  # Kd/2, Kp/2
    assert fb["fc"] == 0.8 and fb["fs"] == 0.95  # sliding levels unchanged
    assert ff["sigma1"] == 0.9 and ff["sigma0"] == 1e5  # feedforward untouched
    assert "limited" in ctrl.feedback_bound_note and ctrl.config()["friction"]["model"]["sigma0"] == 1e5
    # blended: weight 1 - blend; gain 0.5 -> bound / (0.5 x 0.5)
    bl = CompensatingController(
        {"pid": pd, "friction": {"model": BAD_LUGRE, "source": "blended", "gain": 0.5, "feedback_bound": 0.2}}
    )
    assert bl.friction._fb_model.to_config()["sigma1"] == pytest.approx(0.2 * 0.2 / 0.25)
    # the bound follows the model (estimator hot-swap) and the gains
    ctrl.set_coefficients({"sigma0": 2e5})
    assert ctrl.friction._fb_model.to_config()["sigma0"] == pytest.approx(2.5)
    ctrl.set_pid_gains(p=50.0)
    assert ctrl.friction._fb_model.to_config()["sigma0"] == pytest.approx(25.0)
    # GMS: the element stiffnesses sum to <= Kp / 2, in proportion
    gms = {
        "model": "gms",
        "fc": 0.8,
        "fs": 0.95,
        "vs": 0.05,
        "attraction": 50.0,
        "k": [300.0, 100.0],
        "alpha": [0.5, 0.5],
    }
    g = CompensatingController(
        {"pid": {"p": 200.0, "d": 0.15}, "friction": {"model": gms, "source": "feedback"}}
    )
    assert g.friction._fb_model.to_config()["k"] == pytest.approx([75.0, 25.0])
    # cascade: K = kp_velocity kp_position, D = kp_velocity
    c = CompensatingController({"mode": "cascade", "friction": {"model": BAD_LUGRE, "source": "feedback"}})
    assert (c.loop_stiffness, c.loop_damping) == pytest.approx((18.0, 0.3))
    # nothing to bound: feedforward, static models, a model within the bound
    for f in (
        {"model": BAD_LUGRE, "source": "feedforward"},
        {"model": BAD_STRIBECK, "source": "feedback"},
        {"model": {**BAD_LUGRE, "sigma0": 2.0, "sigma1": 0.05}, "source": "feedback"},
    ):
        assert CompensatingController({"pid": pd, "friction": f}).feedback_bound_note == ""
    with pytest.raises(ParameterError, match="feedback_bound"):
        CompensatingController({"friction": {"model": BAD_LUGRE, "feedback_bound": 1.5}})


@pytest.mark.ros
def test_the_node_refuses_a_refused_source_from_the_fitted_file(tmp_path, abb):
    import subprocess
    import sys

    from friction_ros.core.identification.report.export import dump_yaml

    _, scale = abb
    bad = _gate(BAD_STRIBECK, ABB_M19S_PD_GAINS, scale, reference=REF)
    doc = parameter_document(BAD_STRIBECK, 0.0012, gate=bad, gains=ABB_M19S_PD_GAINS, effort_limit=4.9)
    sec = doc["compensating_controller"]["ros__parameters"]
    assert "feedback" in sec["compensation"]["refused"]

    def start(source, allow):
        sec["compensation"] = {**sec["compensation"], "source": source, "allow_refused": allow}
        path = tmp_path / f"{source}_{allow}.yaml"
        path.write_text(dump_yaml(doc))  # what friction-fit writes
        cmd = [sys.executable, "-m", "friction_ros.nodes.compensating_controller", "--ros-args"]
        try:
            return subprocess.run(
                [*cmd, "--params-file", str(path)], capture_output=True, text=True, timeout=8
            )
        except subprocess.TimeoutExpired as exc:  # started and kept running
            return exc

    out = start("feedback", False)
    assert out.returncode == 2 and "Traceback" not in out.stderr, out.stderr
    lines = [ln for ln in out.stderr.splitlines() if "refused by the safety gate" in ln]
    assert len(lines) == 1 and "allow_refused" in lines[0]
    assert isinstance(start("feedback", True), subprocess.TimeoutExpired)  # explicit override: runs
