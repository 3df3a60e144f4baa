"""Online friction estimation: torque balance, DOB, RLS convergence from +-50 % and no drift at rest."""

import numpy as np
import pytest

from friction_ros.core.estimation import (
    DisturbanceObserver,
    OnlineFrictionEstimator,
    RecursiveLeastSquares,
    TorqueBalanceEstimator,
)
from friction_ros.core.harness import run_closed_loop
from friction_ros.core.presets import make_plant
from friction_ros.core.validation import ParameterError

J = 0.0012
TRUTH = {"model": "stribeck", "fc": 0.4, "fs": 0.6, "vs": 0.05, "delta": 2.0, "fv": 0.05}


def plant():
    return make_plant(
        {
            "plant": {"motor_inertia": J, "torque_constant": 0.49, "actuation": "torque"},
            "friction_motor": TRUTH,
        }
    )


def _run(est_cfg, reference, duration, est=None):
    est = est or OnlineFrictionEstimator(est_cfg)
    ctrl = {
        "pid": {"p": 50.0, "d": 0.5},
        "inertia": J,
        "friction": {"model": {"model": "coulomb", "fc": 0.3}, "source": "feedforward"},
    }
    res = run_closed_loop(plant(), ctrl, reference, duration, estimator=est)
    return est, res


EXCITE = {"type": "sinusoid", "amplitude": 1.0, "frequency": 0.5}


@pytest.mark.parametrize("factor", [0.5, 1.5])
def test_rls_stribeck_converges_from_wrong_start_and_does_not_drift(factor):
    cfg = {
        "model": "stribeck",
        "inertia": J,
        "vs": 0.05,
        "delta": 2.0,
        "min_velocity": 0.01,
        "initial": {k: factor * TRUTH[k] for k in ("fc", "fs", "fv")},
        "forgetting_factor": 0.9999,
    }
    # slow large sinusoid (v up to 1.9 rad/s, gentle reversals) excites the Stribeck and viscous parts
    est, _ = _run(cfg, {"type": "sinusoid", "amplitude": 3.0, "frequency": 0.1}, 10.0)
    c = est.coefficients
    for k in ("fc", "fs", "fv"):
        assert c[k] == pytest.approx(TRUTH[k], rel=0.05), (k, c[k])
    assert est.converged
    # 10 s at rest: no update, no drift beyond 1 %
    before = dict(c)
    _run(cfg, {"type": "constant"}, 10.0, est=_continue(est))
    for k in before:
        assert est.coefficients[k] == pytest.approx(before[k], rel=0.01)


def _continue(est):
    # keep the fitted coefficients across the rest run (run_closed_loop resets the estimator)
    theta = est.rls.theta.copy()
    P = est.rls.P.copy()

    class Keep(OnlineFrictionEstimator):
        def reset(self):
            super().reset()
            if self.rls is not None:
                self.rls.theta, self.rls.P = theta.copy(), P.copy()

    est.__class__ = Keep
    est.rls.theta, est.rls.P = theta, P
    return est


@pytest.mark.parametrize("factor", [0.5, 1.5])
def test_rls_asymmetric_coulomb_viscous_with_dob(factor):
    truth = {"fc": 0.4, "fv": 0.05}
    p = make_plant(
        {
            "plant": {"motor_inertia": J, "torque_constant": 0.49, "actuation": "torque"},
            "friction_motor": {"model": "coulomb_viscous", **truth},
        }
    )
    init = {
        "positive": {"fc": 0.4 * factor, "fv": 0.05 * factor},
        "negative": {"fc": 0.4 * factor, "fv": 0.05 * factor},
    }
    est = OnlineFrictionEstimator(
        {
            "method": "disturbance_observer",
            "model": "asymmetric_coulomb_viscous",
            "inertia": J,
            "observer_bandwidth": 300.0,
            "initial": init,
            "min_velocity": 0.05,
        }
    )
    run_closed_loop(p, {"pid": {"p": 50.0, "d": 0.5}, "inertia": J}, EXCITE, 8.0, estimator=est)
    c = est.coefficients
    assert c["positive.fc"] == pytest.approx(0.4, rel=0.05) and c["negative.fc"] == pytest.approx(
        0.4, rel=0.05
    )
    assert c["positive.fv"] == pytest.approx(0.05, rel=0.05) and c["negative.fv"] == pytest.approx(
        0.05, rel=0.05
    )
    cfg = est.model_config()
    assert cfg["model"] == "asymmetric" and cfg["positive"]["fc"] == pytest.approx(c["positive.fc"])


