"""friction-fit CLI and data preparation: outputs, clear one-line errors (exit code 2), loading."""

from __future__ import annotations

import dataclasses
import json
import math
import subprocess
import sys

import numpy as np
import pytest

from friction_ros.cli.fit import main
from friction_ros.core.experiment.events import END, START, Event
from friction_ros.core.identification.data.breakaway_detection import find_breakaways
from friction_ros.core.identification.data.plateau_detection import find_plateaus
from friction_ros.core.identification.data.records import ExcitationError, prepare
from friction_ros.core.identification.data.training_split import split
from friction_ros.core.identification.fit import learned, metrics
from friction_ros.core.synthetic import plant_runs
from friction_ros.core.synthetic.plant_runs import Record


def _record(t, pos, eff, events=None):
    z = np.zeros_like(t)
    return Record(t, pos, np.gradient(pos, t), eff, eff / 0.49, z, z, events or [])


@pytest.fixture(scope="module")
def small_bag(tmp_path_factory):
    rec = plant_runs.abb_m19s_excitation_experiment(12.0, low=0.05)
    return plant_runs.write_bag(tmp_path_factory.mktemp("cli") / "run", rec)


def test_cli_end_to_end(small_bag, tmp_path, capsys):
    out = tmp_path / "fit"
    rc = main(
        [
            str(small_bag),
            "--joint",
            "joint1",
            "--models",
            "coulomb",
            "dahl",
            "nusvr",
            "--out",
            str(out),
            "--quiet",
            "--no-plots",
            "--params-out",
            str(tmp_path / "p.yaml"),
        ]
    )
    text = capsys.readouterr().out
    assert rc == 0, text
    assert "recommended" in text and (tmp_path / "p.yaml").exists()
    assert (out / "summary.json").exists() and (out / "report.md").exists()


def _expect_error(argv, capsys, *words):
    rc = main(argv)
    err = capsys.readouterr().err
    assert rc == 2, err
    assert err.startswith("friction-fit: error:") and err.count("\n") == 1  # one line, no traceback
    for w in words:
        assert w in err, err
    return err


def test_bag_without_topic(small_bag, capsys):
    _expect_error(
        [str(small_bag), "--topic", "/arm/joint_states", "--quiet"],
        capsys,
        "no topic /arm/joint_states",
        "/joint_states",
    )


def test_missing_joint_and_bad_model(small_bag, capsys):
    _expect_error([str(small_bag), "--joint", "elbow", "--quiet"], capsys, "elbow", "joint1")
    _expect_error(
        [str(small_bag), "--joint", "joint1", "--models", "karnopp9", "--quiet"], capsys, "karnopp9"
    )
    _expect_error([str(small_bag), "--quiet"], capsys, "--joint")  # two joints on the topic


def test_bag_without_motion(tmp_path, capsys):
    t = np.arange(3000) * 1e-3
    bag = plant_runs.write_bag(tmp_path / "still", _record(t, np.zeros_like(t), 0.01 * np.ones_like(t)))
    _expect_error([str(bag), "--joint", "joint1", "--quiet"], capsys, "no motion", "plateaus")


def test_too_little_excitation(tmp_path, capsys):
    """One slow ramp in one direction (a conveyor): no negative motion, no reversals. A valid log:
    the fit proceeds (exit 0) and says what it cannot determine: the other direction, and the
    dynamic models, listed as not fitted with the reason and no figure."""
    t = np.arange(15000) * 1e-3
    pos = 0.2 * t
    bag = plant_runs.write_bag(tmp_path / "ramp", _record(t, pos, 0.8 * np.ones_like(t)))
    out = tmp_path / "f"
    rc = main([str(bag), "--joint", "joint1", "--quiet", "--no-plots", "--out", str(out)])
    text = capsys.readouterr().out
    assert rc == 0, text
    assert "positive direction only" in text and "reversals" in text
    s = json.loads((out / "summary.json").read_text())
    for name in ("lugre", "gms4"):
        assert s["models"][name]["status"] == "not fitted" and "reversals" in s["models"][name]["reason"]
        assert set(s["models"][name]["metrics"]) <= {"n_params"}


def test_bag_without_effort_needs_current(tmp_path, capsys):
    rec = plant_runs.abb_m19s_excitation_experiment(3.0)
    bag = plant_runs.write_bag(tmp_path / "noeff", rec, with_effort=False)
    _expect_error([str(bag), "--joint", "joint1", "--quiet"], capsys, "no effort", "--torque-constant")


def test_console_script_installed():
    out = subprocess.run(
        [sys.executable, "-m", "friction_ros.cli.fit", "--help"], capture_output=True, text=True
    )
    assert out.returncode == 0 and "--models" in out.stdout


