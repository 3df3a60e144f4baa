"""PID with control_toolbox names: law, clamps, anti-windup strategies, derivative filter, validation."""

import math

import pytest

from friction_ros.core.control import Pid
from friction_ros.core.validation import ParameterError


def test_pd_law_and_terms():
    pid = Pid({"p": 200.0, "d": 0.15})
    out = pid.update(0.01, 1e-3, error_dot=2.0, offset=0.5)
    assert out.p_term == pytest.approx(2.0)
    assert out.d_term == pytest.approx(0.3)
    assert out.command == pytest.approx(2.8)
    assert not out.saturated


def test_integral_forward_euler_and_i_clamp():
    pid = Pid(p=0.0, i=10.0, i_clamp_max=0.05, i_clamp_min=-0.05)
    outs = [pid.update(1.0, 1e-3, error_dot=0.0) for _ in range(10)]
    assert outs[0].i_term == 0.0 and outs[1].i_term == pytest.approx(0.01)
    assert pid.integral == pytest.approx(0.05)  # clamped


def _windup(strategy):
    pid = Pid(p=1.0, i=50.0, u_clamp_max=0.5, u_clamp_min=-0.5, antiwindup_strategy=strategy)
    for _ in range(1000):  # 1 s saturated by a large error
        pid.update(2.0, 1e-3, error_dot=0.0)
    return pid.integral


def test_antiwindup_strategies_limit_the_integrator():
    none, back, cond = _windup("none"), _windup("back_calculation"), _windup("conditional_integration")
    assert none == pytest.approx(100.0, rel=1e-6)  # i e t, unbounded growth
    assert back < 0.1 * none
    assert cond == pytest.approx(0.0)  # saturated from the first period: never integrates


def test_conditional_integration_integrates_when_error_unwinds():
    pid = Pid(p=1.0, i=50.0, u_clamp_max=0.5, u_clamp_min=-0.5, antiwindup_strategy="conditional_integration")
    pid.integral = 1.0
    pid.update(-0.1, 1e-3, error_dot=0.0)  # u = 0.9 saturated, but e < 0 drives out of saturation
    assert pid.integral < 1.0


def test_u_clamp_and_extra_bounds():
    pid = Pid(p=100.0, u_clamp_max=1.0, u_clamp_min=-2.0)
    assert pid.update(1.0, 1e-3).command == 1.0
    assert pid.update(-1.0, 1e-3).command == -2.0
    out = pid.update(1.0, 1e-3, lower=-0.1, upper=0.2)
    assert out.command == 0.2 and out.saturated and out.unlimited == pytest.approx(100.0)


def test_deadband_and_derivative_filter():
    pid = Pid(p=1.0, error_deadband=0.01)
    assert pid.update(0.005, 1e-3).p_term == 0.0
    f = Pid(d=1.0, derivative_filter_time_constant=0.009)
    f.update(0.0, 1e-3, error_dot=0.0)
    out = f.update(0.0, 1e-3, error_dot=1.0)
    assert out.d_term == pytest.approx(0.1)  # dt / (Tf + dt)


def test_default_tracking_time_constant_is_control_toolbox():
    assert Pid(p=2.0, i=4.0, d=1.0)._effective_tt() == pytest.approx(math.sqrt(0.25))
    assert Pid(p=2.0, i=4.0)._effective_tt() == pytest.approx(0.5)


@pytest.mark.parametrize(
    "cfg, words",
    [
        ({"p": -1.0}, ["p = -1", ">= 0"]),
        ({"antiwindup_strategy": "legacy"}, ["antiwindup_strategy", "back_calculation"]),
        ({"u_clamp_max": 1.0, "u_clamp_min": 2.0}, ["u_clamp_min"]),
        ({"kp": 1.0}, ["unknown", "'kp'"]),
        ({"i_clamp_max": float("nan")}, ["i_clamp_max", "not finite"]),
    ],
)
def test_validation_errors_name_the_parameter(cfg, words):
    with pytest.raises(ParameterError) as ei:
        Pid(cfg)
    for w in words:
        assert w in str(ei.value)


def test_set_gains_all_or_nothing():
    pid = Pid(p=1.0)
    with pytest.raises(ParameterError):
        pid.set_gains(p=2.0, d=-1.0)
    assert pid.p == 1.0
    pid.set_gains(p=3.0)
    assert pid.p == 3.0
