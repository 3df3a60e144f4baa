"""Benchmark: fleet wear alarms (table level, several seeds) and friction-fleet fit throughput.

Run: .venv/bin/python bench/fleet.py [--quick] [--fit]

Table level (no fits; :func:`~friction_ros.core.fleet.synthetic.table_rows`): 20 robots x 7 joints
x 60 days x 4 runs a day per seed (``--quick``: 6 robots, 3 seeds), wear of 1 %/day on fc injected
in 5 joints per seed: detection delay of each (days from wear start to alarm), false alarms on the
healthy coefficient series over 60 days, analysis time. Goals: every wear within 5 days, no false
alarm. ``--fit``: writes a CSV fleet (bench/fleet_synth.py; 2 robots x 7 joints x 3 days,
``--quick`` 1 day) and times ``friction-fleet fit`` with 1 and 2 workers: runs per minute, the
speed-up, and the 20 x 7 x 30 time extrapolated from the 2-worker rate.
"""

from __future__ import annotations

import argparse
import datetime as dt
import json
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from _common import print_table, write_results  # noqa: E402
from fleet_synth import PATTERN, write_fleet  # noqa: E402

from friction_ros.core.fleet.synthetic import fleet_plan, table_rows  # noqa: E402
from friction_ros.core.fleet.table import rows_to_table  # noqa: E402
from friction_ros.core.fleet.trend import alarms, analyse  # noqa: E402


def table_level(seeds, robots: int) -> dict:
    rows, delays, false_alarms, healthy_series, worst = [], [], 0, 0, 0.0
    for seed in seeds:
        plan = fleet_plan(robots=robots, days=60, runs_per_day=4, seed=seed, worn=5)
        table = rows_to_table(table_rows(plan))
        t0 = time.perf_counter()
        trends = analyse(table)
        seconds = time.perf_counter() - t0
        found = alarms(trends)
        worn = {(w.robot, w.joint): w for w in plan.wear}
        seed_delays, fa = [], 0
        for a in found:
            w = worn.get((a["robot"], a["joint"]))
            if w is not None and a["coefficient"] == w.coefficient:
                seed_delays.append(
                    (dt.date.fromisoformat(a["date"]) - dt.date.fromisoformat(w.start_date)).days
                )
            else:
                fa += 1
        missed = len(worn) - len(seed_delays)
        for jt in trends:
            for c in jt.coefficients:
                w = worn.get((jt.robot, jt.joint))
                if w is None or c.name != w.coefficient:
                    healthy_series += 1
                    worst = max(worst, float(c.detection.statistic.max() / c.detection.design.h))
        delays += seed_delays
        false_alarms += fa
        rows.append(
            [seed, robots * 7, len(worn), missed, max(seed_delays) if seed_delays else "-", fa, seconds]
        )
    print_table(
        f"Wear alarms, table level: {robots} robots x 7 joints x 60 days x 4 runs/day, 1 %/day wear on fc",
        ["seed", "joints", "worn", "missed", "max delay [days]", "false alarms", "analysis [s]"],
        rows,
    )
    return {
        "seeds": list(seeds),
        "robots": robots,
        "detection_delay_days": {"min": min(delays), "median": float(np.median(delays)), "max": max(delays)},
        "missed": sum(r[3] for r in rows),
        "false_alarms": false_alarms,
        "healthy_series": healthy_series,
        "healthy_worst_statistic_over_threshold": worst,
        "analysis_seconds_per_seed": float(np.mean([r[6] for r in rows])),
    }


def fit_throughput(days: int) -> dict:
    tmp = Path(tempfile.mkdtemp(prefix="fleet_bench_"))
    try:
        plan = fleet_plan(robots=2, days=days, runs_per_day=1, seed=0, worn=0)
        write_fleet(tmp / "runs", plan)
        out = {"runs": len(plan.runs)}
        rows = []
        for workers in (1, 2):
            table = tmp / f"table_{workers}"
            t0 = time.perf_counter()
            r = subprocess.run(
                [
                    sys.executable,
                    "-m",
                    "friction_ros.cli.fleet",
                    "fit",
                    str(tmp / "runs"),
                    "--table",
                    str(table),
                    "--pattern",
                    PATTERN,
                    "--workers",
                    str(workers),
                    "--quiet",
                ],
                capture_output=True,
                text=True,
                cwd=Path(__file__).resolve().parents[1],
            )
            seconds = time.perf_counter() - t0
            per_min = 60.0 * len(plan.runs) / seconds
            out[f"workers_{workers}"] = {"seconds": seconds, "runs_per_minute": per_min, "exit": r.returncode}
            rows.append([workers, len(plan.runs), seconds, per_min, r.returncode])
        out["speedup_2_over_1"] = out["workers_2"]["runs_per_minute"] / out["workers_1"]["runs_per_minute"]
        out["extrapolated_20x7x30_minutes"] = 20 * 7 * 30 / out["workers_2"]["runs_per_minute"]
        print_table(
            "friction-fleet fit on synthetic CSV runs (12 s, 200 Hz)",
            ["workers", "runs", "wall [s]", "runs/min", "exit"],
            rows,
        )
        return out
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="smaller fleet, fewer seeds")
    ap.add_argument("--fit", action="store_true", help="also time friction-fleet fit on CSV runs")
    a = ap.parse_args()
    figures = {"table_level": table_level(range(3) if a.quick else range(5), 6 if a.quick else 20)}
    if a.fit:
        figures["fit"] = fit_throughput(1 if a.quick else 3)
    write_results("fleet", figures, command="python bench/fleet.py" + " --quick" * a.quick + " --fit" * a.fit)
    print(json.dumps(figures, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
