"""Issue 17 items 2 and 4: the controller's feedforward of the identified joint load (section load)
and of the learned residual (section residual)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from friction_ros.core.control.controller import CompensatingController, controller_from_ros_parameters
from friction_ros.core.friction.joint_load import JointLoad
from friction_ros.core.friction.learned_residual import LearnedResidual, feature_names, feature_settings
from friction_ros.core.harness import run_closed_loop
from friction_ros.core.presets import load_preset
from friction_ros.core.validation import ParameterError

PD = {"p": 200.0, "d": 0.15}
CV = {"model": "coulomb_viscous", "fc": 0.8, "fv": 0.01}
LOAD = {
    "gravity": 1.5,
    "gravity_phase": 0.4,
    "offset": 0.2,
    "spring": 0.7,
    "load_friction": 0.05,
    "ripple_period": 0.5,
    "ripple_cos": [0.03, 0.01],
    "ripple_sin": [-0.02, 0.005],
    "eps": 0.01,
}
SINE = {"type": "sinusoid", "amplitude": 0.2, "frequency": 0.5}


def _ctrl(load=None, source="feedforward", gain=1.0, **extra):
    cfg = {"mode": "pid", "pid": PD, "inertia": 0.0012, **extra}
    cfg["friction"] = {"model": CV, "source": source, "gain": gain}
    if load is not None:
        cfg["load"] = load
    return CompensatingController(cfg)


def _tau_load(q):
    return LOAD["gravity"] * math.sin(q + LOAD["gravity_phase"]) + LOAD["offset"] + LOAD["spring"] * q


def _load_and_position(res):
    """(load_feedforward[k], the measured position it was computed from) for k >= 1: the harness
    records the measurement after each period's step, which the next period's command uses."""
    return res.terms["load_feedforward"][1:], res.position[:-1]


def test_load_term_is_joint_load_torque_at_the_compensation_velocity():
    """feedforward: tau_L = JointLoad.torque_scalar(q_measured, v_ref, a_ref, J_hat); feedback: the
    measured velocity; blended: both with the blend weights; the gain scales the friction part only."""
    jl = JointLoad(**LOAD)
    q, vm, (rp, rv, ra) = 0.31, -0.004, (0.3, 0.02, 1.5)
    c = _ctrl(LOAD)
    t = c.compute(0.0, (rp, rv, ra), (q, vm), 1e-3)
    assert t.load_feedforward == pytest.approx(jl.torque_scalar(q, rv, ra, 0.0012), rel=1e-14)
    tl = _tau_load(q)
    fr = 0.05 * abs(tl + 0.0012 * ra) + sum(
        c_ * math.cos((k + 1) * 4 * math.pi * q) + s_ * math.sin((k + 1) * 4 * math.pi * q)
        for k, (c_, s_) in enumerate(zip(LOAD["ripple_cos"], LOAD["ripple_sin"]))
    )
    assert t.load_feedforward == pytest.approx(tl + 1.0 * fr, rel=1e-12)  # v_ref / eps = 2: sgn = 1
    fb = _ctrl(LOAD, source="feedback").compute(0.0, (rp, rv, ra), (q, vm), 1e-3)
    assert fb.load_feedforward == pytest.approx(tl - 0.4 * fr, rel=1e-12)  # v_meas / eps = -0.4
    bl = _ctrl(LOAD, source="blended", gain=0.5).compute(0.0, (rp, rv, ra), (q, vm), 1e-3)
    assert bl.load_feedforward == pytest.approx(tl + 0.5 * (0.5 * 1.0 + 0.5 * -0.4) * fr, rel=1e-12)
    half = _ctrl(LOAD, gain=0.5).compute(0.0, (rp, rv, ra), (q, vm), 1e-3)
    assert half.load_feedforward == pytest.approx(tl + 0.5 * fr, rel=1e-12)
    for off in (_ctrl(LOAD, source="none"), _ctrl(LOAD, gain=0.0)):
        assert off.compute(0.0, (rp, rv, ra), (q, vm), 1e-3).load_feedforward == pytest.approx(tl, rel=1e-14)
    # the command carries it: the same controller without the load section differs by tau_L exactly
    base = _ctrl().compute(0.0, (rp, rv, ra), (q, vm), 1e-3)
    assert t.command - base.command == pytest.approx(t.load_feedforward, rel=1e-12)


def test_zero_load_section_gives_bitwise_the_same_commands():
    """Defaults = no effect: an explicit all-zero section, or none, gives the same command sequence
    bit for bit, in every mode (PID, cascade, DNPF, sliding mode; feedback and blended sources)."""
    zero = {k: (0.0 if not isinstance(v, list) else []) for k, v in LOAD.items()}
    zero.update(ripple_period=2 * math.pi, eps=1e-3)
    for mode, source in (
        ("pid", "feedforward"),
        ("pid", "feedback"),
        ("cascade", "blended"),
        ("dnpf", "feedforward"),
        ("sliding_mode", "none"),
    ):
        cfgs = [
            {"mode": mode, "pid": PD, "load_feedforward": 0.1, "friction": {"model": CV, "source": source}},
        ]
        cfgs.append({**cfgs[0], "load": zero})
        cfgs.append({**cfgs[0], "load": {"ripple_cos": [0.0], "ripple_sin": [0.0], "eps": 0.5}})
        runs = [run_closed_loop("abb_m19s", c, SINE, 0.5, 1e-3, record_terms=True) for c in cfgs]
        for r in runs[1:]:
            assert np.array_equal(r.torque, runs[0].torque), mode
            assert not np.any(r.terms["load_feedforward"])


def test_gravity_feedforward_holds_a_pendulum_against_gravity():
    """A pendulum J qdd = u - m g l sin(q + phi) - fc sgn(v) - b v under PD: without the load term the
    joint sags by ~ m g l sin(q + phi) / Kp; with it the error is the friction's dead band only."""
    J, mgl, phi, fc, b = 0.05, 3.0, 0.3, 0.05, 0.02
    load = {"gravity": mgl, "gravity_phase": phi}

    def run(load_section, ref):
        pd = {"p": 60.0, "d": 1.0}
        c = CompensatingController(
            {"mode": "pid", "pid": pd, "inertia": J, "feedforward_gain": b, "load": load_section}
        )
        q, v, dt, errs = 0.0, 0.0, 1e-3, []
        for k in range(4000):
            t = k * dt
            r = ref(t)
            u = c.update(t, r, (q, v), dt)
            for _ in range(10):  # semi-implicit Euler, 0.1 ms
                tau = u - mgl * math.sin(q + phi) - b * v
                if abs(v) < 1e-6 and abs(tau) <= fc:
                    v = 0.0
                else:
                    v += 1e-4 * (tau - fc * math.copysign(1.0, v if v else tau)) / J
                q += 1e-4 * v
            errs.append(r[0] - q)
        return np.asarray(errs)

    def hold(t):
        return (0.8, 0.0, 0.0)

    def sine(t):
        w = 2 * math.pi * 0.5
        return (0.8 * math.sin(w * t), 0.8 * w * math.cos(w * t), -0.8 * w * w * math.sin(w * t))

    e0, e1 = run(None, hold), run(load, hold)
    # without: the static sag mgl sin(1.1) / Kp = 44.6 mrad (minus what Coulomb friction holds)
    assert abs(e0[-1]) > 0.04
    assert abs(e1[-1]) < 1e-3 and abs(e1[-1]) < abs(e0[-1]) / 40
    s0, s1 = run(None, sine), run(load, sine)
    rms0, rms1 = (math.sqrt(np.mean(e[1000:] ** 2)) for e in (s0, s1))
    # measured: 24.0 -> 1.08 mrad RMS (what is left: Coulomb friction, uncompensated here)
    assert rms0 > 0.02 and rms1 < rms0 / 10, (rms0, rms1)


