"""Gearhead servo plant: mechanics, actuation, stick logic, sensing, fallback path."""

from __future__ import annotations

import json
import math
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from friction_ros.core.plant.params import PlantParams, voltage_params_from_transfer_function
from friction_ros.core.plant.sensing import current_from_sensor_voltage, sensor_voltage_from_current
from friction_ros.core.plant.servo import GearheadServoPlant
from friction_ros.core.validation import ParameterError

ROOT = Path(__file__).resolve().parents[1]


def _plant(**kw):
    base = dict(motor_inertia=0.01, torque_constant=1.0, actuation="torque")
    base.update(kw)
    return GearheadServoPlant(PlantParams(**base))


def test_rigid_frictionless_torque_step_is_exact():
    pl = _plant(gear_ratio=5.0, load_inertia=0.5, gear_efficiency=1.0)
    jeq = 0.01 + 0.5 / 25
    tau = 2.0  # joint torque -> motor torque 0.4
    out = pl.simulate(np.full(1000, tau), 1e-3)
    t = out["time"]
    acc = (tau / 5.0) / jeq / 5.0  # joint acceleration
    np.testing.assert_allclose(out["true_velocity"], acc * t, rtol=1e-9)
    assert out["true_position"][-1] == pytest.approx(0.5 * acc * t[-1] ** 2, rel=2e-3)  # semi-implicit Euler
    np.testing.assert_allclose(out["effort"], tau)


def test_karnopp_holds_body_under_fs_and_releases_above():
    fr = dict(model="karnopp", fc=0.3, fs=0.5, vs=0.1, dv=1e-3)
    for stick_model in (fr, dict(model="stribeck", fc=0.3, fs=0.5, vs=0.1)):
        pl = _plant(friction_motor=stick_model)
        out = pl.simulate(np.full(500, 0.49), 1e-3)
        assert np.all(out["true_velocity"] == 0.0) and np.all(out["true_position"] == 0.0)
        assert out["friction_motor"][-1] == pytest.approx(0.49)
        pl.reset()
        out = pl.simulate(np.full(500, 0.51), 1e-3)
        assert out["true_velocity"][-1] > 0.01
        pl.reset()
        out = pl.simulate(np.full(500, -0.51), 1e-3)
        assert out["true_velocity"][-1] < -0.01


@pytest.mark.parametrize(
    "fric",
    [
        dict(model="coulomb", fc=0.2),
        dict(model="stribeck", fc=0.2, fs=0.3, vs=0.05, fv=0.01),
        dict(model="ga_exponential", fs=0.3, gamma=4.0, delta=0.5, fc=0.1, sigma=0.01),
        dict(model="lugre", sigma0=1e4, sigma1=5.0, fc=0.2, fs=0.3, vs=0.05),
        dict(model="gms", fc=0.2, fs=0.3, vs=0.05, attraction=50.0, k=[1e3, 5e2], alpha=[0.5, 0.5]),
    ],
)
def test_coast_down_friction_never_injects_energy(fric):
    pl = _plant(friction_motor=fric)
    pl.reset(velocity=3.0)
    out = pl.simulate(np.zeros(3000), 1e-3)
    v = out["true_velocity"]
    assert np.all(np.isfinite(v))
    ke = 0.5 * 0.01 * v**2
    # kinetic energy never grows; a dynamic model may only give back its stored bristle energy F^2/(2 k)
    k = min(fric.get("k", [fric.get("sigma0", np.inf)]))
    assert np.all(np.diff(ke) <= (0.3**2 / (2 * k) if np.isfinite(k) else 1e-12))
    # the body comes to rest (dynamic models: at most a presliding oscillation on the bristle springs)
    ebr = 0.3**2 / (2 * k) if np.isfinite(k) else 0.0
    assert np.max(np.abs(v[-500:])) <= math.sqrt(2 * ebr / 0.01) + 1e-3


def test_current_loop_lag_and_limits():
    pl = GearheadServoPlant(
        PlantParams(
            motor_inertia=1.0,
            torque_constant=0.1,
            actuation="current",
            amplifier_gain=2.0,
            current_time_constant=0.005,
            current_limit=1.5,
        )
    )
    out = pl.simulate(np.full(50, 0.5), 1e-3)
    t = out["time"]
    np.testing.assert_allclose(out["true_motor_current"], 1.0 * (1 - np.exp(-t / 0.005)), rtol=1e-9)
    pl.reset()
    out = pl.simulate(np.full(100, 5.0), 1e-3)
    assert out["true_motor_current"].max() == pytest.approx(1.5)


