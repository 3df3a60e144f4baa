"""Benchmark: fleet wear alarms and friction-fleet fit throughput, end to end.

Run: .venv/bin/python bench/fleet.py --fleet 20x7x30     (robots x joints x days, one command)
     .venv/bin/python bench/fleet.py --quick              (about a minute)

``--fleet RxJxD`` (default 20x7x30, ``--runs-per-day`` 1): writes the synthetic fleet of
bench/_fleet_synth.py (CSV logs, 1 %/day Coulomb wear injected in one joint per 4 robots, truth.json)
into a temporary folder, fits it with ``friction-fleet fit``'s driver with 2 workers (all runs) and
with 1 worker (``--subset`` robots), runs ``friction-fleet trend``'s analysis and compares the
alarms with the truth: runs per minute (wall clock, and steady: first to last finished run), the
speed-up from 1 to 2 workers (steady rates), CPU seconds per run, peak memory per worker, total
time, detection delay (days from wear start to alarm), missed wear, false alarms. Every timing
carries the 1-minute load average before and after (a shared machine slows it down).

Table level (no fits; :func:`~friction_ros.core.fleet.synthetic.table_rows`, run-to-run scatter
as friction-fit's on a 10 s run): 60 days at 1 run a day and at 4 runs a day (the synthetic
default), several seeds, 5 worn joints per seed. Goals: every wear found within 5 days, no false
alarm, >= 140 runs/min with 2 workers, >= 1.8x from 1 to 2 workers.
"""

from __future__ import annotations

import argparse
import datetime as dt
import json
import os
import shutil
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import pyarrow as pa

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from _common import print_table, write_results  # noqa: E402
from _fleet_synth import PATTERN, write_fleet  # noqa: E402

from friction_ros.core.fleet.synthetic import ARM, fleet_plan, table_rows  # noqa: E402
from friction_ros.core.fleet.table import read_table, rows_to_table, same_rows  # noqa: E402
from friction_ros.core.fleet.trend import alarms, analyse  # noqa: E402

GOAL_DAYS = 5


def load() -> float:
    return round(os.getloadavg()[0], 2)


def score(trends, found: list[dict], wear, last_day: dt.date) -> dict:
    """Delays of the worn joints' alarms, wear missed (no alarm by ``last_day``), false alarms (an
    alarm on a healthy joint, or before its wear started), healthy series and their worst
    statistic / threshold."""
    worn = {(w.robot, w.joint): w for w in wear}
    delays, false_alarms, first = {}, [], {}
    for a in found:
        w = worn.get((a["robot"], a["joint"]))
        day = dt.date.fromisoformat(a["date"])
        if w is None or day < dt.date.fromisoformat(w.start_date):
            false_alarms.append(f"{a['robot']} {a['joint']} {a['coefficient']} {a['date']}")
        elif (w.robot, w.joint) not in first:
            first[(w.robot, w.joint)] = (day - dt.date.fromisoformat(w.start_date)).days
    delays = list(first.values())
    missed = [
        {
            "robot": w.robot,
            "joint": w.joint,
            "days_available": (last_day - dt.date.fromisoformat(w.start_date)).days,
        }
        for k, w in worn.items()
        if k not in first
    ]
    worst = 0.0
    for jt in trends:
        if (jt.robot, jt.joint) in worn:
            continue
        for c in jt.coefficients:
            worst = max(worst, float(np.nanmax(c.detection.statistic) / c.detection.design.h))
    return {
        "worn": len(worn),
        "delays_days": sorted(delays),
        "max_delay_days": max(delays) if delays else None,
        "within_goal": sum(d <= GOAL_DAYS for d in delays),
        "missed": missed,
        "false_alarms": false_alarms,
        "healthy_worst_statistic_over_threshold": round(worst, 3),
    }


