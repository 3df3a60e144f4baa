"""Learned residual on a physics backbone (issue 17 item 4): run-time recursion, config, training."""

from __future__ import annotations

import math

import numpy as np
import pytest

from friction_ros.core.config import flatten
from friction_ros.core.friction.learned_residual import (
    LEARNED_RESIDUAL_SCHEMA,
    LearnedResidual,
    feature_names,
    feature_settings,
)
from friction_ros.core.identification.fit.residual_learning import fit_residual, residual_features
from friction_ros.core.validation import ParameterError

DT = 1e-3


def joint(duration: float, seed: int = 0):
    """A joint whose torque has presliding hysteresis (Dahl, dz/dq = sigma (1 - z sgn dq)) and a
    frictional lag (0.4 (v_f - v), v_f low-passed at 50 ms) that a Coulomb-viscous backbone misses."""
    rng = np.random.default_rng(seed)
    t = np.arange(0.0, duration, DT)
    v = sum(
        rng.uniform(0.1, 0.4) * np.sin(2 * np.pi * f * t + rng.uniform(0, 2 * np.pi))
        for f in (0.13, 0.31, 0.7, 1.3)
    )
    q = np.cumsum(v) * DT
    a = np.gradient(v, DT)
    z = np.zeros_like(t)
    vf = np.zeros_like(t)
    zk = vfk = 0.0
    alpha = 1.0 - math.exp(-DT / 0.05)
    for k in range(1, t.size):
        dq = q[k] - q[k - 1]
        zk = min(max(zk + 300.0 * dq * (1.0 - zk * np.sign(dq)), -1.0), 1.0)
        vfk += alpha * (v[k] - vfk)
        z[k], vf[k] = zk, vfk
    tau = 0.05 * a + 0.3 * z + 0.1 * v + 0.4 * (vf - v) + 0.5 * np.sin(q) + rng.normal(0, 0.01, t.size)
    return q, v, a, tau


def backbone(q, v, a, tau, n_train):
    """Least-squares physics: J a + Fc tanh(v / 0.01) + Fv v + G sin q + offset, on the training part."""
    basis = np.c_[a, np.tanh(v / 0.01), v, np.sin(q), np.ones_like(q)]
    theta = np.linalg.lstsq(basis[:n_train], tau[:n_train], rcond=None)[0]
    return basis @ theta


def nmse(pred, y):
    return 100.0 * np.mean((pred - y) ** 2) / np.var(y)


@pytest.fixture(scope="module")
def fitted():
    q, v, a, tau = joint(20.0)
    n = int(0.6 * q.size)
    phys = backbone(q, v, a, tau, n)
    model, report = fit_residual(q, v, tau, tau - phys, DT, kind="mlp", seed=0, validation=0.4)
    return q, v, tau, phys, n, model, report


def hand_config(kind: str, seed: int = 1, **settings) -> dict:
    """A valid config with random weights (no training) for the recursion and config tests."""
    rng = np.random.default_rng(seed)
    s = feature_settings(settings)
    n = len(feature_names(s))
    sizes = [n, 12, 8, 1] if kind == "mlp" else [n, 30, 1]
    nw = sum(x * y for x, y in zip(sizes[:-1], sizes[1:]))
    return {
        "kind": kind,
        **s,
        "feature_mean": rng.normal(0, 0.1, n).tolist(),
        "feature_scale": rng.uniform(0.5, 2.0, n).tolist(),
        "feature_low": [-5.0] * n,
        "feature_high": [5.0] * n,
        "layer_sizes": sizes,
        "weights": rng.normal(0, 0.5, nw).tolist(),
        "biases": rng.normal(0, 0.1, sum(sizes[1:])).tolist(),
        "output_mean": 0.05,
        "output_scale": 0.2,
        "clip_low": -0.3,
        "clip_high": 0.4,
    }


def wave(n: int = 4000, seed: int = 2):
    rng = np.random.default_rng(seed)
    t = np.arange(n) * DT
    v = 0.8 * np.sin(2 * np.pi * 1.1 * t) + 0.3 * np.sin(2 * np.pi * 3.7 * t) + rng.normal(0, 0.01, n)
    q = 0.3 + np.cumsum(v) * DT
    return q, v, 2.0 * np.sin(2 * np.pi * 0.5 * t)


