"""Synthetic fleet as files: the identification runs of :func:`~friction_ros.core.fleet.synthetic.fleet_plan`
written as CSV logs for ``friction-fleet fit``, plus the truth file; and the table-level fleet.

    .venv/bin/python bench/_fleet_synth.py ROOT --robots 20 --days 30 --runs-per-day 1 [--seconds 12]
    .venv/bin/python bench/_fleet_synth.py ROOT --table fleet.parquet   (rows directly, no fits)

Layout (what ``friction-fleet fit`` discovers): ``ROOT/{robot}/{date}/{joint}-{HHMM}.csv`` with a
sidecar ``{joint}-{HHMM}.yaml`` (robot, joint, time in ISO 8601 UTC, joint_type), and
``ROOT/truth.json`` (the plan's size, seed and injected wear: robot, joint, coefficient, start_date,
rate). Path pattern for the fit: ``{robot}/{date:%Y-%m-%d}/{joint}-{time:%H%M}.csv``.

One run: ``seconds`` at 200 Hz of a multisine (0.1-2 Hz, the joint's stroke and peak speed;
:func:`~friction_ros.core.synthetic.logs.tables.scaled_sines`) followed exactly (a stiff position
loop, as the gauntlet's ball-screw axis), effort = J a + the project's ``coulomb_viscous`` friction
at the run's true fc, fv (:meth:`FleetPlan.truth`) + noise (3 % of fc), position on a 2^17-count
encoder (1 um scale on the track), velocity +- 0.5 % of the peak speed, a temperature column
(the run's temperature +- 0.2 degC). The same arguments give the same bytes.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from friction_ros.core.fleet.synthetic import FleetPlan, Run, fleet_plan, table_rows  # noqa: E402
from friction_ros.core.friction import make_model  # noqa: E402
from friction_ros.core.synthetic.logs.tables import quantize, scaled_sines  # noqa: E402

RATE_HZ = 200.0
PATTERN = "{robot}/{date:%Y-%m-%d}/{joint}-{time:%H%M}.csv"


def run_columns(plan: FleetPlan, run: Run, seconds: float, seed: int) -> dict[str, np.ndarray]:
    """CSV columns of one run (module docstring), seeded by ``seed``."""
    rng = np.random.default_rng(seed)
    j = run.joint
    truth = plan.truth(run)
    n = int(round(seconds * RATE_HZ))
    t = np.arange(n) / RATE_HZ
    q, v, a, _ = scaled_sines(rng, t, 0.1, 2.0, j.stroke, j.vmax, n=6)
    fric = make_model("coulomb_viscous", fc=truth["fc"], fv=truth["fv"])
    effort = truth["J"] * a + fric.torque(v) + 0.03 * truth["fc"] * rng.standard_normal(n)
    step = 1e-6 if j.joint_type == "prismatic" else 2 * math.pi / 2**17
    return {
        "time": t,
        "position": quantize(q, step),
        "velocity": v + 0.005 * j.vmax * rng.standard_normal(n),
        "effort": effort,
        "temperature": run.temperature + 0.2 * rng.standard_normal(n),
    }


def run_path(root: Path, run: Run) -> Path:
    return (
        root / run.robot / run.time.strftime("%Y-%m-%d") / f"{run.joint.name}-{run.time.strftime('%H%M')}.csv"
    )


def write_run(root: Path, plan: FleetPlan, run: Run, seconds: float, seed: int) -> Path:
    """Write one run's CSV and sidecar YAML; returns the CSV path."""
    cols = run_columns(plan, run, seconds, seed)
    path = run_path(root, run)
    path.parent.mkdir(parents=True, exist_ok=True)
    table = np.column_stack(list(cols.values()))
    with path.open("w") as f:
        f.write(",".join(cols) + "\n")
        np.savetxt(f, table, fmt="%.9g", delimiter=",")
    path.with_suffix(".yaml").write_text(
        f"robot: {run.robot}\njoint: {run.joint.name}\ntime: '{run.time.strftime('%Y-%m-%dT%H:%M:%SZ')}'\n"
        f"joint_type: {run.joint.joint_type}\n"
    )
    return path


def write_fleet(root, plan: FleetPlan, seconds: float = 12.0) -> list[Path]:
    """Every run of ``plan`` under ``root`` and ``root/truth.json``; returns the CSV paths."""
    root = Path(root)
    root.mkdir(parents=True, exist_ok=True)
    paths = [write_run(root, plan, r, seconds, plan.seed * 1_000_003 + i) for i, r in enumerate(plan.runs)]
    (root / "truth.json").write_text(json.dumps({**plan.truth_dict(), "pattern": PATTERN}, indent=2) + "\n")
    return paths


def write_table(path, plan: FleetPlan):
    """The table-level fleet of ``plan`` (no fits) as one Parquet file."""
    from friction_ros.core.fleet.table import rows_to_table
    from friction_ros.core.fleet.table import write_table as write

    return write(rows_to_table(table_rows(plan)), path)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("root", help="output folder (truth.json and the runs)")
    ap.add_argument("--robots", type=int, default=20)
    ap.add_argument("--days", type=int, default=30)
    ap.add_argument("--runs-per-day", type=int, default=1)
    ap.add_argument("--seconds", type=float, default=12.0)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--table", default=None, help="write the table-level fleet to this Parquet file instead")
    a = ap.parse_args(argv)
    plan = fleet_plan(robots=a.robots, days=a.days, runs_per_day=a.runs_per_day, seed=a.seed)
    if a.table:
        write_table(a.table, plan)
        Path(a.root).mkdir(parents=True, exist_ok=True)
        (Path(a.root) / "truth.json").write_text(json.dumps(plan.truth_dict(), indent=2) + "\n")
        print(f"wrote {a.table}: {len(plan.runs)} runs")
    else:
        paths = write_fleet(a.root, plan, a.seconds)
        print(f"wrote {len(paths)} runs under {a.root}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
