"""Run-time limit-cycle detector: catches compensation-induced oscillations, never normal tracking."""

from __future__ import annotations

import math

import numpy as np
import pytest

from friction_ros.core.control.compensation import FrictionCompensator
from friction_ros.core.control.controller import CompensatingController
from friction_ros.core.control.limit_cycle import LimitCycleDetector
from friction_ros.core.experiment.joint_scale import JointScale
from friction_ros.core.experiment.tracking_design import tracking_gains
from friction_ros.core.harness import run_closed_loop
from friction_ros.core.presets import load_preset
from friction_ros.core.validation import ParameterError

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
BAD_STRIBECK = {"model": "stribeck", "fc": 0.8, "fs": 0.95, "vs": 0.05, "delta": 2.0}
ABB_M19S_PD_GAINS = {"p": 200.0, "d": 0.15}
REF = {"type": "band_limited_random", "amplitude": 0.05, "cutoff": 1.0, "duration": 10.0, "seed": 1}
COUNT = 2.0 * math.pi / 60000.0  # abb_m19s: 20000 cpr at the motor x encoder_ratio 3


@pytest.fixture
def unbounded(monkeypatch):
    """The controller as it was before the feedback-path bound (the bound is a no-op)."""
    monkeypatch.setattr(FrictionCompensator, "_apply_bound", lambda self, kp, kd: "")


def _run(model, source, gains=ABB_M19S_PD_GAINS, ref=REF, duration=10.0, detect=True):
    cfg = {"mode": "pid", "pid": gains, "inertia": 0.0012, "limit_cycle_detection": detect}
    if source != "none":
        cfg["friction"] = {"model": model, "source": source}
    ctrl = CompensatingController(cfg)
    res = run_closed_loop("abb_m19s", ctrl, ref, duration, record_terms=True)
    return res, ctrl


def _onset(res) -> float:
    """First time the error's fast part (minus a 20 ms moving average) exceeds 4 encoder counts:
    the oscillation is then established at the detector's amplitude threshold."""
    e = res.reference[:, 0] - res.true_position
    hp = e - np.convolve(e, np.ones(20) / 20, mode="same")
    return float(res.t[np.nonzero(np.abs(hp) > 4 * COUNT)[0][0]])


@pytest.mark.parametrize("case", ["unbounded LuGre", "static Stribeck"])
def test_the_detector_catches_the_bad_case_within_0_1_s(case, request):
    if case == "unbounded LuGre":
        request.getfixturevalue("unbounded")
        model = BAD_LUGRE
    else:
        model = BAD_STRIBECK
    base, _ = _run(None, "none")
    bad, _ = _run(model, "feedback", detect=False)
    assert bad.metrics["rms_error"] > 5 * base.metrics["rms_error"]  # the ~9x-worse limit cycle
    onset = _onset(bad)
    caught, ctrl = _run(model, "feedback")
    assert ctrl.compensation_fallback and "limit cycle" in ctrl.fallback_reason
    assert ctrl.terms.compensation_fallback
    latency = ctrl.limit_cycle.fired_at - onset
    assert 0.0 < latency < 0.1, (onset, ctrl.limit_cycle.fired_at)
    k = int(round(ctrl.limit_cycle.fired_at / 1e-3))
    assert np.all(caught.terms["friction_feedback"][k + 2 :] == 0.0)  # off and latched
    assert caught.metrics["rms_error"] < 1.2 * base.metrics["rms_error"]


@pytest.mark.parametrize(
    "ref",
    [
        REF,
        {"type": "band_limited_random", "amplitude": 0.05, "cutoff": 1.0, "duration": 10.0, "seed": 7},
        {"type": "sinusoid", "amplitude": 0.05, "frequency": 2.0},
        {"type": "sinusoid", "amplitude": 0.01, "frequency": 5.0},
        {"type": "step", "amplitude": 0.05, "start_time": 0.5},
    ],
    ids=["random1", "random7", "sine2Hz", "sine5Hz", "step"],
)
def test_the_detector_does_not_fire_on_normal_tracking(ref):
    preset = load_preset("abb_m19s")
    truth = preset.friction.to_config()
    tuned = tracking_gains(JointScale.from_preset(preset))
    cases = [
        (g, truth, s)
        for g in (tuned, ABB_M19S_PD_GAINS)
        for s in ("none", "feedforward", "feedback", "blended")
    ]
    cases += [
        (ABB_M19S_PD_GAINS, BAD_LUGRE, s) for s in ("feedforward", "feedback", "blended", "observer")
    ]  # bounded
    for gains, model, source in cases:
        if (
            ref["type"] == "step"
            and gains is ABB_M19S_PD_GAINS
            and source in ("feedback", "blended", "observer")
        ):
            # documented limit: the ABB M19-S paper PD has damping ratio Kd / (2 sqrt(Kp J)) = 0.15 here;
            # feedback compensation removes the friction that damped its step response, which then
            # rings at +-35 mrad, ~50 Hz, for ~0.15 s: the detector takes that for a limit cycle
            continue
        _, ctrl = _run(model, source, gains, ref, duration=6.0)
        assert not ctrl.compensation_fallback, (gains, source, ref, ctrl.fallback_reason)