# ------------------------------------------------------------------------------ data preparation
def test_prepare_time_alignment_current_and_derivatives():
    rng = np.random.default_rng(0)
    n = 4000
    t = np.arange(n) * 1e-3 + rng.uniform(-2e-4, 2e-4, n)  # jittered stamps, shuffled order
    pos_true = 0.3 * np.sin(2 * np.pi * 1.0 * t)
    q = 1.05e-4
    pos = np.floor(pos_true / q) * q
    cur = 0.5 * np.cos(2 * np.pi * t)
    perm = rng.permutation(n)
    d = prepare(
        t[perm],
        pos[perm],
        None,
        None,
        current=cur[perm],
        current_t=t[perm],
        torque_constant=0.49,
        gear_ratio=3.0,
    )
    assert abs(d.dt - 1e-3) < 1e-5 and abs(d.resolution - q) / q < 0.05
    v_true = 0.3 * 2 * np.pi * np.cos(2 * np.pi * (d.t + d.t0))
    inner = slice(100, -100)
    assert np.max(np.abs(d.velocity - v_true)[inner]) < 0.02
    assert np.allclose(
        d.torque[inner], (0.5 * 0.49 * 3.0 * np.cos(2 * np.pi * (d.t + d.t0)))[inner], atol=0.01
    )
    a_true = -0.3 * (2 * np.pi) ** 2 * np.sin(2 * np.pi * (d.t + d.t0))
    assert np.max(np.abs(d.acceleration - a_true)[inner]) < 0.5


def test_split_and_breakaway_detection():
    dt = 1e-3
    t = np.arange(14000) * dt
    tau = np.where(t < 1.0, 0.0, 0.1 * (t - 1.0))  # ramp 0.1 N*m/s from t = 1 s
    q = 1.05e-4
    # the joint leaves rest when the torque reaches 0.35 N*m (t = 4.5 s)
    pos = np.where(tau > 0.35, (t - 4.5) * 0.01, 0.0)
    pos = np.floor(pos / q) * q
    ev = [
        Event(1.0, "breakaway", "ramp+", 0, START, math.nan),
        Event(13.0, "breakaway", "ramp+", 0, END),
    ]
    d = prepare(t, pos, None, tau, events=ev)
    br = find_breakaways(d)
    assert len(br) == 1 and br[0].source == "events" and br[0].direction == 1
    assert abs(br[0].torque - 0.35) < 0.01
    tr, va = split(d, 10.0)
    assert tr.n == 10000 and va.n == 4000
    with pytest.raises(ExcitationError, match="no validation"):
        split(d, 14.0)


def test_automatic_plateaus_without_events():
    rec = plant_runs.plateau_experiment([0.05, 0.5], hold=1.5)
    d = prepare(rec.t, rec.position, rec.velocity, rec.effort)  # no events
    pl = find_plateaus(d)
    got = sorted(round(p.velocity, 2) for p in pl)
    assert got == [-0.5, -0.05, 0.05, 0.5], got
    assert all(p.source == "auto" for p in pl)


# ------------------------------------------------------------------------------ metrics and learned maps
def test_nmse_definition_and_recommendation():
    y = np.sin(np.linspace(0, 10, 1000))
    assert abs(metrics.nmse_percent(np.full_like(y, y.mean()), y) - 100.0) < 1e-9
    assert metrics.nmse_percent(y, y) == 0.0
    m = {
        "a": {"bic": -100.0, "nmse_percent": 1.0, "nmse_low_percent": 1.0, "n_params": 15},
        "b": {"bic": -99.0, "nmse_percent": 1.01, "nmse_low_percent": 1.01, "n_params": 9},
    }
    assert metrics.recommend(m) == "b"


def test_anfis_and_nusvr_per_direction():
    v = np.concatenate([np.geomspace(0.01, 2, 60), -np.geomspace(0.01, 2, 60)])
    f = (0.2 + 0.05 * np.exp(-((np.abs(v) / 0.1) ** 2)) + 0.02 * np.abs(v)) * np.sign(v)
    f[v < 0] *= 0.9  # asymmetric
    a = learned.fit_directional("anfis", v, f)
    s = learned.fit_directional("nusvr", v, f)
    # epsilon-completeness initialisation: both MFs 0.5 at the midpoint
    x = np.array([0.0, 1.0])
    wb, mu = learned.Anfis._wbar(np.array([0.5]), x, np.full(2, 1.0 / (2 * math.sqrt(2 * math.log(2)))))
    assert np.allclose(mu, 0.5)
    for mdl in (a, s):
        err = mdl.steady_state(v) - f
        assert np.sqrt(np.mean(err**2)) < 0.02
        assert mdl.steady_state(np.array([0.0]))[0] == 0.0