def step_loop(model: LearnedResidual, q, v, c) -> np.ndarray:
    model.reset()
    return np.array([model.step(a, b, d) for a, b, d in zip(q.tolist(), v.tolist(), c.tolist())])


@pytest.mark.parametrize(
    "kind,settings",
    [
        ("mlp", {}),
        ("mlp", {"use_command": True, "position_input": "raw", "velocity_time_constants": [0.005]}),
        ("rff", {"position_input": "none", "displacement_scales": [0.001, 0.01, 0.1]}),
    ],
)
def test_step_equals_predict_batch(kind, settings):
    model = LearnedResidual(hand_config(kind, **settings))
    q, v, c = wave()
    batch = model.predict_batch(q, v, c)
    loop = step_loop(model, q, v, c)
    assert np.max(np.abs(batch - loop)) < 1e-12
    assert np.std(batch) > 1e-3  # the map does something (the comparison is not between zeros)
    # predict_batch leaves step()'s history alone; reset() restarts it
    model.reset()
    first = [model.step(a, b, d) for a, b, d in zip(q[:10], v[:10], c[:10])]
    model.predict_batch(q, v, c)
    assert model.step(q[10], v[10], c[10]) == pytest.approx(loop[10], abs=1e-12)
    assert np.allclose(first, loop[:10], atol=1e-12)


def test_fitted_step_equals_predict_batch_and_round_trip(fitted):
    q, v, tau, _, _, model, _ = fitted
    qs, vs, cs = q[:5000], v[:5000], tau[:5000]
    batch = model.predict_batch(qs, vs, cs)
    assert np.max(np.abs(batch - step_loop(model, qs, vs, cs))) < 1e-12
    cfg = model.to_config()
    for key, value in flatten({"residual": cfg}).items():  # flat ROS parameter values only
        assert isinstance(value, (str, float, int, bool)) or (
            isinstance(value, list) and all(isinstance(x, (float, int)) for x in value)
        ), key
    again = LearnedResidual.from_config(cfg)
    assert np.max(np.abs(again.predict_batch(qs, vs, cs) - batch)) < 1e-12
    assert again.to_config() == cfg


def test_residual_reduces_validation_nmse(fitted):
    """The backbone misses the hysteresis and lag: the residual cuts the validation NMSE >= 5x."""
    q, v, tau, phys, n, model, report = fitted
    r_hat = model.predict_batch(q, v, tau)[n:]
    physics_only = nmse(phys[n:], tau[n:])
    with_residual = nmse(phys[n:] + r_hat, tau[n:])
    assert physics_only > 5.0  # the backbone really misses something
    assert with_residual < physics_only / 5.0, (physics_only, with_residual)
    assert report["chosen"] == "mlp"
    mse = report["candidates"]["mlp"]["validation_mse"]
    assert mse == pytest.approx(np.mean((r_hat - (tau - phys)[n:]) ** 2), rel=1e-9)


def test_extrapolation_stays_in_clip_range_and_fades_out(fitted):
    q, v, tau, phys, n, model, _ = fitted
    lo, hi = model.clip_low, model.clip_high
    r = tau[:n] - phys[:n]
    assert lo == pytest.approx(r.min()) and hi == pytest.approx(r.max())
    rng = np.random.default_rng(3)
    qf = rng.uniform(-1e3, 1e3, 3000)
    vf = rng.uniform(-1e2, 1e2, 3000)
    out = model.predict_batch(qf, vf, rng.uniform(-1e3, 1e3, 3000))
    assert np.all((out >= lo) & (out <= hi))
    # far outside the training velocities only the backbone is left
    model.reset()
    assert [model.step(0.0, 50.0 * (-1) ** k, 0.0) for k in range(20)][-1] == min(max(0.0, lo), hi)
    # inside the training range it is not faded (the comparison above is not vacuous)
    assert np.std(model.predict_batch(q[:2000], v[:2000], tau[:2000])) > 0.01


