"""Friction model library: defining properties, stiff-bristle stability, batch paths, validation."""

from __future__ import annotations

import math

import numpy as np
import pytest
import yaml

from friction_ros.core.friction import (
    DYNAMIC_MODEL_NAMES,
    MODEL_NAMES,
    make_model,
    model_from_config,
)
from friction_ros.core.friction import _kernels as K
from friction_ros.core.friction.gearmesh import spur_gear_dte
from friction_ros.core.validation import ParameterError

GMS4 = dict(
    fc=0.80,
    fs=0.95,
    vs=0.05,
    delta=2.0,
    attraction=50.0,
    k=[190.0, 190.0, 142.5, 95.0],
    alpha=[0.1, 0.2, 0.3, 0.4],
)

EXAMPLES = {
    "none": {},
    "coulomb": dict(fc=0.3),
    "viscous": dict(fv=0.02),
    "coulomb_viscous": dict(fc=0.3, fv=0.02),
    "stribeck": dict(fc=0.3, fs=0.5, vs=0.1, delta=1.5, fv=0.02),
    "tustin": dict(fc=0.3, fs=0.5, vs=0.1, fv=0.02),
    "gaussian": dict(fc=0.3, fs=0.5, vs=0.1, fv=0.02),
    "lorentzian": dict(fc=0.3, fs=0.5, vs=0.1, fv=0.02),
    "stribeck_eps": dict(fc=0.3, fs=0.5, vs=0.1, delta=2.0, fv=0.02, eps=1e-3),
    "ga_exponential": dict(fs=1.5281, gamma=4.3743, delta=0.1992, fc=0.3303, sigma=0.0588),
    "ga_tustin": dict(ff0=1.0, ffc=0.4, vc=0.2, x=1.3, sigma=0.05),
    "ga_nonlinear": dict(alpha0=0.3, alpha1=0.2, alpha2=0.1, beta1=5.0, beta2=0.5),
    "ga_dupont": dict(c0=0.3, c1=0.05, c2=0.2, c3=0.1, c4=2.0),
    "ga_seven_parameter": dict(fc=0.3, fv=0.05, fs=0.2, vs=0.1),
    "polynomial": dict(pos=[0.3, 0.0, 0.1, 0.01], neg=[0.25, 0.0, 0.12, 0.0]),
    "load_dependent": dict(fc=0.2, fl=0.05, fv=0.01, veps=0.0),
    "karnopp": dict(fc=0.3, fs=0.5, vs=0.1, fv=0.02, dv=1e-3),
    "gkf": dict(fc=0.3, fs=0.5, vs=0.1, fv=0.02),
    "dahl": dict(sigma=500.0, fc=0.3, alpha=1.0),
    "lugre": dict(sigma0=1e4, sigma1=5.0, fv=0.02, fc=0.3, fs=0.5, vs=0.1, vd=0.05),
    "gms": GMS4,
    "asymmetric": dict(
        base="stribeck", positive=dict(fc=0.3, fs=0.5, vs=0.1), negative=dict(fc=0.25, fs=0.4, vs=0.1)
    ),
}


def test_every_model_has_an_example_and_round_trips_through_ros_yaml():
    assert set(EXAMPLES) == set(MODEL_NAMES)
    for name, coefs in EXAMPLES.items():
        m = make_model(name, **coefs)
        cfg = m.to_config()
        assert cfg["model"] == name
        doc = yaml.safe_load(yaml.safe_dump({"plant_simulator": {"ros__parameters": {"friction": cfg}}}))
        back = model_from_config(doc["plant_simulator"]["ros__parameters"]["friction"])
        assert back == m and back.to_config() == cfg
        # flat lists only (ROS parameters cannot hold lists of lists)
        for v in cfg.values():
            if isinstance(v, list):
                assert all(isinstance(x, float) for x in v)
        v = np.linspace(-2, 2, 41)
        np.testing.assert_allclose(back.steady_state(v), m.steady_state(v))