def test_fit_kernels_match_the_friction_library():
    """The normalised VarPro kernels reproduce the library's GMS and LuGre for the same coefficients."""
    from friction_ros.core.friction import make_model
    from friction_ros.core.identification.fit import kernels

    rng = np.random.default_rng(0)
    v = np.repeat(rng.normal(0, 0.05, 400), 5) + 0.02 * np.sin(np.arange(2000) * 0.01)
    dt = 1e-3
    g = dict(fc=0.8, fs=0.95, vs=0.05, delta=2.0, attraction=50.0, fv=0.0, k=[190.0, 95.0], alpha=[0.4, 0.6])
    lib = make_model("gms", **g).simulate(v, dt)
    x = np.array(g["alpha"]) * g["fs"] / np.array(g["k"])
    theta = np.array([g["fc"] / g["fs"], g["vs"], g["delta"], g["attraction"] / g["fs"], *x])
    ours = kernels.gms_features(theta, v, dt) @ (np.array(g["alpha"]) * g["fs"])
    assert np.max(np.abs(ours - lib)) < 1e-9
    lg = dict(sigma0=600.0, sigma1=0.3, fv=0.0, fc=0.8, fs=0.95, vs=0.05, delta=2.0)
    lib = make_model("lugre", **lg).simulate(v, dt)
    th = np.array([lg["fc"] / lg["fs"], lg["vs"], lg["delta"], lg["sigma0"] / lg["fs"]])
    ours = kernels.lugre_features(th, v, dt) @ np.array([lg["fs"], lg["sigma1"]])
    assert np.max(np.abs(ours - lib)) < 1e-9


def test_damped_gms_fit_kernel_matches_the_library_and_exports_sigma1():
    """gms<N>d: regressors G_i + s dG_i/dt (s = sigma1 / sum k) reproduce the library GMS with
    presliding damping sigma1; the Gram kernel agrees with the features; the exported config
    carries sigma1 = s sum k; gms<N> (undamped) is unchanged."""
    from friction_ros.core.friction import make_model
    from friction_ros.core.identification.fit import kernels
    from friction_ros.core.identification.fit.fit_registry import library_config
    from friction_ros.core.identification.fit.models import spec_for

    rng = np.random.default_rng(0)
    v = np.repeat(rng.normal(0, 0.05, 400), 5) + 0.02 * np.sin(np.arange(2000) * 0.01)
    dt = 1e-3
    g = dict(fc=0.8, fs=0.95, vs=0.05, delta=2.0, attraction=50.0, fv=0.0, k=[190.0, 95.0], alpha=[0.4, 0.6])
    sigma1 = 0.86
    lib = make_model("gms", **g, sigma1=sigma1).simulate(v, dt)
    x = np.array(g["alpha"]) * g["fs"] / np.array(g["k"])
    s = sigma1 / sum(g["k"])
    theta = np.array([g["fc"] / g["fs"], g["vs"], g["delta"], g["attraction"] / g["fs"], *x, s])
    beta = np.array(g["alpha"]) * g["fs"]
    ours = kernels.gms_features(theta, v, dt, True) @ beta
    assert np.max(np.abs(ours - lib)) < 1e-9
    spec = spec_for("gms2d")
    assert spec.name == "gms2d" and spec.damped and spec.nonlinear[-1] == "s_damp"
    assert not spec_for("gms2").damped and spec_for("gms_4_d").name == "gms4d"
    spec.mid_velocity = False
    a = np.gradient(v, dt)
    X = spec.design(theta, v, a, dt)
    tau = X @ np.array([*beta, 0.01, 0.0012])
    gram = spec.grams(theta[None, :], v, a, tau, dt)[0]
    Xt = np.column_stack([X, tau])
    assert np.allclose(gram, Xt.T @ Xt, rtol=1e-10, atol=1e-12)
    c = spec.coefficients(theta, np.array([*beta, 0.01, 0.0012]))
    assert c["k"] == pytest.approx(sorted(g["k"], reverse=True)) and c["sigma1"] == pytest.approx(sigma1)
    cfg = library_config(spec.name, c)
    assert cfg["sigma1"] == pytest.approx(sigma1)
    assert make_model("gms", **{k: w for k, w in cfg.items() if k != "model"})["sigma1"] == pytest.approx(
        sigma1
    )
    undamped = spec_for("gms2").coefficients(theta[:-1], np.array([*beta, 0.01, 0.0012]))
    assert "sigma1" not in undamped and "sigma1" not in library_config("gms2", undamped)