def table_level(seeds, robots: int, runs_per_day: int, days: int = 60) -> dict:
    per_seed = []
    for seed in seeds:
        plan = fleet_plan(robots=robots, days=days, runs_per_day=runs_per_day, seed=seed, worn=5)
        t0 = time.perf_counter()
        trends = analyse(rows_to_table(table_rows(plan)))
        s = score(trends, alarms(trends), plan.wear, (plan.runs[-1].time).date())
        s["analysis_seconds"] = time.perf_counter() - t0
        per_seed.append(s)
    delays = [d for s in per_seed for d in s["delays_days"]]
    return {
        "robots": robots,
        "days": days,
        "runs_per_day": runs_per_day,
        "seeds": list(seeds),
        "worn": sum(s["worn"] for s in per_seed),
        "detection_delay_days": {"min": min(delays), "median": float(np.median(delays)), "max": max(delays)}
        if delays
        else None,
        "within_goal": sum(s["within_goal"] for s in per_seed),
        "missed": sum(len(s["missed"]) for s in per_seed),
        "false_alarms": sum(len(s["false_alarms"]) for s in per_seed),
        "healthy_worst_statistic_over_threshold": max(
            s["healthy_worst_statistic_over_threshold"] for s in per_seed
        ),
        "analysis_seconds_per_seed": float(np.mean([s["analysis_seconds"] for s in per_seed])),
    }


def fit(root: Path, table: Path, workers: int, robots: set[str] | None = None) -> dict:
    """friction-fleet fit's discovery and driver on ``root`` (only ``robots`` when given)."""
    from friction_ros.core.fleet.discovery import discover
    from friction_ros.core.fleet.driver import fit_fleet

    tasks, _ = discover([str(root)], PATTERN)
    if robots is not None:
        tasks = [t for t in tasks if t.robot in robots]
    done: list[float] = []
    before = load()
    cpu0 = time.process_time()
    t0 = time.perf_counter()
    res = fit_fleet(tasks, table, workers=workers, on_task=lambda *_: done.append(time.perf_counter() - t0))
    n = res.fitted + res.failed
    steady = 60.0 * (len(done) - 1) / (done[-1] - done[0]) if len(done) > 2 else float("nan")
    return {
        "workers": res.workers,
        "runs": n,
        "failed": res.failed,
        "seconds": res.seconds,
        "runs_per_minute": 60.0 * n / res.seconds,
        "steady_runs_per_minute": steady,
        "first_run_seconds": done[0] if done else None,
        "cpu_seconds_per_run": sum(res.worker_cpu_s.values()) / max(n, 1),
        # this process: the Dask scheduler and client, writing the table's Parquet files
        "driver_cpu_seconds_per_run": (time.process_time() - cpu0) / max(n, 1),
        "peak_mb_per_worker": [round(v, 1) for v in res.worker_peak_mb.values()],
        "load_average_before": before,
        "load_average_after": load(),
    }