@pytest.mark.parametrize("name", [n for n in MODEL_NAMES if n not in DYNAMIC_MODEL_NAMES])
def test_static_numpy_matches_compiled_kernel_and_is_odd_and_dissipative(name):
    m = make_model(name, **EXAMPLES[name])
    v = np.concatenate([np.linspace(-3, 3, 301), [1e-6, -1e-6, 5e-4, -5e-4]])
    f = m.torque(v)
    ker = np.array([K.friction_eval(m.kernel_kind, m.kernel_params, np.zeros(1), x, 1e-3, 0.0) for x in v])
    np.testing.assert_allclose(f, ker, rtol=1e-12, atol=1e-14)
    assert np.all(f * v >= 0), "friction must oppose motion (never inject energy in sliding)"
    assert m.torque(0.0) == 0.0
    if name not in ("polynomial", "asymmetric"):
        np.testing.assert_allclose(m.torque(-v), -f)


@pytest.mark.parametrize("name", MODEL_NAMES)
def test_scalar_steady_state_equals_the_vectorised_one(name):
    """The controller's per-period path (``steady_scalar``: the formula on a float) gives the
    vectorised map's numbers for every model, at 0, near 0 and in sliding."""
    m = make_model(name, **EXAMPLES[name])
    for x in (0.0, 1e-9, -1e-9, 1e-6, -5e-4, 0.013, -0.2, 1.0, -3.0):
        assert m.steady_scalar(x) == pytest.approx(
            float(m.steady_state(np.array([x]))[0]), rel=1e-12, abs=1e-15
        )
        assert isinstance(m.steady_scalar(x), float)


def test_stribeck_family_ai_chapter_eq5_and_lorentzian_eq7():
    fc, fs, vs, fv = 0.3, 0.5, 0.1, 0.02
    t = make_model("tustin", fc=fc, fs=fs, vs=vs, fv=fv)
    g = make_model("gaussian", fc=fc, fs=fs, vs=vs, fv=fv)
    s1 = make_model("stribeck", fc=fc, fs=fs, vs=vs, delta=1.0, fv=fv)
    v = np.linspace(0.001, 1, 50)
    np.testing.assert_allclose(t.torque(v), (fc + (fs - fc) * np.exp(-v / vs)) + fv * v)
    np.testing.assert_allclose(g.torque(v), (fc + (fs - fc) * np.exp(-((v / vs) ** 2))) + fv * v)
    np.testing.assert_allclose(s1.torque(v), t.torque(v))
    # at |v| = vs: Fc + (Fs - Fc)/e + Fv vs (E.1.2); Lorentzian: Fc + (Fs - Fc)/2 + Fv vs (E.1.3)
    assert t.torque(vs) == pytest.approx(fc + (fs - fc) / math.e + fv * vs)
    assert g.torque(-vs) == pytest.approx(-(fc + (fs - fc) / math.e + fv * vs))
    lor = make_model("lorentzian", fc=fc, fs=fs, vs=vs, fv=fv)
    assert lor.torque(vs) == pytest.approx(fc + (fs - fc) / 2 + fv * vs)
    assert t.torque(1e-9) == pytest.approx(fs, rel=1e-6)
    assert t.torque(50.0) == pytest.approx(fc + fv * 50.0)


def test_abb_m19s_stribeck_eps_zone_extract_E11():
    eps = 1e-4
    m = make_model("stribeck_eps", fc=0.8, fs=0.95, vs=0.05, delta=2.0, fv=0.01, eps=eps)
    assert m.torque(0.0) == 0.0
    assert m.torque(eps * (1 + 1e-9)) == pytest.approx(m.torque(eps * (1 - 1e-9)), abs=1e-6)  # continuous
    assert m.torque(-eps * (1 + 1e-9)) == pytest.approx(m.torque(-eps * (1 - 1e-9)), abs=1e-6)
    assert m.torque(eps * 1.0001) == pytest.approx(0.95, abs=1e-3)  # F(eps+) ~ Fs when eps << vs
    assert m.torque(100.0) == pytest.approx(0.8 + 0.01 * 100.0)
    v = np.linspace(0, 3 * eps, 7)
    np.testing.assert_allclose(m.torque(-v), -m.torque(v))


