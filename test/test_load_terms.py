"""Load, gravity and position terms identified jointly with friction (issue 17): the realistic
synthetic joint is recovered, the real pendulum needs its gravity term, a poor fit is flagged."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
import yaml
from scipy.optimize import lsq_linear

from friction_ros.core.friction.joint_load import JointLoad
from friction_ros.core.identification.data.csv_loading import load_csv
from friction_ros.core.identification.data.records import prepare
from friction_ros.core.identification.fit.linsolve import solve_grams
from friction_ros.core.identification.fit.load_terms import LoadTerms, parse_terms
from friction_ros.core.identification.fit.pipeline import fit_records
from friction_ros.core.identification.report.export import fit_parameter_document
from friction_ros.core.identification.report.fit_logs import cross_validate_runs
from friction_ros.core.synthetic.realistic_joint import (
    JointTruth,
    pooled_measured_input_nmse_percent,
    realistic_runs,
)
from friction_ros.core.validation import ParameterError

DATA = Path(__file__).parent / "data" / "dfki_pendulum"
RIPPLE_PERIOD = 2.0 * math.pi / 100.0  # the synthetic joint's ripple: motor angle of its 100:1 gear


def test_free_sign_solver_equals_bounded_least_squares():
    """Free (either-sign) coefficients eliminated by the Schur complement give the same solution as
    a bounded least-squares solver, also when a non-negative coefficient sits on its bound."""
    rng = np.random.default_rng(1)
    for truth in ([1.0, -2.0, 0.5, -0.3, 2.0], [-0.4, -2.0, 0.5, 1.3, 2.0]):
        X = rng.normal(size=(400, 5))
        y = X @ np.array(truth) + 0.1 * rng.normal(size=400)
        free = np.array([False, True, False, True, False])
        G = np.hstack([X, y[:, None]])
        beta, sse = solve_grams((G.T @ G)[None], free)
        ref = lsq_linear(X, y, bounds=(np.where(free, -np.inf, 0.0), np.inf))
        assert np.allclose(beta[0], ref.x, atol=1e-6)
        assert sse[0] == pytest.approx(float(np.sum((X @ ref.x - y) ** 2)), rel=1e-6)


def test_parse_terms_and_bad_names():
    t = parse_terms("gravity,offset,ripple=4", ripple_period=0.5)
    assert t.gravity and t.offset and not t.spring and t.ripple == 4 and t.ripple_period == 0.5
    assert t.names[:3] == ["gravity_sin", "gravity_cos", "offset"] and len(t.names) == 11
    assert parse_terms("auto") == "auto" and parse_terms("none").empty
    for bad, word in (
        ("gravty", "gravty"),
        ("ripple=0", "1..20"),
        ("ripple=x", "integer"),
        ("offset=2", "only"),
    ):
        with pytest.raises(ParameterError, match=word):
            parse_terms(bad)


def test_joint_load_from_fitted_sine_and_cosine():
    """a sin q + b cos q = gravity sin(q + phase): the conversion and JointLoad agree pointwise."""
    t = LoadTerms(
        gravity=True, offset=True, spring=True, load_friction=True, ripple=1, ripple_period=0.3, eps=0.01
    )
    c = {"gravity_sin": 3.0, "gravity_cos": -1.2, "offset": 0.2, "spring": 0.4, "load_friction": 0.05}
    c.update(ripple_cos1=0.1, ripple_sin1=-0.05)
    jl = t.joint_load(c)
    q = np.linspace(-2, 2, 41)
    v = np.linspace(-0.5, 0.5, 41)
    beta = np.array([c[n] for n in t.names])
    tl = 3.0 * np.sin(q) - 1.2 * np.cos(q) + 0.2 + 0.4 * q
    assert np.allclose(jl.load_torque(q), tl, atol=1e-12)
    assert np.allclose(t.columns(q, v, tl) @ beta, tl + jl.friction(v, q, tl), atol=1e-12)
    assert np.allclose(JointLoad.from_config(jl.to_config()).torque(q, v), jl.torque(q, v), atol=1e-12)


@pytest.fixture(scope="module")
def realistic_fit():
    runs = realistic_runs(seed=0)
    recs = [prepare(r.stamp, r.position, r.velocity, r.effort, source=r.name) for r in runs]
    res = fit_records(
        recs,
        ["coulomb_viscous", "stribeck"],
        identifiability_check=False,
        ripple_period=RIPPLE_PERIOD,
        residual="none",
    )
    return runs, recs, res


def test_realistic_joint_recovered(realistic_fit):
    """Friction map within 5 %, load-dependent coefficient within 10 %, gravity within 2 %, validation
    NMSE within 1.5x of the noise floor: what the true model scores on the same validation samples
    from the same inputs every fitted model gets (velocity and acceleration differentiated from the
    logged 17-bit positions; with them the truth's sharp sgn(v) misjudges some reversals). The
    generator's own figure with the drive's velocity field and the true acceleration (0.12 %) is
    lower; the loader does not use a velocity field when positions exist."""
    runs, _, res = realistic_fit
    truth = JointTruth()
    assert res.recommended == "stribeck", res.recommended
    m = res.models["stribeck"]
    v = np.concatenate([-np.geomspace(0.4, 0.005, 60), np.geomspace(0.005, 0.4, 60)])
    ref = truth.friction_map(v)
    map_err = np.max(np.abs(m.steady_state(v) - ref)) / np.max(np.abs(ref))
    assert map_err < 0.05, map_err
    load = m.extra["load"]
    assert abs(load["gravity"] / truth.gravity - 1) < 0.02, load
    assert abs(load["gravity_phase"] - truth.gravity_phase) < 0.02, load
    assert abs(load["load_friction"] / truth.load_friction - 1) < 0.10, load
    assert abs(load["spring"] / truth.spring - 1) < 0.2, load
    # offset of the load and of the sensor add up (one constant)
    assert abs(load["offset"] - (truth.offset + truth.sensor_offset)) < 0.05, load
    assert len(load["ripple_cos"]) >= 1 and abs(load["ripple_cos"][0] - truth.ripple_cos[0]) < 0.03, load
    assert abs(m.coefficients["J"] / truth.J - 1) < 0.1, m.coefficients
    val = res.validation
    y = np.concatenate([r.torque for r in val])
    e = y - np.concatenate(
        [truth.torque(r.position, r.velocity, r.acceleration) + truth.sensor_offset for r in val]
    )
    floor = 100.0 * np.mean(e**2) / np.var(y)
    assert floor > pooled_measured_input_nmse_percent(runs)
    assert m.metrics["nmse_percent"] < 1.5 * floor, (m.metrics["nmse_percent"], floor)
    assert "gravity" in res.options["load_terms"] and "load_friction" in res.options["load_terms"]
    assert not res.options["verdict"]["explains_little"]


@pytest.mark.parametrize("seed", [2, 4])
def test_realistic_joint_recovered_on_other_seeds(seed):
    """The same recovery on other draws of the runs (seed 2 once traded 3 % of gravity against the
    spring when the reversal samples were fitted)."""
    truth = JointTruth()
    runs = realistic_runs(seed=seed)
    recs = [prepare(r.stamp, r.position, r.velocity, r.effort, source=r.name) for r in runs]
    res = fit_records(recs, ["stribeck"], identifiability_check=False, ripple_period=RIPPLE_PERIOD)
    m = res.models["stribeck"]
    v = np.concatenate([-np.geomspace(0.4, 0.005, 60), np.geomspace(0.005, 0.4, 60)])
    ref = truth.friction_map(v)
    assert np.max(np.abs(m.steady_state(v) - ref)) / np.max(np.abs(ref)) < 0.05
    load = m.extra["load"]
    assert abs(load["gravity"] / truth.gravity - 1) < 0.02, load
    assert abs(load["load_friction"] / truth.load_friction - 1) < 0.10, load


def test_realistic_joint_without_load_terms_is_flagged(realistic_fit):
    _, recs, _ = realistic_fit
    res = fit_records(recs, ["coulomb_viscous"], identifiability_check=False, load="none", residual="none")
    assert res.models["coulomb_viscous"].metrics["nmse_percent"] > 30
    v = res.options["verdict"]
    assert v["explains_little"] and "gravity" in v["suggestions"][0], v
    assert any("do not compensate" in w for w in res.warnings)


def test_parameter_file_carries_the_load_section(realistic_fit, tmp_path):
    _, _, res = realistic_fit
    doc = fit_parameter_document(res)
    sec = doc["compensating_controller"]["ros__parameters"]["load"]
    jl = JointLoad.from_config(sec)
    assert jl.gravity == pytest.approx(res.models["stribeck"].extra["load"]["gravity"])
    text = yaml.safe_dump(doc)
    assert yaml.safe_load(text)["compensating_controller"]["ros__parameters"]["load"][
        "ripple_period"
    ] == pytest.approx(RIPPLE_PERIOD)


def test_cross_validation_over_runs(realistic_fit):
    _, recs, _ = realistic_fit
    cv = cross_validate_runs(recs, ["coulomb_viscous"], ripple_period=RIPPLE_PERIOD, residual="none")
    assert [f["validation"] for f in cv["folds"]] == [r.meta["source"] for r in recs]
    nm = [f["nmse_percent"]["coulomb_viscous"] for f in cv["folds"]]
    assert all(0 < x < 30 for x in nm), nm
    with pytest.raises(ParameterError, match=">= 2 runs"):
        cross_validate_runs(recs[:1], ["coulomb_viscous"])


def test_pendulum_needs_its_gravity_term():
    """Real pendulum (DFKI, gravity compensation while moved by hand): the gravity term is chosen by
    validation (3.31 N*m, the commanded compensation); without it the fit explains nothing, and
    the report says gravity is what is missing."""
    rec = load_csv(DATA / "control_method_gravity_compensation_first12s.csv")
    res = fit_records(
        [rec], ["coulomb_viscous"], identifiability_check=False, train_seconds=5.0, residual="none"
    )
    assert "gravity" in res.options["load_terms"]
    load = res.models["coulomb_viscous"].extra["load"]
    assert load["gravity"] == pytest.approx(3.31, rel=0.02)
    assert res.models["coulomb_viscous"].metrics["nmse_percent"] < 2.0
    bare = fit_records(
        [rec], ["coulomb_viscous"], identifiability_check=False, train_seconds=5.0, load="none"
    )
    assert bare.models["coulomb_viscous"].metrics["nmse_percent"] > 100
    v = bare.options["verdict"]
    assert v["explains_little"] and v["suggestions"][0].startswith("gravity explains"), v
    assert "explains little" in v["text"] and "explains nothing" in v["text"]


def test_cli_load_option(tmp_path, capsys):
    from friction_ros.cli.fit import main

    src = DATA / "control_method_gravity_compensation_first12s.csv"
    before = src.read_bytes()
    out = tmp_path / "fit"
    args = [str(src), "--models", "coulomb_viscous", "--out", str(out), "--no-gate", "--no-plots", "--quiet"]
    assert main([*args, "--train-seconds", "5", "--load", "gravity", "--residual", "none"]) == 0
    doc = yaml.safe_load((out / "friction_params.yaml").read_text().split("\n", 1)[1])
    assert doc["compensating_controller"]["ros__parameters"]["load"]["gravity"] == pytest.approx(
        3.31, rel=0.02
    )
    report = (out / "report.md").read_text()
    assert "## Load, gravity and position terms" in report
    capsys.readouterr()
    assert main([*args, "--load", "gravity,wind"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "wind" in err[0] and "gravity" in err[0]
    assert src.read_bytes() == before


def test_csv_load_column_is_the_transmitted_torque(tmp_path):
    """A CSV ``load`` column (the torque the gear transmits, known to the user) is what the
    load-dependent friction uses: the record keeps it through the selection."""
    from friction_ros.core.identification.fit.load_terms import with_transmitted

    run = realistic_runs(duration=8.0, speeds=(0.3,), seed=2)[0]
    path = tmp_path / "log.csv"
    tr = run.true_load + JointTruth().J * run.true_acceleration
    rows = ["time,position,velocity,effort,load"] + [
        ",".join(repr(float(x)) for x in row)
        for row in zip(run.t, run.position, run.velocity, run.effort, tr)
    ]
    path.write_text("\n".join(rows) + "\n")
    rec = load_csv(path)
    assert rec.meta["transmitted_source"] == "column 'load'"
    assert np.allclose(rec.transmitted, np.interp(rec.t + rec.t0, run.t, tr), atol=1e-9)
    kept = with_transmitted([rec.slice(0, 100)], 5.0, JointLoad(gravity=100.0))[0]
    assert np.array_equal(kept.transmitted, rec.transmitted[:100])


def test_auto_load_terms_that_do_not_help_the_model_are_dropped():
    """The real pendulum's swing-up run (torque: a PD command, mostly noise): the linear backbone
    keeps gravity and spring, the recommended model validates worse with them, so the fit is
    repeated without load terms and says why."""
    rec = load_csv(DATA / "control_method_pd_system_identification.csv")
    res = fit_records([rec], ["coulomb_viscous"], identifiability_check=False, train_seconds=1.5)
    assert res.options["load_terms"] == "none"
    assert any("did not lower the validation NMSE" in w for w in res.warnings), res.warnings
    bare = fit_records(
        [rec], ["coulomb_viscous"], identifiability_check=False, train_seconds=1.5, load="none"
    )
    assert (
        res.models["coulomb_viscous"].metrics["nmse_percent"]
        == bare.models["coulomb_viscous"].metrics["nmse_percent"]
    )
    assert res.options["verdict"]["explains_little"]


def test_a_pendulum_log_fits_with_the_default_options(tmp_path):
    """A hand-moved real pendulum (torque = gravity compensation): the default ``--load auto`` picks
    gravity and the fit succeeds (the check that the terms help the recommended model used to fail
    outright when nothing could be fitted without them)."""
    import json

    from friction_ros.cli.fit import main

    out = tmp_path / "fit"
    code = main([str(DATA / "control_method_gravity_compensation_first12s.csv"), "--out", str(out)]
                + ["--models", "coulomb", "stribeck", "--residual", "none", "--no-plots", "--quiet"])  # fmt: skip
    assert code in (0, None)
    s = json.loads((out / "summary.json").read_text())
    assert "gravity" in s["options"]["load_terms"]
    assert s["recommended"] is not None