def test_gravity_and_spring_feedforward_on_the_servo_plant():
    """abb_m19s with a constant gravity load (plant.gravity_force, towards -q) and a spring
    (plant.load_stiffness): the offset + spring feedforward removes most of the tracking error."""
    preset = load_preset("abb_m19s").override({"plant": {"gravity_force": 2.0, "load_stiffness": 3.0}})
    base = {"mode": "pid", "pid": PD, "inertia": 0.0012, "friction": {"model": CV, "source": "feedforward"}}
    without = run_closed_loop(preset, base, SINE, 3.0, 1e-3, record_terms=True)
    with_load = run_closed_loop(
        preset, {**base, "load": {"offset": 2.0, "spring": 3.0}}, SINE, 3.0, 1e-3, record_terms=True
    )
    e0, e1 = without.metrics["rms_error"], with_load.metrics["rms_error"]
    assert e0 > 5e-3  # ~ (2 + 3 q) / 200
    assert e1 < e0 / 5, (e0, e1)  # measured 10.8 -> 1.19 mrad RMS
    tau_l, q = _load_and_position(with_load)
    assert np.allclose(tau_l, 2.0 + 3.0 * q, rtol=0, atol=1e-12)


def test_fallback_keeps_the_load_and_drops_its_friction_part():
    """The limit-cycle fallback switches the friction part of tau_L off with the friction
    compensation; tau_load(q) (a load) stays."""
    bad = {"model": "stribeck", "fc": 0.8, "fs": 0.95, "vs": 0.05, "delta": 2.0}
    cfg = {"mode": "pid", "pid": PD, "inertia": 0.0012, "friction": {"model": bad, "source": "feedback"}}
    cfg["load"] = LOAD
    ctrl = CompensatingController(cfg)
    ref = {"type": "band_limited_random", "amplitude": 0.05, "cutoff": 1.0, "duration": 3.0, "seed": 1}
    res = run_closed_loop("abb_m19s", ctrl, ref, 3.0, 1e-3, record_terms=True)
    assert ctrl.compensation_fallback
    k = int(round(ctrl.limit_cycle.fired_at / 1e-3)) + 1
    tau_l, q = _load_and_position(res)
    assert np.allclose(tau_l[k:], np.vectorize(_tau_load)(q[k:]), rtol=0, atol=1e-12)
    assert np.all(res.terms["friction_feedback"][k + 1 :] == 0.0)
    friction_part = tau_l[:k] - np.vectorize(_tau_load)(q[:k])
    assert np.max(np.abs(friction_part)) > 0.01  # on before the fallback