def test_ga_thesis_identified_exponential_model_table():
    m = make_model("ga_exponential", fs=1.5281, gamma=4.3743, delta=0.1992, fc=0.3303, sigma=0.0588)
    table = {
        1e-9: 1.5025,
        1e-6: 1.4298,
        1e-4: 1.2971,
        1e-3: 1.1839,
        0.01: 1.0316,
        0.05: 0.9054,
        0.1: 0.8491,
        0.2: 0.7944,
        0.5: 0.7319,
        1.0: 0.7022,
        2.0: 0.7046,
        3.0: 0.7322,
        5.0: 0.8129,
        10.0: 1.0617,
    }
    v = np.array(list(table))
    np.testing.assert_allclose(m.torque(v), list(table.values()), atol=6e-5)
    np.testing.assert_allclose(m.torque(-v), -m.torque(v))
    # limits of the other GA models (GA friction thesis 2002 section 9.1)
    nl = make_model("ga_nonlinear", **EXAMPLES["ga_nonlinear"])
    assert nl.torque(1e-12) == pytest.approx(0.3 + 0.2) and nl.torque(1e3) == pytest.approx(0.3 + 0.1)
    du = make_model("ga_dupont", **EXAMPLES["ga_dupont"])
    assert du.torque(1e-12) == pytest.approx(0.3 + 0.2)
    tu = make_model("ga_tustin", **EXAMPLES["ga_tustin"])
    assert tu.torque(1e-12) == pytest.approx(1.0)


def test_polynomial_per_direction_and_load_dependent_gearbox():
    p = make_model("polynomial", pos=[0.3, 0.0, 0.1], neg=[0.2, 0.0, 0.05])
    assert p.torque(2.0) == pytest.approx(0.3 + 0.4)
    assert p.torque(-2.0) == pytest.approx(-(0.2 + 0.2))
    ld = make_model("load_dependent", fc=0.2, fl=0.05, fv=0.0)
    assert ld.torque(1.0, load=0.0) == pytest.approx(0.2)
    assert ld.torque(1.0, load=-10.0) == pytest.approx(0.7)
    assert ld.torque(-1.0, load=10.0) == pytest.approx(-0.7)


def test_gkf_and_karnopp_stick_rules_extract_E14():
    g = make_model("gkf", fc=0.3, fs=0.5, vs=0.1)
    assert g.torque_stick(0.0, 0.4) == pytest.approx(0.4)  # |Fe| < Fs: F = Fe
    assert g.torque_stick(0.0, -0.7) == pytest.approx(-0.5)  # |Fe| > Fs: Fs sgn(Fe)
    assert g.torque_stick(0.2, 0.0) == pytest.approx(g.torque(0.2))
    k = make_model("karnopp", fc=0.3, fs=0.5, vs=0.1, dv=1e-3)
    assert k.torque_stick(5e-4, 0.3) == pytest.approx(0.3) and bool(k.sticks(5e-4, 0.3))
    assert k.torque_stick(-5e-4, -0.9) == pytest.approx(-0.5) and not bool(k.sticks(-5e-4, -0.9))
    assert k.torque_stick(2e-3, 0.0) == pytest.approx(k.torque(2e-3))


def test_asymmetric_direction_dependent():
    a = make_model("asymmetric", **EXAMPLES["asymmetric"])
    assert a.torque(1e-9) == pytest.approx(0.5, rel=1e-6)
    assert a.torque(-1e-9) == pytest.approx(-0.4, rel=1e-6)
    assert a.breakaway(1) == pytest.approx(0.5) and a.breakaway(-1) == pytest.approx(0.4)
    al = make_model(
        "asymmetric",
        base="lugre",
        positive=dict(sigma0=1e4, fc=0.3, fs=0.5, vs=0.1),
        negative=dict(sigma0=1e4, fc=0.2, fs=0.3, vs=0.1),
    )
    assert al.is_dynamic
    assert al.simulate(np.full(2000, 0.5), 1e-3)[-1] == pytest.approx(al.steady_state(0.5), rel=1e-6)
    assert al.simulate(np.full(2000, -0.5), 1e-3)[-1] == pytest.approx(al.steady_state(-0.5), rel=1e-6)


