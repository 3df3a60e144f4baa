"""Seed schemes (DNPF, describing function, gain scheduling, SMC, relay), compensation, façade."""

import math

import numpy as np
import pytest

from friction_ros.core.control import (
    DNPF,
    CompensatingController,
    FrictionCompensator,
    GainScheduling,
    SlidingMode,
    describing_damping,
    describing_stiffness,
    maxwell_virgin_curve,
    sliding_mode_relay,
)
from friction_ros.core.validation import ParameterError

GMS = dict(
    model="gms",
    fc=0.8,
    fs=0.95,
    vs=0.05,
    delta=2.0,
    attraction=50.0,
    fv=0.01,
    k=[190.0, 190.0, 142.5, 95.0],
    alpha=[0.1, 0.2, 0.3, 0.4],
)


@pytest.mark.parametrize(
    "A, ke, ce",
    [
        (0.0005, 617.50, 0.0),
        (0.001, 522.50, 60.48),
        (0.002, 369.65, 105.84),
        (0.004, 217.10, 117.18),
        (0.01, 69.21, 91.32),
    ],
)
def test_describing_function_regression_abb_m19s_e18(A, ke, ce):
    y = maxwell_virgin_curve([190, 190, 142.5, 95], [0.1, 0.2, 0.3, 0.4], 0.95)
    assert describing_stiffness(y, A) == pytest.approx(ke, abs=0.02)
    assert describing_damping(y, A) == pytest.approx(ce, abs=0.02)


def test_describing_function_linear_spring():
    y = lambda x: 300.0 * np.asarray(x)  # noqa: E731
    assert describing_stiffness(y, 0.01) == pytest.approx(300.0)
    assert describing_damping(y, 0.01) == pytest.approx(0.0, abs=1e-9)


def test_dnpf_law_abb_m19s():
    d = DNPF.from_dict({"q_h": 0.004, "tau_st": 0.95, "epsilon": 0.05, "kd": 0.0})
    assert d.kp == pytest.approx(250.0)  # continuous at |e| = Q_h
    assert d.proportional(0.001) == pytest.approx(1.0)  # constant tau_st + eps inside Q_h
    assert d.proportional(-1e-6) == pytest.approx(-1.0)
    assert d.proportional(0.0) == 0.0
    assert d.proportional(0.01) == pytest.approx(2.5)
    assert d.proportional(0.004) == pytest.approx(1.0)


def test_gain_scheduling_stiffness_schedule_switches_and_raises_gains():
    gs = GainScheduling.from_dict({"model": GMS, "dwell": 0.0, "schedule": "stiffness"})
    ref = (0.4, 0.0, 0.0)
    out = gs.compute(0.01, 0.0, ref, (0.39, 0.5), 1e-3)
    assert gs.mode == 1 and out.friction_feedback == pytest.approx(0.8)
    gs.compute(0.002, 0.0, ref, (0.398, 0.0), 1e-3)  # standstill inside Q_h -> mode 2
    assert gs.mode == 2 and gs.kp2 > gs.kp and gs.adjustments == 1
    kp_first = gs.kp2
    gs.compute(0.002, 0.0, ref, (0.398, 0.2), 1e-3)  # moves
    gs.compute(0.001, 0.0, ref, (0.399, 0.0), 1e-3)  # new standstill -> re-adjusted
    assert gs.kp2 > kp_first and gs.adjustments == 2
    gs.compute(0.01, 0.0, ref, (0.39, 0.0), 1e-3)  # leaves presliding
    assert gs.mode == 1 and gs.kp2 == gs.kp


def test_gain_scheduling_bias_schedule_holds_the_describing_function_torque():
    """bias schedule: u_b += (kp + k_e(A)) e at each standstill, kd2 = kd - c_e(A); reset on leaving."""
    gs = GainScheduling.from_dict({"model": GMS, "dwell": 0.0, "kd": 0.4})
    ref = (0.4, 0.0, 0.0)
    e = 0.001
    out = gs.compute(e, 0.0, ref, (0.4 - e, 0.0), 1e-3)
    ke = describing_stiffness(gs.virgin, e)
    assert gs.mode == 2 and gs.adjustments == 1 and gs.kp2 == gs.kp
    assert 450.0 < ke < sum(GMS["k"])  # the softening virgin curve: k_e(A) < sum k_i
    assert gs.bias == pytest.approx((gs.kp + ke) * e)
    assert 0.0 < gs.kd2 < 0.4  # friction supplies part of the damping
    assert out.p_term == pytest.approx(gs.kp * e + gs.bias)
    b1 = gs.bias
    gs.compute(5e-4, 0.0, ref, (0.3995, 0.05), 1e-3)  # moves: no re-adjustment while moving
    assert gs.bias == b1 and gs.adjustments == 1
    gs.compute(-2e-4, 0.0, ref, (0.4002, 0.0), 1e-3)  # overshoot and stop: bias steps back
    assert gs.adjustments == 2 and gs.bias < b1
    gs.compute(-2e-4, 0.0, (0.4, 0.5, 0.0), (0.4002, 0.0), 1e-3)  # the reference moves -> mode 1
    assert gs.mode == 1 and gs.bias == 0.0
    with pytest.raises(ParameterError, match="schedule.*bias, stiffness"):
        GainScheduling.from_dict({"model": GMS, "schedule": "integral"})