def test_bad_load_values_are_refused_naming_the_key():
    for section, key in (
        ({"gravity_phase": 4.0}, "controller.load.gravity_phase = 4"),
        ({"load_friction": -0.1}, "controller.load.load_friction = -0.1"),
        ({"eps": 0.0}, "controller.load.eps = 0"),
        ({"gravity": math.nan}, "controller.load.gravity = nan"),
        ({"ripple_cos": [0.1], "ripple_sin": []}, "controller.load.ripple_sin has 0 values"),
        ({"gravitty": 1.0}, "gravitty"),
    ):
        with pytest.raises(ParameterError) as exc:
            _ctrl(section)
        text = str(exc.value)
        assert key in text and "\n" not in text, text
    # the ROS layout names it as the parameter file does
    with pytest.raises(ParameterError, match=r"^load\.gravity_phase = 4 "):
        controller_from_ros_parameters({"pid": PD, "load": {"gravity_phase": 4.0}})
    # a refused reconfiguration changes nothing
    c = _ctrl(LOAD)
    with pytest.raises(ParameterError):
        c.reconfigure({"load": {"eps": -1.0}})
    assert c.config()["load"]["eps"] == 0.01
    c.reconfigure({"load": {"gravity": 0.0}})
    assert c.config()["load"] == {**JointLoad(**LOAD).to_config(), "gravity": 0.0}