def test_dahl_extract_E15_and_is_lugre_special_case():
    sigma, fc = 500.0, 0.3
    d = make_model("dahl", sigma=sigma, fc=fc, alpha=1.0)
    dt, v = 1e-3, 0.01
    f = d.simulate(np.full(500, v), dt)
    x = v * dt * np.arange(1, 501)
    np.testing.assert_allclose(f, fc * (1 - np.exp(-sigma * x / fc)), rtol=1e-9)  # exact closed form
    assert (f[0] / x[0]) == pytest.approx(sigma, rel=2e-2)  # initial slope dF/dx = sigma
    assert d.simulate(np.full(5000, v), dt)[-1] == pytest.approx(fc, rel=1e-9)  # saturates to Fc sgn(v)
    lug = make_model("lugre", sigma0=sigma, sigma1=0.0, fv=0.0, fc=fc, fs=fc, vs=1.0)
    rng = np.random.default_rng(0)
    vv = np.repeat(rng.normal(0, 0.02, 300), 10)
    np.testing.assert_allclose(d.simulate(vv, dt), lug.simulate(vv, dt), rtol=1e-9, atol=1e-12)
    # other exponents: closed forms of dy/dx = -(sigma/Fc) y^alpha, y = 1 - F/Fc
    xx = v * dt * np.arange(1, 3001)
    u = sigma * xx / fc
    closed = {0.5: fc * (1 - np.clip(1 - 0.5 * u, 0, None) ** 2), 2.0: fc * (1 - 1 / (1 + u))}
    for alpha, expect in closed.items():
        fa = make_model("dahl", sigma=sigma, fc=fc, alpha=alpha).simulate(np.full(3000, v), dt)
        np.testing.assert_allclose(fa, expect, rtol=1e-9, atol=1e-12)
        assert np.all(np.diff(fa) >= -1e-15) and np.all(fa <= fc)
        assert fa[0] / xx[0] == pytest.approx(sigma, rel=3e-2)


def test_lugre_steady_state_and_presliding_stiffness_extract_E16():
    m = make_model("lugre", sigma0=1e5, sigma1=300.0, fv=0.02, fc=0.8, fs=0.95, vs=0.05)
    for v in (-1.0, -0.05, 0.01, 0.05, 0.3, 2.0):
        assert m.simulate(np.full(3000, v), 1e-3)[-1] == pytest.approx(m.steady_state(v), rel=1e-9)
    # presliding: tiny displacement x, F/x -> sigma0 (sigma1 = 0, no viscous)
    m0 = make_model("lugre", sigma0=1e5, fc=0.8, fs=0.95, vs=0.05)
    v, dt = 1e-6, 1e-4
    f = m0.simulate(np.full(10, v), dt)
    assert f[-1] / (10 * v * dt) == pytest.approx(1e5, rel=1e-3)
    # velocity-dependent micro-damping: sigma1(v) = sigma1 exp(-(v/vd)^2)
    md = make_model("lugre", sigma0=1e4, sigma1=50.0, fc=0.8, fs=0.95, vs=0.05, vd=0.01)
    md.reset()
    z0 = md.state[0]
    f1 = md.step(0.02, 1e-4)
    zn = md.state[0]
    a = 1e4 * 0.02 / (0.8 + 0.15 * math.exp(-((0.02 / 0.05) ** 2)))
    assert f1 == pytest.approx(1e4 * zn + 50 * math.exp(-4) * (0.02 - a * zn), rel=1e-9)
    assert z0 == 0.0