def test_the_detector_fires_on_an_oscillating_loop_but_only_watches_a_feedback_path():
    """The ABB M19-S paper PD on this plant limit-cycles by itself (~100 Hz, no compensation): the detector
    sees it, but the controller does not watch without compensation or with feed-forward only
    (a function of the reference cannot make the loop oscillate)."""
    res, ctrl = _run(None, "none", ref={**REF, "seed": 7}, duration=3.0)
    det = LimitCycleDetector()
    e = res.reference[:, 0] - res.position
    fired = any(
        det.update(
            res.t[k], e[k], res.command[k], res.reference[k, 1], res.position[k], 1e-3, res.reference[k, 0]
        )
        for k in range(e.size)
    )
    assert fired and det.frequency > 50.0
    assert not ctrl.compensation_fallback
    _, ff = _run(BAD_STRIBECK, "feedforward", ref={**REF, "seed": 7}, duration=3.0)
    assert not ff.compensation_fallback


def test_a_small_oscillation_below_the_thresholds_never_fires():
    """20 s of a 3 Hz, 1 mrad error with a 0.5 N*m command through the abb_m19s encoder: below the
    detector's thresholds, so it never fires (its CPU per sample, 1.3 us, is bench/limit_cycle.py's)."""
    det = LimitCycleDetector()
    n = 20000
    t = np.arange(n) * 1e-3
    e = 1e-3 * np.sin(2 * np.pi * 3.0 * t)
    u = 0.5 * np.sin(2 * np.pi * 3.0 * t + 0.3)
    v = 0.02 * np.cos(2 * np.pi * 3.0 * t)
    p = np.round(np.sin(2 * np.pi * 3.0 * t) / COUNT) * COUNT
    for k in range(n):
        det.update(float(t[k]), float(e[k]), float(u[k]), float(v[k]), float(p[k]), 1e-3)
        assert not det.fired, k


def test_detector_parameters_are_validated_and_reconfiguring_clears_the_latch(unbounded):
    with pytest.raises(ParameterError, match="limit_cycle_window"):
        CompensatingController({"limit_cycle_window": 0.08, "limit_cycle_hold": 0.05})
    with pytest.raises(ParameterError, match="limit_cycle_detection"):
        CompensatingController({"limit_cycle_detection": "yes"})
    assert CompensatingController({"limit_cycle_detection": False}).limit_cycle is None
    _, ctrl = _run(BAD_LUGRE, "feedback", duration=3.0)
    assert ctrl.compensation_fallback
    ctrl.reconfigure({"pid": {"p": 150.0}})
    assert not ctrl.compensation_fallback and not ctrl.limit_cycle.fired


@pytest.mark.ros
def test_the_node_reports_the_fallback_as_diagnostic_error_and_one_log_line(tmp_path):
    from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
    from friction_msgs.msg import ControllerState
    from ros_graph import Graph, Listener, stamp_s, write_params

    from friction_ros.cli.bringup import NodeSpec

    params = write_params(
        tmp_path / "ctrl.yaml",
        {
            "compensating_controller": {
                "ros__parameters": {
                    "mode": "pid",
                    "effort_limit": 4.9,
                    "pid": ABB_M19S_PD_GAINS,
                    "inertia": 0.0012,
                    "compensation": {"source": "feedback"},
                    "friction": BAD_STRIBECK,
                    "reference": REF,
                    "diagnostics_period": 0.2,
                }
            }
        },
    )
    specs = [
        NodeSpec("plant_simulator", "", [], {"preset": "abb_m19s", "mode": "lockstep"}),
        NodeSpec("compensating_controller", "", [params], {"use_sim_time": True}),
    ]

    def errors():
        return [
            s
            for m in diags
            for s in m.status
            if s.level == DiagnosticStatus.ERROR and "limit cycle" in s.message
        ]

    with Listener() as lis:
        states = lis.subscribe(ControllerState, "controller_state")
        diags = lis.subscribe(DiagnosticArray, "diagnostics")
        with Graph(specs) as g:
            assert lis.wait_for(lambda: errors() and states and stamp_s(states[-1]) > 4.0, 120, g), (
                f"no ERROR diagnostic; log:\n{g.output('compensating_controller')}"
            )
            log = g.output("compensating_controller")
    lines = [ln for ln in log.splitlines() if "compensation-induced limit cycle" in ln]
    assert len(lines) == 1, log
    assert "friction compensation switched off" in lines[0]
    values = {kv.key: kv.value for kv in errors()[-1].values}
    assert values["compensation_fallback"] == "1"
    late = [m for m in states if stamp_s(m) > stamp_s(states[-1]) - 1.0]
    assert late and all(m.friction_feedback == 0.0 for m in late)