# ------------------------------------------------------------------------------ learned residual
def tiny_residual(seed: int = 3, clip: float = 0.3, use_command: bool = True) -> dict:
    """A residual section with random weights: an MLP [n, 4, 1] over the default features (and the
    command), clipped to +-clip N*m; training range +-5 per feature."""
    rng = np.random.default_rng(seed)
    s = feature_settings({"use_command": use_command})
    n = len(feature_names(s))
    return {
        "kind": "mlp",
        **s,
        "feature_mean": [0.0] * n,
        "feature_scale": [1.0] * n,
        "feature_low": [-5.0] * n,
        "feature_high": [5.0] * n,
        "layer_sizes": [n, 4, 1],
        "weights": rng.normal(0.0, 0.5, 4 * n + 4).tolist(),
        "biases": rng.normal(0.0, 0.1, 5).tolist(),
        "output_scale": 0.2,
        "clip_low": -clip,
        "clip_high": clip,
    }


def test_residual_section_adds_exactly_the_residual_step():
    """u gains residual.step(q_measured, v_measured, previous command), step by step: a twin
    LearnedResidual fed the same inputs gives learned_feedforward bit for bit."""
    section = tiny_residual()
    twin = LearnedResidual.from_config(section)
    base_cfg = {"mode": "pid", "pid": PD, "inertia": 0.0012, "friction": {"model": CV}}
    ctrl = CompensatingController({**base_cfg, "residual": section})
    base = CompensatingController(base_cfg)
    prev, nonzero = 0.0, 0
    for k in range(400):
        t = k * 1e-3
        ref = (0.2 * math.sin(3 * t), 0.6 * math.cos(3 * t), -1.8 * math.sin(3 * t))
        meas = (ref[0] - 0.01 * math.sin(17 * t), ref[1] + 0.05 * math.cos(11 * t))
        tm = ctrl.compute(t, ref, meas, 1e-3)
        tb = base.compute(t, ref, meas, 1e-3)
        r = twin.step(meas[0], meas[1], prev)
        assert tm.learned_feedforward == r
        assert tm.command_unlimited - tb.command_unlimited == pytest.approx(r, abs=1e-12)
        assert abs(r) <= 0.3
        nonzero += r != 0.0
        prev = tm.command
    assert nonzero == 400
    assert ctrl.config()["residual"]["kind"] == "mlp"
    # after reset the history restarts: the same first value as a fresh map
    ctrl.reset()
    first = ctrl.compute(0.0, (0.0, 0.0, 0.0), (0.0, 0.0), 1e-3).learned_feedforward
    assert first == LearnedResidual.from_config(section).step(0.0, 0.0, 0.0)


def test_residual_follows_the_gain_the_source_and_the_fallback():
    section = tiny_residual()
    r0 = LearnedResidual.from_config(section).step(0.05, 0.1, 0.0)
    assert r0 != 0.0

    def first(source="feedforward", gain=1.0):
        cfg = {"mode": "pid", "pid": PD, "friction": {"model": CV, "source": source, "gain": gain}}
        c = CompensatingController({**cfg, "residual": section})
        return c, c.compute(0.0, (0.0, 0.0, 0.0), (0.05, 0.1), 1e-3).learned_feedforward

    assert first()[1] == r0
    assert first(gain=0.5)[1] == 0.5 * r0
    assert first(source="none")[1] == 0.0 and first(gain=0.0)[1] == 0.0
    c, _ = first()
    assert c.watch.feedback_path  # the residual is inside the loop: the limit-cycle detector watches it
    c.compensation_fallback = True
    assert c.compute(1e-3, (0.0, 0.0, 0.0), (0.05, 0.1), 1e-3).learned_feedforward == 0.0


def test_nonfinite_residual_gives_zero_and_is_counted_once():
    section = tiny_residual()
    ctrl = CompensatingController({"mode": "pid", "pid": PD, "residual": section})
    calls = iter([0.1, math.nan, math.inf, 0.2])
    ctrl.residual.residual.step = lambda q, v, u: next(calls)
    out = [ctrl.compute(k * 1e-3, (0.0, 0.0, 0.0), (0.0, 0.0), 1e-3) for k in range(4)]
    assert [t.learned_feedforward for t in out] == [0.1, 0.0, 0.0, 0.2]
    assert all(math.isfinite(t.command) for t in out)
    assert ctrl.residual_nonfinite == 2
    assert ctrl.residual_note.startswith("learned residual returned nan at t = 0.001 s")


