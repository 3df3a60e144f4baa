"""Fleet trends: temperature normalisation, the CUSUM wear alarm and its false-alarm design, the
report and alarms.json of friction-fleet trend, and its refusals of bad input."""

from __future__ import annotations

import datetime as dt
import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest

from friction_ros.cli.fleet import main as fleet_main
from friction_ros.core.fleet.drift import design, detect, siegmund_arl
from friction_ros.core.fleet.synthetic import fleet_plan, table_rows
from friction_ros.core.fleet.table import empty_table, rows_to_table, write_table
from friction_ros.core.fleet.temperature_law import fit_law
from friction_ros.core.fleet.trend import TrendOptions, alarms, analyse

ROOT = Path(__file__).resolve().parents[1]


def _table(**plan_kw) -> tuple[pa.Table, object]:
    plan = fleet_plan(**plan_kw)
    return rows_to_table(table_rows(plan)), plan


@pytest.mark.parametrize("name,truth_slope", [("fc", -0.004), ("fv", 0.02)])
def test_normalisation_recovers_reference_coefficient(name, truth_slope):
    rng = np.random.default_rng(7)
    t = rng.uniform(15.0, 45.0, 60)
    c_ref, rel = 3.0, 0.01
    if name == "fv":  # fv(T) = fv_ref exp(-k_v (T - 25))
        truth = c_ref * np.exp(-truth_slope * (t - 25.0))
    else:  # fc(T) = fc_ref (1 + a_c (T - 25))
        truth = c_ref * (1.0 + truth_slope * (t - 25.0))
    values = truth * (1.0 + rel * rng.standard_normal(t.size))
    law = fit_law(name, values, t, t_ref=25.0)
    se_ref = np.sqrt(law.cov[0][0]) * (law.c_ref if law.form == "exponential" else 1.0)
    assert abs(law.c_ref - c_ref) < 4 * se_ref
    expected_slope = -truth_slope if name == "fv" else truth_slope
    assert abs(law.slope_per_k - expected_slope) < 0.25 * abs(truth_slope)
    cn, se_n = law.normalise(values, np.full(t.size, rel * c_ref), t)
    # the raw values spread with temperature (>= 10 %); the normalised ones only by the noise
    assert np.std(values) / c_ref > 0.03
    assert np.std(cn) / c_ref < 1.5 * rel
    assert abs(np.mean(cn) - c_ref) < 3 * rel * c_ref / np.sqrt(t.size) + 2 * se_ref
    # propagated uncertainty: at least the run's own, larger far from T_ref
    far, near = np.argmax(np.abs(t - 25.0)), np.argmin(np.abs(t - 25.0))
    assert np.all(se_n >= rel * c_ref * 0.5)
    assert se_n[far] / (rel * c_ref) > se_n[near] / (rel * c_ref) - 1e-12


def test_no_temperature_term_without_temperature_spread():
    law = fit_law("fc", [1.0, 1.01, 0.99, 1.0, 1.02], [30.0, 30.5, 30.2, np.nan, 30.1])
    assert law.beta[1] == 0.0
    cn, _ = law.normalise([1.0, 1.0], [0.01, 0.01], [np.nan, 40.0])
    assert np.allclose(cn, 1.0)


def test_siegmund_design_matches_simulated_run_length():
    """With a baseline so long its estimates are exact, h for ARL0 = 400 gives ~400 runs to a false
    alarm on N(0, 1) data (Siegmund's approximation is within a few per cent)."""
    d = design(10**8, arl0=400.0)
    rng = np.random.default_rng(1)
    chains, steps = 3000, 4000
    s = np.zeros(chains)
    stop = np.full(chains, steps)
    for i in range(steps):
        s = np.maximum(0.0, s + rng.standard_normal(chains) - d.k)
        hit = (s > d.h) & (stop == steps)
        stop[hit] = i + 1
    assert 0.85 * 400 < np.mean(stop) < 1.15 * 400
    # a short baseline is guarded by a larger h
    assert design(20).h > design(200).h > design(10**6).h
    assert siegmund_arl(1.0, design(56).h) > 1e7


def test_detect_dates_and_sizes_a_step():
    rng = np.random.default_rng(3)
    day = np.repeat(np.arange(40), 4)
    v = 2.0 * (1 + 0.01 * rng.standard_normal(day.size))
    v[day >= 30] *= 1.05  # +5 % (5 sigma) from day 30
    det = detect(day, v, np.full(v.size, 0.02), day < 14)
    # 5 sigma clipped to 4: 3 per run over h = 12.2 -> the 5th run after the step (day 31)
    assert det.alarm is not None and day[det.alarm] == 31 and det.alarm == 124
    assert 3.0 < det.size_percent < 7.0
    assert day[det.start] >= 29