def test_voltage_mode_reproduces_ai_chapter_transfer_function_E113():
    cfg = voltage_params_from_transfer_function(275.0, 0.1009)
    pl = GearheadServoPlant(PlantParams(**cfg))
    u = 0.01
    out = pl.simulate(np.full(2000, u), 1e-3)
    t, w = out["time"], out["true_velocity"]
    np.testing.assert_allclose(w, 275.0 * u * (1 - np.exp(-t / 0.1009)), rtol=1e-3, atol=1e-6)


def test_lead_screw_gravity_and_backlash():
    # linear axis: joint in metres; gravity pulls down; reflected inertia per Tilakaratna et al. 2004 eq. (2)
    p = PlantParams(
        motor_inertia=3e-5,
        transmission_inertia=8.37e-5,
        load_inertia=23.0,
        lead_pitch=0.005,
        gear_efficiency=0.9,
        gravity_force=225.63,
        torque_constant=1.0,
        actuation="torque",
    )
    pl = GearheadServoPlant(p)
    out = pl.simulate(np.zeros(100), 1e-3)
    assert out["true_position"][-1] < 0
    assert out["motor_position"][-1] == pytest.approx(out["true_position"][-1] * 2 * math.pi / 0.005)
    pl.reset()
    hold = pl.simulate(np.full(100, 225.63), 1e-3)  # joint force equal to the weight: no motion
    assert abs(hold["true_position"][-1]) < 1e-12
    # backlash: the motor turns through the gap before the load moves
    pb = GearheadServoPlant(
        PlantParams(
            motor_inertia=1e-4,
            load_inertia=1e-2,
            gear_ratio=10.0,
            torque_constant=1.0,
            backlash=0.02,
            coupling_stiffness=50.0,
            coupling_damping=0.1,
            actuation="current",
        )
    )
    out = pb.simulate(np.full(200, 0.01), 1e-3)
    gap_crossed = np.argmax(out["motor_position"] / 10.0 > 0.01)
    assert gap_crossed > 0
    assert np.all(out["true_position"][:gap_crossed] == 0.0)
    assert out["true_position"][-1] > 0.0


def test_sensing_quantisation_filter_noise_delay_and_seed():
    p = PlantParams(
        motor_inertia=0.0012,
        torque_constant=0.49,
        encoder_cpr=20000,
        encoder_ratio=3.0,
        velocity_filter_hz=100.0,
        current_noise_std=0.01,
        current_offset=0.05,
        seed=7,
    )
    pl = GearheadServoPlant(p)
    out = pl.simulate(np.full(300, 0.2), 1e-3)
    res = 2 * math.pi / 60000
    counts = out["position"] / res
    np.testing.assert_allclose(counts, np.round(counts), atol=1e-6)
    assert np.all(np.abs(out["position"] - out["true_position"]) <= res + 1e-12)
    assert np.std(out["motor_current"] - out["true_motor_current"]) == pytest.approx(0.01, rel=0.2)
    assert np.mean(out["motor_current"] - out["true_motor_current"]) == pytest.approx(0.05, abs=0.003)
    # velocity from the filtered difference tracks the true velocity (lag ~ 1/(2 pi 100 Hz))
    assert out["velocity"][-1] == pytest.approx(out["true_velocity"][-1], rel=0.05)
    pl.reset()
    again = pl.simulate(np.full(300, 0.2), 1e-3)
    np.testing.assert_array_equal(again["motor_current"], out["motor_current"])  # seeded
    d = GearheadServoPlant(p.replace(measurement_delay=0.005, current_noise_std=0.0, encoder_cpr=0))
    nd = GearheadServoPlant(p.replace(current_noise_std=0.0, encoder_cpr=0))
    a = d.simulate(np.full(50, 0.2), 1e-3)
    b = nd.simulate(np.full(50, 0.2), 1e-3)
    np.testing.assert_allclose(a["position"][5:], b["position"][:-5])
    da = GearheadServoPlant(p.replace(actuation_delay=0.003, current_noise_std=0.0, encoder_cpr=0))
    c = da.simulate(np.full(50, 0.2), 1e-3)
    np.testing.assert_allclose(c["true_position"][3:], b["true_position"][:-3])