def _gms_run(path, n_per=4000):
    """Drive GMS-4 quasi-statically along the displacement waypoints ``path`` (v = 1e-4 rad/s)."""
    m = make_model("gms", **GMS4)
    m.reset()
    x, xs, fs = 0.0, [], []
    for tgt in path:
        dx = (tgt - x) / n_per
        dt = abs(dx) / 1e-4
        for _ in range(n_per):
            fs.append(m.step(dx / dt, dt))
            x += dx
            xs.append(x)
    return np.array(xs), np.array(fs), m


def test_gms_steady_sliding_virgin_curve_masing_wipeout_extract_E17():
    m = make_model("gms", **GMS4)
    # (a) steady sliding -> s(|v|) sgn(v): 0.8552 at v = 0.05
    assert m.simulate(np.full(3000, 0.05), 1e-3)[-1] == pytest.approx(0.8552, abs=1e-4)
    assert m.simulate(np.full(3000, -0.2), 1e-3)[-1] == pytest.approx(m.steady_state(-0.2), rel=1e-6)
    # (b) virgin curve sum_i min(k_i x, alpha_i Fs)
    xs, fs, _ = _gms_run([0.006])
    assert np.max(np.abs(fs - m.virgin_curve(xs))) < 1e-3
    # (c) Masing: after reversal at x_r the branch is F_r - 2 y((x_r - x)/2)
    xs, fs, _ = _gms_run([0.003, -0.001])
    n = 4000
    xr, fr = xs[n - 1], fs[n - 1]
    pred = fr - 2 * m.virgin_curve((xr - xs[n:]) / 2)
    assert np.max(np.abs(fs[n:] - pred)) < 2e-3
    assert fs[-1] == pytest.approx(-0.66500, abs=1e-3)
    # (d) wiping-out: the closed minor loop 0.0005 -> 0.002 -> 0.0005 is forgotten
    _, f1, m1 = _gms_run([0.003, 0.0005, 0.002, 0.0005, -0.001])
    _, f2, m2 = _gms_run([0.003, 0.0005, -0.001])
    assert f1[-1] == pytest.approx(f2[-1], abs=1e-9)
    np.testing.assert_allclose(m1.element_forces, m2.element_forces, atol=1e-9)


def test_gms_literal_plus_sign_of_eq3_diverges_extract_E17e():
    # dF/dt = sgn(v) C (alpha + F/s) as printed: unstable (dF'/dF = +C/s > 0); the library's sign is stable
    c, s, alpha, f, dt = 50.0, 0.9, 0.4, 0.36, 1e-3
    for _ in range(5000):
        f += dt * c * (alpha + f / s)
    assert f > 1e10
    m = make_model("gms", **GMS4)
    out = m.simulate(np.full(5000, 0.3), 1e-3)
    assert np.all(np.isfinite(out)) and out[-1] == pytest.approx(m.steady_state(0.3), rel=1e-6)


def _random_velocity(n, seed=1, amp=0.5):
    rng = np.random.default_rng(seed)
    w = rng.normal(size=n)
    a = math.exp(-2 * math.pi * 2.0 * 1e-3)  # 2 Hz first-order band limit
    v = np.empty(n)
    acc = 0.0
    for i in range(n):
        acc = a * acc + (1 - a) * w[i]
        v[i] = acc
    return amp * v / np.std(v)


def _reference_lugre(p, v, dt, sub):
    # independent reference: classical RK4 at dt/sub on the LuGre ODE with v held per sample
    s0, s1, fv, fc, fs, vs, de, _vd = p
    h = dt / sub
    z, out = 0.0, np.empty(v.size)
    for i, vi in enumerate(v):
        g = fc + (fs - fc) * math.exp(-((abs(vi) / vs) ** de))
        a = s0 * abs(vi) / g
        # RK4 on dz/dt = vi - a z is linear: one step multiplies by the RK4 amplification polynomial
        q = -a * h
        amp = 1 + q + q * q / 2 + q**3 / 6 + q**4 / 24
        zss = vi / a if a > 0 else None
        for _ in range(sub):
            z = zss + (z - zss) * amp if zss is not None else z + vi * h
        out[i] = s0 * z + s1 * (vi - a * z) + fv * vi
    return out