def test_sliding_mode_and_relay():
    s = SlidingMode.from_dict({"lambda": 10.0, "gain": 2.0})
    assert s.compute(0.01, 0.0, (0, 0, 0), (0, 0), 1e-3).friction_feedback == 2.0
    assert s.compute(-0.01, 0.05, (0, 0, 0), (0, 0), 1e-3).friction_feedback == -2.0 + 4.0 * 0  # S = -0.05
    b = SlidingMode.from_dict({"lambda": 10.0, "gain": 2.0, "boundary_layer": 0.2})
    assert b.compute(0.01, 0.0, (0, 0, 0), (0, 0), 1e-3).friction_feedback == pytest.approx(1.0)
    # Chatterjee et al. 2017 A-T7
    assert list(sliding_mode_relay([0.02, 0.01, 0.005, -0.01, -0.05])) == [0.9, 0.9, 1.0, 1.1, 1.1]


def test_compensator_sources_gain_smoothing():
    m = {"model": "coulomb", "fc": 1.0}
    ff = FrictionCompensator({"model": m, "gain": 0.95})
    assert ff.update(0.1, -0.1, 1e-3) == (pytest.approx(0.95), 0.0)
    fb = FrictionCompensator({"model": m, "source": "feedback"})
    assert fb.update(0.1, -0.1, 1e-3) == (0.0, pytest.approx(-1.0))
    bl = FrictionCompensator({"model": m, "source": "blended", "blend": 0.25})
    assert bl.update(0.1, 0.1, 1e-3) == (pytest.approx(0.25), pytest.approx(0.75))
    th = FrictionCompensator({"model": m, "smoothing": "tanh", "smoothing_velocity": 0.01})
    assert th.update(0.01, 0, 1e-3)[0] == pytest.approx(math.tanh(1.0))
    li = FrictionCompensator({"model": m, "smoothing": "linear", "smoothing_velocity": 0.01})
    assert li.update(0.005, 0, 1e-3)[0] == pytest.approx(0.5)
    assert li.update(0.0, 0, 1e-3)[0] == 0.0


def test_dynamic_feedforward_driven_by_reference():
    c = FrictionCompensator({"model": GMS})
    out = [c.update(0.1, 0.0, 1e-3)[0] for _ in range(2000)]
    assert out[-1] == pytest.approx(0.8 + 0.15 * math.exp(-4.0) + 0.001, rel=1e-2)  # s(0.1) + fv v
    assert c.state[:4].sum() == pytest.approx(out[-1] - 0.001, rel=1e-3)  # element forces


def test_lugre_observer_converges_to_steady_state():
    lu = {"model": "lugre", "sigma0": 1e5, "sigma1": 0.0, "fv": 0.0, "fc": 0.5, "fs": 0.7, "vs": 0.05}
    c = FrictionCompensator({"model": lu, "source": "observer", "observer_gain": 0.0})
    for _ in range(1000):
        _, fb = c.update(0.0, 0.2, 1e-3)
    assert fb == pytest.approx(0.5 + 0.2 * math.exp(-16.0), rel=1e-6)


def test_facade_terms_sum_and_limits():
    c = CompensatingController(
        {
            "pid": {"p": 200.0, "d": 0.15},
            "inertia": 0.0012,
            "feedforward_gain": 0.01,
            "friction": {"model": {"model": "coulomb", "fc": 0.8}, "source": "blended"},
            "u_clamp_max": 5.0,
            "u_clamp_min": -5.0,
            "rate_limit": 1000.0,
        }
    )
    cmd = c.update(0.0, (0.001, 0.1, 2.0), (0.0, 0.05), 1e-3)
    t = c.terms
    total = (
        t.p_term
        + t.i_term
        + t.d_term
        + t.velocity_feedforward
        + t.inertia_feedforward
        + t.friction_feedforward
        + t.friction_feedback
    )
    assert t.command_unlimited == pytest.approx(total) and cmd == t.command
    assert t.inertia_feedforward == pytest.approx(0.0024) and t.friction_feedforward == pytest.approx(0.4)
    cmd2 = c.update(1e-3, (1.0, 0.0, 0.0), (0.0, 0.0), 1e-3)  # big step: rate limit 1 N*m per period
    assert cmd2 == pytest.approx(cmd + 1.0) and c.terms.saturated