def test_ai_chapter_current_sensor_calibration_E110():
    assert current_from_sensor_voltage(2.531) == pytest.approx(0.22787, abs=1e-5)
    assert current_from_sensor_voltage(2.475) == pytest.approx(-0.21204, abs=1e-5)
    assert current_from_sensor_voltage(2.50199) == pytest.approx(0.0, abs=1e-4)
    assert sensor_voltage_from_current(0.22787) == pytest.approx(2.531, abs=1e-5)


def test_stiff_friction_forces_finer_substeps_and_stays_stable():
    pl = _plant(
        motor_inertia=0.0012,
        friction_motor=dict(model="lugre", sigma0=1e5, sigma1=10.0, fc=0.8, fs=0.95, vs=0.05),
    )
    n, h = pl.substeps(1e-3)
    assert h * math.sqrt(1e5 / 0.0012) <= 0.5 + 1e-12 and n >= 10
    rng = np.random.default_rng(0)
    out = pl.simulate(rng.normal(0, 1.5, 3000), 1e-3)
    assert np.all(np.isfinite(out["true_velocity"])) and np.max(np.abs(out["true_velocity"])) < 50


def test_parameter_validation_is_clear():
    with pytest.raises(
        ParameterError, match=r"plant\.motor_inertia = -1 is out of range: must be > 0 \[kg\*m\^2\]"
    ):
        PlantParams(motor_inertia=-1.0, torque_constant=1.0)
    with pytest.raises(
        ParameterError,
        match=r"plant\.actuation = 'pwm' is not allowed: must be one of current, torque, voltage",
    ):
        PlantParams(motor_inertia=1.0, torque_constant=1.0, actuation="pwm")
    with pytest.raises(ParameterError, match=r"plant\.gear_efficiency = 1.5 is out of range"):
        PlantParams(motor_inertia=1.0, torque_constant=1.0, gear_efficiency=1.5)
    with pytest.raises(ParameterError, match=r"plant\.coupling_stiffness = 0 with plant\.backlash"):
        PlantParams(motor_inertia=1.0, torque_constant=1.0, backlash=0.01)
    with pytest.raises(ParameterError, match=r"plant: unknown parameter\(s\) 'inertia'"):
        PlantParams.from_config({"inertia": 1.0, "torque_constant": 1.0})
    with pytest.raises(ParameterError, match=r"plant\.torque_constant is missing"):
        PlantParams.from_config({"motor_inertia": 1.0})
    with pytest.raises(ParameterError, match=r"lugre\.sigma0"):
        PlantParams(motor_inertia=1.0, torque_constant=1.0, friction_motor={"model": "lugre", "sigma0": 0.0})


_FALLBACK = r"""
import json, numpy as np
from friction_ros.core.friction import make_model
from friction_ros.core.plant.params import PlantParams
from friction_ros.core.plant.servo import GearheadServoPlant
v = np.sin(np.linspace(0, 20, 400)) * 0.3
g = make_model("gms", fc=0.8, fs=0.95, vs=0.05, attraction=50.0, k=[1e5, 1e3], alpha=[0.4, 0.6])
l = make_model("lugre", sigma0=1e5, sigma1=20.0, fc=0.8, fs=0.95, vs=0.05)
pl = GearheadServoPlant(PlantParams(motor_inertia=0.0012, torque_constant=0.49, friction_motor=g.to_config(),
                        friction_load={"model": "stribeck", "fc": 0.1, "fs": 0.2, "vs": 0.1}))
out = pl.simulate(np.sin(np.linspace(0, 10, 100)) * 2.0, 1e-3)
print(json.dumps({"gms": g.simulate(v, 1e-3).tolist(), "lugre": l.simulate(v, 1e-3).tolist(),
                  "plant": out["true_position"].tolist()}))
"""


def test_pure_python_fallback_equals_numba_path():
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    res = {}
    for flag in ("0", "1"):
        env["FRICTION_ROS_NO_NUMBA"] = flag
        r = subprocess.run(
            [sys.executable, "-c", _FALLBACK], env=env, capture_output=True, text=True, check=True
        )
        res[flag] = json.loads(r.stdout)
    for key in ("gms", "lugre", "plant"):
        np.testing.assert_allclose(res["0"][key], res["1"][key], rtol=1e-9, atol=1e-12)