def test_residual_kind_none_is_bitwise_the_old_controller_and_bad_values_are_named():
    cfg = {"mode": "pid", "pid": PD, "friction": {"model": CV, "source": "feedback", "gain": 0.95}}
    a = run_closed_loop("abb_m19s", cfg, SINE, 0.5, 1e-3)
    b = run_closed_loop("abb_m19s", {**cfg, "residual": {"kind": "none", "fade": 0.5}}, SINE, 0.5, 1e-3)
    assert np.array_equal(a.torque, b.torque)
    assert CompensatingController(cfg).residual is None
    bad = tiny_residual()
    for change, key in (
        ({"fade": -1.0}, "controller.residual.fade = -1"),
        ({"layer_sizes": [3, 4, 1]}, "controller.residual.layer_sizes = [3, 4, 1]"),
        ({"weights": [0.1]}, "controller.residual.weights has 1 values"),
        ({"kind": "gpt"}, "controller.residual.kind = 'gpt'"),
    ):
        with pytest.raises(ParameterError) as exc:
            CompensatingController({**cfg, "residual": {**bad, **change}})
        assert key in str(exc.value) and "\n" not in str(exc.value), str(exc.value)
    with pytest.raises(ParameterError, match=r"^residual\.fade = -1 "):
        controller_from_ros_parameters({"pid": PD, "residual": {**bad, "fade": -1.0}})


def test_fitted_parameter_document_feeds_the_controller():
    """friction-fit's document (export.parameter_document with load and residual, through YAML)
    builds the node's controller with both terms: the interface between fitter and controller."""
    import yaml

    from friction_ros.core.identification.report.export import parameter_document

    load = JointLoad(**LOAD).to_config()
    residual = LearnedResidual.from_config(tiny_residual()).to_config()
    doc = parameter_document(CV, 0.0012, load=load, residual=residual)
    values = yaml.safe_load(yaml.safe_dump(doc))["compensating_controller"]["ros__parameters"]
    ctrl, _ = controller_from_ros_parameters(values)
    t = ctrl.compute(0.0, (0.3, 0.02, 1.5), (0.31, -0.004), 1e-3)
    assert t.load_feedforward == pytest.approx(
        JointLoad(**LOAD).torque_scalar(0.31, 0.02, 1.5, 0.0012), rel=1e-14
    )
    assert t.learned_feedforward == LearnedResidual.from_config(tiny_residual()).step(0.31, -0.004, 0.0)


def test_learned_residual_follows_the_control_period():
    """A map trained on a 2 ms log keeps its filters' time constants in seconds in a 1 ms loop."""
    from friction_ros.core.control.load_compensation import LearnedFeedforward
    from friction_ros.core.friction.learned_residual import LearnedResidual

    cfg = {
        "kind": "mlp",
        "dt": 0.002,
        "position_input": "none",
        "velocity_time_constants": [0.05],
        "displacement_scales": [],
        "feature_mean": [0.0, 0.0, 0.0],
        "feature_scale": [1.0, 1.0, 1.0],
        "feature_low": [-10.0, -10.0, -10.0],
        "feature_high": [10.0, 10.0, 10.0],
        "layer_sizes": [3, 1, 1],
        "weights": [0.0, 1.0, 0.0, 1.0],  # output = tanh(the filtered velocity)
        "biases": [0.0, 0.0],
        "clip_low": -10.0,
        "clip_high": 10.0,
    }
    ff = LearnedFeedforward(LearnedResidual.from_config(cfg), 1.0)
    vel = [math.sin(0.05 * k) for k in range(200)]
    at_1ms = [ff.torque(0.0, v, 0.0, 0.001 * k, 0.001) for k, v in enumerate(vel)]
    ref = LearnedResidual.from_config({**cfg, "dt": 0.001})
    unmatched = LearnedResidual.from_config(cfg)
    assert ff.period == 0.001
    assert at_1ms == [ref.step(0.0, v, 0.0) for v in vel]
    assert max(abs(a - unmatched.step(0.0, v, 0.0)) for a, v in zip(at_1ms, vel)) > 0.05