def test_a_truncated_bag_is_fitted_with_a_warning(small_bag, tmp_path, capsys):
    """What `friction-bag info` warns about, friction-fit says too (issue 15, item 9)."""
    import shutil

    cut = tmp_path / "cut"
    cut.mkdir()
    src = next(small_bag.glob("*.mcap"))
    data = src.read_bytes()
    (cut / src.name).write_bytes(data[: int(len(data) * 0.8)])
    shutil.copy(small_bag / "metadata.yaml", cut / "metadata.yaml")
    before = (cut / src.name).read_bytes()
    rc = main([str(cut), "--joint", "joint1", "--models", "coulomb", "--out", str(tmp_path / "f")])
    text = capsys.readouterr().out
    assert rc == 0, text
    assert "warning:" in text and "truncated" in text, text
    report = (tmp_path / "f" / "report.md").read_text()
    assert report.index("## Warnings") < report.index("## Data") and "truncated" in report
    assert (cut / src.name).read_bytes() == before  # the input is left alone


def test_positions_all_nan_are_fitted_from_the_velocity_field_and_said_so(tmp_path, capsys):
    """The report names the velocity source it used and knows no encoder resolution (item 10)."""
    rec = plant_runs.abb_m19s_excitation_experiment(12.0, low=0.05)
    rec = dataclasses.replace(rec, position=np.full_like(rec.position, np.nan))
    bag = plant_runs.write_bag(tmp_path / "nanpos", rec, extra_joint=None)
    rc = main([str(bag), "--models", "coulomb", "--out", str(tmp_path / "f"), "--no-plots", "--quiet"])
    text = capsys.readouterr().out
    assert rc == 0, text
    assert "no finite position" in text
    report = (tmp_path / "f" / "report.md").read_text()
    assert "velocity field" in report and "resolution unknown" in report
    assert "differentiation of the position" not in report


def test_a_model_that_explains_little_is_not_recommended_silently(tmp_path, capsys):
    """Torque that is pure noise: whatever wins says it explains little (validation NMSE > 30 %)."""
    rec = plant_runs.abb_m19s_excitation_experiment(12.0, low=0.05)
    rng = np.random.default_rng(0)
    noise = rng.normal(0.0, 1.0, rec.effort.shape)
    rec = dataclasses.replace(rec, effort=noise)
    bag = plant_runs.write_bag(tmp_path / "noise", rec, extra_joint=None)
    rc = main([str(bag), "--models", "coulomb", "--out", str(tmp_path / "f"), "--no-plots", "--quiet"])
    text = capsys.readouterr().out
    assert rc == 0, text
    assert "explains little" in text, text
    assert "explains little" in (tmp_path / "f" / "report.md").read_text()


def test_marked_plateaus_left_out_are_named_with_the_reason():
    """A plateau at the commanded speed and one where the joint stuck: the second is left out, and
    said so (the fit's warnings carry the line), never silently."""
    dt = 1e-3
    t = np.arange(0.0, 4.0, dt)
    v = np.where(t < 2.0, 0.5, 0.0)  # the second plateau: commanded 0.5, the joint does not move
    v = v + 1e-3 * np.sin(2 * np.pi * 7 * t)
    pos = np.cumsum(v) * dt
    tau = 0.3 * np.sign(v) + 0.05 * v
    ev = [
        Event(0.0, "plateau", "p1", 0, START, 0.5),
        Event(1.9, "plateau", "p1", 0, END, 0.5),
        Event(2.0, "plateau", "p2", 1, START, 0.5),
        Event(3.9, "plateau", "p2", 1, END, 0.5),
    ]
    d = prepare(t, pos, v, tau, events=ev)
    dropped: list[str] = []
    pl = find_plateaus(d, dropped=dropped)
    assert len(pl) == 1 and pl[0].velocity == pytest.approx(0.5, rel=1e-2)
    assert len(dropped) == 1 and dropped[0].startswith("plateau +0.5 (t 2.00-3.90 s): mean speed")
    assert "off the commanded speed" in dropped[0]


def test_the_safety_gate_uses_the_same_lags_as_the_demo_or_says_what_it_assumed():
    """The demo refused feedback on a bag whose README recipe (no --delay) enabled it: the gate's
    lags now come from --plant-preset when not given, and an assumed 0 is a warning."""
    from friction_ros.cli.fit import build_parser, gate_options
    from friction_ros.core.identification.fit.gating import preset_lags
    from friction_ros.core.presets import load_preset

    parse = build_parser().parse_args
    known = preset_lags(load_preset("abb_m19s"))
    assert gate_options(parse(["b", "--plant-preset", "abb_m19s"])) == known
    given = gate_options(parse(["b", "--plant-preset", "abb_m19s", "--delay", "0.004"]))
    assert given == {"current_lag": known["current_lag"], "delay": 0.004}
    bare = gate_options(parse(["b"]))
    assert bare["current_lag"] == 0.0 and bare["delay"] == 0.0
    assert "assumed --current-lag and --delay 0" in bare["assumed"]
    assert "assumed" not in gate_options(parse(["b", "--current-lag", "0", "--delay", "0"]))