def _reference_gms(p, v, dt, sub):
    # independent reference: the GMS sketch of ABB M19-S paper A.2.4 (explicit Euler in slip) at dt/sub
    fc, fs, vs, de, c, fv = p[:6]
    n = (len(p) - 6) // 2
    k, al = p[6 : 6 + n], p[6 + n :]
    h = dt / sub
    f = np.zeros(n)
    stuck = np.ones(n, dtype=bool)
    out = np.empty(v.size)
    for i, vi in enumerate(v):
        s = fc + (fs - fc) * math.exp(-((abs(vi) / vs) ** de))
        sv = math.copysign(1.0, vi)
        for _ in range(sub):
            for j in range(n):
                if stuck[j]:
                    f[j] += k[j] * vi * h
                    if vi != 0 and f[j] * sv >= al[j] * s:
                        stuck[j] = False
                        f[j] = sv * al[j] * s
                elif vi == 0 or f[j] * vi < 0:
                    stuck[j] = True
                    f[j] += k[j] * vi * h
                else:
                    f[j] += c * (al[j] * sv - f[j] / s) * h
        out[i] = f.sum() + fv * vi
    return out


def test_stiff_bristles_stable_at_1ms_and_match_100x_finer_reference():
    dt, n = 1e-3, 60_000  # 60 s of random velocity
    v = _random_velocity(n)
    lug = make_model("lugre", sigma0=1e5, sigma1=50.0, fv=0.01, fc=0.8, fs=0.95, vs=0.05)
    f = lug.simulate(v, dt)
    assert np.all(np.isfinite(f))
    assert np.max(np.abs(f)) < 0.95 + 0.01 * np.max(np.abs(v)) + 50.0 * 2 * np.max(np.abs(v))
    assert np.max(np.abs(f[-10000:])) <= 1.05 * np.max(np.abs(f[:10000])) + 0.1  # no growth
    m = 6000  # compare the first 6 s against the 10 us reference (pure Python reference is slow)
    ref = _reference_lugre(lug.param_vector(), v[:m], dt, 100)
    err = np.sqrt(np.mean((f[:m] - ref) ** 2)) / np.sqrt(np.mean(ref**2))
    assert err < 0.01
    gms = make_model(
        "gms", fc=0.8, fs=0.95, vs=0.05, attraction=50.0, fv=0.01, k=[1e5] * 4, alpha=[0.1, 0.2, 0.3, 0.4]
    )
    g = gms.simulate(v, dt)
    assert np.all(np.isfinite(g)) and np.max(np.abs(g)) <= 0.95 + 0.01 * np.max(np.abs(v)) + 1e-9
    m = 1500
    ref = _reference_gms(gms.param_vector(), v[:m], dt, 100)
    err = np.sqrt(np.mean((g[:m] - ref) ** 2)) / np.sqrt(np.mean(ref**2))
    assert err < 0.01