def test_injected_wear_found_within_5_days():
    table, plan = _table(robots=4, days=60, seed=11, worn=3)
    found = {(a["robot"], a["joint"]): a for a in alarms(analyse(table)) if a["coefficient"] == "fc"}
    assert len(plan.wear) == 3
    for w in plan.wear:
        a = found[(w.robot, w.joint)]
        delay = (dt.date.fromisoformat(a["date"]) - dt.date.fromisoformat(w.start_date)).days
        assert 0 <= delay <= 5, (w, a)
        # size: the truth's change on the alarm day (1 %/day), within the day's noise
        assert abs(a["size_percent"] - delay) < 2.0
        assert a["statistic"] > a["threshold"]


@pytest.mark.parametrize("seed", [21, 22, 23])
def test_no_alarm_on_healthy_joints(seed):
    table, plan = _table(robots=3, days=60, seed=seed, worn=0)
    trends = analyse(table)
    assert len(trends) == 3 * 7 and not plan.wear
    assert alarms(trends) == []
    # margin: the largest statistic of the healthy series stays well below the threshold
    worst = max(c.detection.statistic.max() / c.detection.design.h for jt in trends for c in jt.coefficients)
    assert worst < 1.0


def test_trend_report_and_alarms_json(tmp_path):
    table, plan = _table(robots=2, days=40, seed=5, worn=1, first_wear_day=25)
    path = write_table(table, tmp_path / "fleet.parquet")
    before = path.read_bytes()
    out = tmp_path / "trends"
    assert fleet_main(["trend", str(path), "--out", str(out)]) == 0
    assert path.read_bytes() == before
    doc = json.loads((out / "alarms.json").read_text())
    (w,) = plan.wear
    assert [(a["robot"], a["joint"], a["coefficient"]) for a in doc["alarms"]] == [(w.robot, w.joint, "fc")]
    a = doc["alarms"][0]
    assert set(a) >= {"robot", "joint", "coefficient", "date", "size_percent", "statistic"}
    assert dt.date.fromisoformat(a["date"]) >= dt.date.fromisoformat(w.start_date)
    report = (out / "report.md").read_text()
    assert f"| {a['date']} | {w.robot} | {w.joint} | fc |" in report
    for f in ["plots/overview.png", "plots/robot00.png", "plots/robot01.png"]:
        assert (out / f).read_bytes()[:4] == b"\x89PNG"
    lines = (out / "trends.csv").read_text().splitlines()
    assert len(lines) == 1 + 2 * 7 * 40 * 4 * 2  # robots x joints x days x runs x (fc, fv)


def _bad_tables(tmp: Path) -> dict[str, list[str]]:
    wrong = tmp / "wrong.parquet"
    pq.write_table(pa.table({"robot": ["r"], "value": [1.0]}), wrong)
    empty = write_table(empty_table(), tmp / "empty.parquet")
    text = tmp / "text.parquet"
    text.write_text("robot,joint\nr,j\n")
    (tmp / "nofiles").mkdir()
    good = write_table(_table(robots=1, days=3, runs_per_day=1)[0], tmp / "good.parquet")
    return {
        "missing": [str(tmp / "nope.parquet")],
        "wrong columns": [str(wrong)],
        "empty": [str(empty)],
        "not parquet": [str(text)],
        "empty folder": [str(tmp / "nofiles")],
        "baseline days": [str(good), "--baseline-days", "0"],
        "temperature": [str(good), "--reference-temperature", "nan"],
        "out is a file": [str(good), "--out", str(wrong)],
    }


def test_cli_refusals_exit_2_with_one_line(tmp_path, capsys):
    for case, args in _bad_tables(tmp_path).items():
        if "--out" not in args:
            args = [*args, "--out", str(tmp_path / "out")]
        assert fleet_main(["trend", *args]) == 2, case
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and err[0].startswith("error: "), (case, err)
    # the installed entry point's process: exit code 2, one line, no traceback
    r = subprocess.run(
        [
            sys.executable,
            "-m",
            "friction_ros.cli.fleet",
            "trend",
            str(tmp_path / "nope"),
            "--out",
            str(tmp_path / "o"),
        ],
        capture_output=True,
        text=True,
        cwd=ROOT,
        env={"PYTHONPATH": str(ROOT), "PATH": "/usr/bin:/bin"},
    )
    assert r.returncode == 2 and len(r.stderr.strip().splitlines()) == 1 and "does not exist" in r.stderr


def test_options_reach_the_analysis():
    table, _ = _table(robots=1, days=20, seed=2, worn=0)
    (jt,) = [
        t for t in analyse(table, TrendOptions(coefficients=("fv",), baseline_days=5)) if t.joint == "j1"
    ]
    assert [c.name for c in jt.coefficients] == ["fv"] and jt.model == "coulomb_viscous"
    assert int(jt.coefficients[0].baseline.sum()) == 5 * 4