def test_estimate_fields_and_adoption_by_controller():
    cfg = {"model": "coulomb_viscous", "inertia": J, "min_velocity": 0.02}
    est = OnlineFrictionEstimator(cfg)
    res = run_closed_loop(
        plant(),
        {
            "pid": {"p": 50.0, "d": 0.5},
            "inertia": J,
            "friction": {"model": {"model": "coulomb_viscous", "fc": 0.0, "fv": 0.0}},
        },
        EXCITE,
        4.0,
        estimator=est,
        adopt_period=0.5,
    )
    e = est.estimate
    assert e.coefficient_names == ["fc", "fv"] and len(e.coefficient_std) == 2
    assert e.excitation_ok in (True, False) and e.converged
    assert res.estimate["friction_torque"].shape == res.t.shape


def test_torque_balance_and_dob_recover_constant_friction():
    tb = TorqueBalanceEstimator(J, 0.002)
    dob = DisturbanceObserver(J, 300.0)
    # J a = tau - d with tau = 1.0, d = 0.4 -> a = 500 rad/s^2
    v = 0.0
    for _ in range(200):
        v += 500.0 * 1e-3
        f1, _, _ = tb.update(1.0, v, 1e-3)
        f2, _, _ = dob.update(1.0, v, 1e-3)
    # torque balance: ZOH of the sampled velocity biases the filtered acceleration by ~2 % (J a)
    assert f1 == pytest.approx(0.4, abs=0.015) and f2 == pytest.approx(0.4, abs=0.006)


def test_rls_skips_unexcited_samples():
    r = RecursiveLeastSquares(["a", "b"], [1.0, 2.0], 0.99)
    for _ in range(100):
        r.update([0.0, 0.0], 5.0)
        r.update([1.0, 0.0], 5.0, excited=False)
    assert list(r.theta) == [1.0, 2.0] and r.updates == 0
    for _ in range(200):
        r.update([1.0, 0.0], 5.0)
    assert r.theta[0] == pytest.approx(5.0, abs=1e-3) and r.theta[1] == 2.0
    assert r.P[1, 1] == pytest.approx(10.0)  # no wind-up of the unexcited direction


def test_lugre_observer_estimator():
    lu = {"model": "lugre", "sigma0": 1e4, "sigma1": 0.0, "fv": 0.05, "fc": 0.4, "fs": 0.6, "vs": 0.05}
    p = make_plant(
        {"plant": {"motor_inertia": J, "torque_constant": 0.49, "actuation": "torque"}, "friction_motor": lu}
    )
    est = OnlineFrictionEstimator({"model": "lugre", "lugre": lu, "inertia": J})
    res = run_closed_loop(p, {"pid": {"p": 50.0, "d": 0.5}, "inertia": J}, EXCITE, 3.0, estimator=est)
    err = res.estimate["model_torque"][500:] - res.friction[500:]
    assert np.sqrt(np.mean(err**2)) < 0.05 * np.sqrt(np.mean(res.friction[500:] ** 2))
    assert len(est.estimate.state) == 1


@pytest.mark.parametrize(
    "cfg, words",
    [
        ({"model": "gms"}, ["estimator.model", "stribeck"]),
        ({"method": "disturbance_observer"}, ["estimator.inertia", "> 0"]),
        ({"forgetting_factor": 1.2}, ["forgetting_factor"]),
        ({"initial": {"fs": 1.0}}, ["estimator.initial", "'fs'"]),
        ({"model": "lugre"}, ["estimator.lugre"]),
        ({"gain": 1.0}, ["unknown", "'gain'"]),
    ],
)
def test_validation(cfg, words):
    with pytest.raises(ParameterError) as ei:
        OnlineFrictionEstimator(cfg)
    for w in words:
        assert w in str(ei.value)