@pytest.mark.parametrize("name", ["lugre", "gms", "dahl"])
def test_batch_compiled_equals_per_set_and_numpy_fallback(name):
    m = make_model(name, **EXAMPLES[name])
    rng = np.random.default_rng(3)
    base = m.param_vector()
    rows = []
    for _ in range(6):
        r = base.copy()
        cand = m.from_param_vector(r)
        if name == "gms":
            r[6:10] *= rng.uniform(0.5, 2.0, 4)
        else:
            r[0] *= rng.uniform(0.5, 2.0)
        cand = m.from_param_vector(r)
        rows.append(cand.param_vector())
    pm = np.array(rows)
    v = _random_velocity(3000, seed=5, amp=0.3)
    a = m.simulate_batch(pm, v, 1e-3)
    b = m.simulate_batch(pm, v, 1e-3, use_numba=False)
    c = np.array([m.from_param_vector(r).simulate(v, 1e-3) for r in pm])
    assert a.shape == (6, 3000)
    np.testing.assert_allclose(a, c, rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(b, a, rtol=1e-8, atol=1e-10)


def test_validation_errors_name_parameter_and_range():
    with pytest.raises(ParameterError, match=r"lugre\.sigma0 = -3 is out of range: must be > 0 \[N\*m/rad\]"):
        make_model("lugre", sigma0=-3.0, fc=0.8, fs=0.95, vs=0.05)
    with pytest.raises(
        ParameterError, match=r"stribeck\.fs = 0.2 is out of range: must be >= stribeck\.fc = 0.3"
    ):
        make_model("stribeck", fc=0.3, fs=0.2, vs=0.1)
    with pytest.raises(ParameterError, match=r"gms\.alpha sums to 0\.9.*must sum to 1"):
        make_model("gms", **{**GMS4, "alpha": [0.1, 0.2, 0.3, 0.3]})
    with pytest.raises(ParameterError, match=r"gms\.alpha has 3 elements but gms\.k has 4"):
        make_model("gms", **{**GMS4, "alpha": [0.2, 0.3, 0.5]})
    with pytest.raises(ParameterError, match=r"gms\.k\[1\] = -5 is out of range: must be > 0"):
        make_model("gms", **{**GMS4, "k": [190.0, -5.0, 142.5, 95.0]})
    with pytest.raises(ParameterError, match=r"gms\.k = 5.0 must be a list"):
        make_model("gms", **{**GMS4, "k": 5.0})
    with pytest.raises(ParameterError, match=r"coulomb: unknown parameter\(s\) 'fcc'"):
        make_model("coulomb", fcc=1.0)
    with pytest.raises(ParameterError, match=r"coulomb\.fc is missing"):
        make_model("coulomb")
    with pytest.raises(ParameterError, match=r"friction\.model = 'lugr' is not allowed: must be one of"):
        make_model("lugr")
    with pytest.raises(ParameterError, match=r"dahl\.fc = nan is not finite"):
        make_model("dahl", sigma=1.0, fc=float("nan"))
    with pytest.raises(ParameterError, match=r"missing 'model'"):
        model_from_config({"fc": 1.0})
    with pytest.raises(ParameterError, match=r"asymmetric\.base = 'foo' is not allowed"):
        make_model("asymmetric", base="foo", positive={}, negative={})
    with pytest.raises(ParameterError, match=r"polynomial\.neg has 2 elements but polynomial\.pos has 3"):
        make_model("polynomial", pos=[1.0, 0.0, 1.0], neg=[1.0, 0.0])
    m = make_model("lugre", **EXAMPLES["lugre"])
    pm = np.tile(m.param_vector(), (3, 1))
    pm[2, 0] = -1.0
    with pytest.raises(ParameterError, match=r"lugre\.sigma0 = -1 \(row 2\) is out of range"):
        m.simulate_batch(pm, np.zeros(5), 1e-3)
    with pytest.raises(ParameterError, match=r"has 3 columns: must have 8"):
        m.simulate_batch(pm[:, :3], np.zeros(5), 1e-3)


def test_chatterjee_gear_mesh_regression_A_T1_and_A_T3():
    r = spur_gear_dte()
    i = int(np.argmax(r["delta"]))
    assert r["delta"][i] == pytest.approx(0.58166, abs=2e-5)
    assert r["t"][i] == pytest.approx(3.626, abs=2e-3)
    assert r["delta"][-1] == pytest.approx(0.49968, abs=2e-5)
    assert r["delta_dot"].min() == pytest.approx(-0.0446, abs=1e-4)
    # analytic peak of d'' + d' + d = 0.5: 0.5 (1 + exp(-pi/sqrt(3))) = 0.5815 at 3.628 s
    assert r["delta"][i] == pytest.approx(0.5 * (1 + math.exp(-math.pi / math.sqrt(3))), abs=2e-3)
    m = spur_gear_dte(modified=True)
    assert np.all(np.isfinite(m["delta"]))
    assert m["delta"][-1] == pytest.approx(39.37, rel=0.01)
    assert m["K"].min() == pytest.approx(5.93, abs=0.01) and m["K"].max() == pytest.approx(65.05, abs=0.01)
