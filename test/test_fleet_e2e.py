"""friction-fleet end to end: a tiny synthetic CSV fleet with one worn joint -> ``friction-fleet fit``
(its own local Dask cluster, the fleet default models) -> ``friction-fleet trend`` -> the alarm
names the worn joint and no healthy one; the report files exist."""

from __future__ import annotations

import dataclasses
import json
import sys
from pathlib import Path

from friction_ros.cli.fleet import main
from friction_ros.core.fleet.synthetic import ARM, fleet_plan

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "bench"))
from _fleet_synth import PATTERN, write_fleet  # noqa: E402

BASELINE_DAYS = 3
WEAR_START = 2  # wear grows by RATE per whole day after this one: runs of day 3 on are worn
RATE = 20.0  # [%/day] far beyond the run-to-run scatter of a fitted fc (about 1-3 %)


def test_worn_joint_alarmed_healthy_not(tmp_path, capsys):
    plan = fleet_plan(robots=1, days=7, runs_per_day=4, seed=4, worn=1, joints=ARM[1:3])
    wear = dataclasses.replace(plan.wear[0], start_day=WEAR_START, rate_percent_per_day=RATE)
    plan.wear = [wear]
    write_fleet(tmp_path / "runs", plan, seconds=4.0)
    truth = json.loads((tmp_path / "runs" / "truth.json").read_text())
    assert [(w["joint"], w["rate_percent_per_day"]) for w in truth["wear"]] == [(wear.joint, RATE)]

    table = tmp_path / "fleet.parquet"
    rc = main(["fit", str(tmp_path / "runs"), "--table", str(table), "--pattern", PATTERN])
    out = capsys.readouterr().out
    assert rc == 0, out
    assert "56 fitted, 0 failed" in out and "peak memory per worker" in out

    trends = tmp_path / "trends"
    assert main(["trend", str(table), "--out", str(trends), "--baseline-days", str(BASELINE_DAYS)]) == 0
    alarms = json.loads((trends / "alarms.json").read_text())["alarms"]
    assert alarms, "the worn joint raised no alarm"
    assert {(a["robot"], a["joint"]) for a in alarms} == {(wear.robot, wear.joint)}
    first = min(a["date"] for a in alarms)
    assert wear.start_date <= first <= plan.runs[-1].time.date().isoformat()
    assert any(a["coefficient"] in ("fc", "fs") and a["size_percent"] > 10.0 for a in alarms)
    for name in ("report.md", "trends.csv", "plots/overview.png", f"plots/{wear.robot}.png"):
        assert (trends / name).stat().st_size > 0, name
    assert wear.joint in (trends / "report.md").read_text()