def test_several_runs_restart_the_history():
    q, v, c = wave(3000)
    s = {"displacement_scales": [0.01]}
    one = residual_features(q[:1000], v[:1000], c[:1000], DT, s)
    two = residual_features(q[1000:], v[1000:], c[1000:], DT, s)
    both = residual_features([q[:1000], q[1000:]], [v[:1000], v[1000:]], [c[:1000], c[1000:]], DT, s)
    assert np.array_equal(both, np.concatenate([one, two]))
    assert not np.allclose(two, residual_features(q, v, c, DT, s)[1000:])  # history did matter
    model = LearnedResidual(hand_config("mlp", dt=DT, **s))
    assert (
        np.max(np.abs(model.predict_features(two) - model.predict_batch(q[1000:], v[1000:], c[1000:])))
        < 1e-12
    )


def test_fit_is_deterministic_with_a_seed():
    q, v, a, tau = joint(6.0, seed=4)
    n = int(0.6 * q.size)
    r = tau - backbone(q, v, a, tau, n)
    kw = {"kind": "mlp", "hidden": (8,), "validation": 0.4}
    # the fitted map (report["models"]) whether or not it beats r = 0 on this short record
    m1 = fit_residual(q, v, tau, r, DT, seed=5, **kw)[1]["models"]["mlp"]
    m2 = fit_residual(q, v, tau, r, DT, seed=5, **kw)[1]["models"]["mlp"]
    m3 = fit_residual(q, v, tau, r, DT, seed=6, **kw)[1]["models"]["mlp"]
    assert m1.to_config() == m2.to_config()
    assert m1.to_config()["weights"] != m3.to_config()["weights"]


def test_none_kind_and_schema_defaults():
    assert LearnedResidual.from_config({}) is None
    assert LearnedResidual.from_config({"kind": "none", "dt": 0.002}) is None
    assert LEARNED_RESIDUAL_SCHEMA.defaults()["kind"] == "none"


def _bad(cfg: dict, key: str, value) -> dict:
    out = dict(cfg)
    out[key] = value
    return out


@pytest.mark.parametrize(
    "change,name",
    [
        (lambda c: _bad(c, "weights", c["weights"][:-1]), "residual.weights"),
        (
            lambda c: _bad(c, "weights", [*c["weights"][:3], float("nan"), *c["weights"][4:]]),
            "residual.weights[3]",
        ),
        (lambda c: _bad(c, "biases", [*c["biases"], 0.0]), "residual.biases"),
        (lambda c: _bad(c, "layer_sizes", [4, *c["layer_sizes"][1:]]), "residual.layer_sizes"),
        (lambda c: _bad(c, "layer_sizes", [*c["layer_sizes"][:-1], 2]), "residual.layer_sizes"),
        (lambda c: _bad(c, "feature_mean", c["feature_mean"][:-1]), "residual.feature_mean"),
        (lambda c: _bad(c, "feature_scale", [0.0] * len(c["feature_scale"])), "residual.feature_scale[0]"),
        (lambda c: _bad(c, "feature_high", [-6.0] * len(c["feature_high"])), "residual.feature_high[0]"),
        (lambda c: _bad(c, "output_mean", float("nan")), "residual.output_mean"),
        (lambda c: _bad(c, "clip_high", -1.0), "residual.clip_high"),
        (lambda c: _bad(c, "kind", "svm"), "residual.kind"),
        (lambda c: _bad(c, "velocity_time_constants", [0.01, -0.1]), "residual.velocity_time_constants[1]"),
        (lambda c: _bad(c, "dt", 0.0), "residual.dt"),
        (lambda c: {**c, "weight": c["weights"]}, "residual"),
    ],
)
def test_bad_config_names_the_key(change, name):
    cfg = change(hand_config("mlp"))
    with pytest.raises(ParameterError) as e:
        LearnedResidual.from_config(cfg)
    msg = str(e.value)
    assert "\n" not in msg and name in msg, msg


def test_fit_rejects_bad_input():
    q, v, c = wave(500)
    with pytest.raises(ParameterError, match="different lengths"):
        fit_residual(q, v, c, np.zeros(499), DT)
    with pytest.raises(ParameterError, match="non-finite"):
        fit_residual(q, np.where(np.arange(500) == 7, np.nan, v), c, np.zeros(500), DT)
    with pytest.raises(ParameterError, match="kind"):
        fit_residual(q, v, c, np.zeros(500), DT, kind="svm")