def test_facade_modes_and_flat_parameters():
    for mode in ("pid", "cascade", "dnpf", "sliding_mode"):
        c = CompensatingController({"mode": mode})
        assert math.isfinite(c.update(0.0, (0.1, 0.0, 0.0), (0.0, 0.0), 1e-3))
    gs = CompensatingController({"mode": "gain_scheduling", "friction": {"model": GMS, "source": "none"}})
    assert gs.scheme.k == GMS["k"]
    c = CompensatingController.from_parameters(
        {"mode": "pid", "pid.p": 3.0, "friction.model.model": "coulomb", "friction.model.fc": 0.2}
    )
    assert c.pid.p == 3.0 and c.friction.model.coefficients["fc"] == 0.2
    c2 = CompensatingController(c.config())
    assert c2.config() == c.config()


def test_set_coefficients_hot_swap_validated():
    c = CompensatingController({"friction": {"model": {"model": "coulomb", "fc": 0.8}}})
    c.set_coefficients({"fc": 0.5})
    assert c.update(0, (0, 1.0, 0), (0, 0), 1e-3) == pytest.approx(0.5)
    with pytest.raises(ParameterError) as ei:
        c.set_coefficients({"fc": -1.0})
    assert "coulomb.fc" in str(ei.value)
    assert c.friction.model.coefficients["fc"] == 0.5
    c.set_coefficients({"model": "viscous", "fv": 2.0})
    assert c.update(0, (0, 1.0, 0), (0, 0), 1e-3) == pytest.approx(2.0)


@pytest.mark.parametrize(
    "cfg, words",
    [
        ({"mode": "mpc"}, ["controller.mode", "gain_scheduling"]),
        ({"pid": {"p": -2.0}}, ["controller.pid.p"]),
        ({"friction": {"gain": 3.0}}, ["controller.friction.gain", "<= 2"]),
        ({"friction": {"source": "magic"}}, ["controller.friction.source"]),
        ({"dnpf": {"q_h": 0.0}, "mode": "dnpf"}, ["dnpf.q_h", "> 0"]),
        ({"velocity_source": "gps"}, ["velocity_source"]),
        ({"kp": 1.0}, ["unknown", "'kp'"]),
        ({"mode": "gain_scheduling"}, ["virgin curve"]),
    ],
)
def test_facade_validation(cfg, words):
    with pytest.raises(ParameterError) as ei:
        CompensatingController(cfg)
    for w in words:
        assert w in str(ei.value)


@pytest.mark.parametrize(
    "values, words, not_words",
    [
        (
            {"compensation": {"gian": 1.0}, "friction": {"model": "coulomb", "fc": 0.1}},
            ["compensation", "'gian'"],
            [],
        ),
        ({"compensation": {"gain": 3.0}}, ["compensation.gain", "<= 2"], []),
        ({"friction": {"model": "coulomb", "fc": -1.0}}, ["friction.fc"], ["model.fc"]),
        ({"pid": {"p": -2.0}}, ["pid.p"], []),
    ],
)
def test_ros_parameter_errors_name_the_ros_keys(values, words, not_words):
    """A typo in the node's parameter file is named as written there, not by core section names."""
    from friction_ros.core.control.controller import controller_from_ros_parameters

    with pytest.raises(ParameterError) as ei:
        controller_from_ros_parameters(values)
    text = str(ei.value)
    assert "controller.friction" not in text and not text.startswith("controller."), text
    for w in words:
        assert w in text, text
    for w in not_words:
        assert w not in text, text


def test_cascade_velocity_pi_takes_the_cascade_gains_checked_once():
    """The cascade's velocity PI is built from the cascade's typed gains (checked with the PID's
    range when the section is typed), and names its own rules under cascade.velocity_pi."""
    from friction_ros.core.control.schemes import Cascade

    c = Cascade.from_dict({"kp_velocity": 0.4, "ki_velocity": 7.0, "i_clamp": 1.5})
    pi = c.pi
    assert (pi.p, pi.i, pi.d) == (0.4, 7.0, 0.0)
    assert (pi.i_clamp_max, pi.i_clamp_min, pi.antiwindup_strategy) == (1.5, -1.5, "back_calculation")
    assert pi.prefix == "cascade.velocity_pi"
    with pytest.raises(ParameterError, match=r"^cascade\.kp_velocity = 2e\+12 is out of range"):
        Cascade.from_dict({"kp_velocity": 2e12})
    with pytest.raises(
        ParameterError, match=r"^cascade\.velocity_pi\.i_clamp_min = 2 is out of range: must be <= 1.5"
    ):
        pi.set_gains(i_clamp_min=2.0)