def end_to_end(
    robots: int, joints: int, days: int, runs_per_day: int, subset: int, keep: Path | None
) -> dict:
    tmp = keep or Path(tempfile.mkdtemp(prefix="fleet_bench_"))
    try:
        t_all = time.perf_counter()
        first_wear = min(20, days - 10)
        plan = fleet_plan(
            robots=robots, days=days, runs_per_day=runs_per_day, seed=0, first_wear_day=first_wear,
            joints=ARM[:joints],
        )  # fmt: skip
        t0 = time.perf_counter()
        write_fleet(tmp / "runs", plan)
        out = {
            "fleet": f"{robots}x{joints}x{days}",
            "runs_per_day": runs_per_day,
            "runs": len(plan.runs),
            "write_seconds": time.perf_counter() - t0,
        }
        out["fit_2_workers"] = fit(tmp / "runs", tmp / "table_2", 2)
        names = set(plan.robots[:subset])
        out["fit_1_worker"] = fit(tmp / "runs", tmp / "table_1", 1, names)
        out["fit_1_worker"]["robots"] = len(names)
        r1, r2 = out["fit_1_worker"]["steady_runs_per_minute"], out["fit_2_workers"]["steady_runs_per_minute"]
        out["speedup_2_over_1"] = r2 / r1
        t2 = read_table(tmp / "table_2")
        sub = t2.filter(pa.array(np.isin(np.array(t2.column("robot").to_pylist()), sorted(names))))
        out["same_table_1_and_2_workers"] = same_rows(sub, read_table(tmp / "table_1"))
        out["minutes_for_4200_runs_at_2_worker_rate"] = 4200 / out["fit_2_workers"]["runs_per_minute"]
        t0 = time.perf_counter()
        trends = analyse(t2)
        found = alarms(trends)
        out["trend_seconds"] = time.perf_counter() - t0
        out["detection"] = score(trends, found, plan.wear, plan.runs[-1].time.date())
        out["models_trended"] = sorted({jt.model for jt in trends})
        out["total_seconds"] = time.perf_counter() - t_all
        return out
    finally:
        if keep is None:
            shutil.rmtree(tmp, ignore_errors=True)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--fleet", default="20x7x30", help="robots x joints (<= 7) x days (default 20x7x30)")
    ap.add_argument(
        "--runs-per-day", type=int, default=1, help="identification runs per joint and day (default 1)"
    )
    ap.add_argument("--subset", type=int, default=2, help="robots fitted with 1 worker (default 2)")
    ap.add_argument("--quick", action="store_true", help="1x7x26 fleet, 1 robot with 1 worker, fewer seeds")
    ap.add_argument("--keep", default=None, help="keep the runs and tables in this folder")
    a = ap.parse_args()
    spec = "1x7x26" if a.quick else a.fleet
    try:
        robots, joints, days = (int(x) for x in spec.lower().split("x"))
        if not (robots >= 1 and 1 <= joints <= len(ARM) and days >= 24):
            raise ValueError
    except ValueError:
        print(
            f"--fleet {spec}: must be ROBOTSxJOINTSxDAYS with joints 1-{len(ARM)} and days >= 24",
            file=sys.stderr,
        )
        return 2
    seeds = range(2) if a.quick else range(4)
    trobots = 6 if a.quick else 20
    figures = {
        "load_average_at_start": load(),
        "end_to_end": end_to_end(
            robots, joints, days, a.runs_per_day, 1 if a.quick else a.subset, Path(a.keep) if a.keep else None
        ),
        "table_level_1_run_per_day": table_level(seeds, trobots, 1),
        "table_level_4_runs_per_day": table_level(seeds, trobots, 4),
    }
    e = figures["end_to_end"]
    f1, f2, d = e["fit_1_worker"], e["fit_2_workers"], e["detection"]
    print_table(
        f"friction-fleet fit, {e['fleet']} fleet x {e['runs_per_day']} run/day (synthetic CSV, 12 s at 200 Hz)",
        ["workers", "runs", "wall [s]", "runs/min", "steady runs/min", "worker CPU s/run", "driver CPU s/run", "peak MB/worker", "load avg"],
        [
            [f["workers"], f["runs"], f["seconds"], f["runs_per_minute"], f["steady_runs_per_minute"],
             f["cpu_seconds_per_run"], f["driver_cpu_seconds_per_run"], "/".join(f"{m:.0f}" for m in f["peak_mb_per_worker"]),
             f"{f['load_average_before']}-{f['load_average_after']}"]
            for f in (f1, f2)
        ],
    )  # fmt: skip
    rows = [
        [f"fitted {e['fleet']}", e["runs_per_day"], d["worn"], d["delays_days"], len(d["missed"]), len(d["false_alarms"])]
    ]  # fmt: skip
    for key in ("table_level_1_run_per_day", "table_level_4_runs_per_day"):
        t = figures[key]
        dd = t["detection_delay_days"] or {}
        rows.append(
            [f"table level {t['robots']}x7x{t['days']}, {len(t['seeds'])} seeds", t["runs_per_day"], t["worn"],
             f"{dd.get('min')}-{dd.get('max')} (median {dd.get('median')})", t["missed"], t["false_alarms"]]
        )  # fmt: skip
    print_table(
        "Wear alarms (1 %/day on fc; goal: found within 5 days, no false alarm)",
        ["fleet", "runs/day", "worn", "delay [days]", "missed", "false alarms"],
        rows,
    )
    print(
        f"speed-up 1 -> 2 workers {e['speedup_2_over_1']:.2f}x; 4200 runs at the 2-worker rate: "
        f"{e['minutes_for_4200_runs_at_2_worker_rate']:.1f} min; total {e['total_seconds']:.0f} s"
    )
    cmd = "python bench/fleet.py " + (
        "--quick" if a.quick else f"--fleet {a.fleet} --runs-per-day {a.runs_per_day}"
    )
    write_results("fleet_quick" if a.quick else "fleet", figures, command=cmd)
    print(json.dumps(figures, indent=1, default=str)[:4000])
    return 0


if __name__ == "__main__":
    sys.exit(main())
