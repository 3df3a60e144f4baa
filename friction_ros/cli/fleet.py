"""friction-fleet: friction identification for a fleet of robots, on one machine or a Dask cluster.

Example::

    friction-fleet fit logs/ --table fleet.parquet --pattern "{robot}/{date:%Y-%m-%d}/{joint}.csv"
    friction-fleet fit logs/ --table fleet.parquet --scheduler tcp://10.0.0.5:8786

``fit`` finds every run (CSV logs, rosbag2 bags, .mcap files) under the folders, fits each joint of
each run as friction-fit does (quick options for short daily runs) and adds one row per run, joint
and model to the table (a folder of Parquet files: docs/fleet.md). Runs already in the table are
skipped. Exit codes: 0 ok, 2 bad input, 1 some runs failed (their rows say why).
"""

from __future__ import annotations

import argparse
import importlib
import sys

PROG = "friction-fleet"

# ---- other subcommands: a module listed here defines ``add_parser(subparsers)``, which registers
# ---- its subcommand and sets ``func(args) -> exit code`` (set_defaults); missing modules are skipped
EXTRA_SUBCOMMANDS = ("friction_ros.cli.fleet_trend",)


def add_fit_parser(sub) -> None:
    from friction_ros.core.fleet.run_fit import QUICK_OPTIONS

    q = QUICK_OPTIONS
    p = sub.add_parser("fit", help="fit every run under the folders and add the rows to the table")
    p.add_argument("roots", nargs="+", metavar="ROOT", help="folders (or single runs) holding the runs")
    p.add_argument(
        "--table", required=True, help="the fleet table: a folder of Parquet files (created if missing)"
    )
    p.add_argument(
        "--pattern",
        default=None,
        help="where robot, joint and time are in a run's path below ROOT, e.g. "
        "'{robot}/{date:%%Y-%%m-%%d}/{joint}.csv' (fields {robot} {joint} {date:FMT} {time:FMT}, * any text); "
        "a sidecar <run>.yaml or the bag's metadata take precedence",
    )
    p.add_argument("--workers", type=int, default=None, help="local Dask workers (default: one per core)")
    p.add_argument("--scheduler", default=None, help="address of a running Dask scheduler (tcp://host:8786)")
    p.add_argument(
        "--models", nargs="+", default=list(q["models"]), help=f"models (default {' '.join(q['models'])})"
    )
    p.add_argument(
        "--maxiter",
        type=int,
        default=q["maxiter"],
        help=f"global-search generations (default {q['maxiter']})",
    )
    p.add_argument(
        "--train-seconds",
        type=float,
        default=q["train_seconds"],
        help=f"training data per run [s] (default {q['train_seconds']:g})",
    )
    p.add_argument("--seed", type=int, default=q["seed"], help=f"random seed (default {q['seed']})")
    p.add_argument(
        "--joint-type",
        choices=["auto", "revolute", "prismatic"],
        default="auto",
        help="revolute (rad, N*m) or prismatic (m, N); auto: a run's sidecar, metadata or column names, else revolute",
    )
    p.add_argument(
        "--topic", default="/joint_states", help="JointState topic of bags (default /joint_states)"
    )
    p.add_argument(
        "--temperature-column",
        default=None,
        help="CSV temperature column [degC] (default: temperature, drive_temperature or winding_temperature)",
    )
    p.add_argument(
        "--temperature-topic",
        default=None,
        help="bag sensor_msgs/Temperature topic [degC] (default: the first of that type)",
    )
    p.add_argument(
        "--columns", default=None, metavar="ROLE=NAME,...", help="CSV columns, as friction-fit --columns"
    )
    p.add_argument("--time-scale", type=float, default=1.0, help="CSV time unit in seconds (default 1)")
    p.add_argument(
        "--refit-failed",
        action="store_true",
        help="fit again the runs whose rows in the table say they failed",
    )
    p.add_argument("--quiet", action="store_true", help="no progress output")
    p.set_defaults(func=main_fit)


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog=PROG, allow_abbrev=False, description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    add_fit_parser(sub)
    for name in EXTRA_SUBCOMMANDS:
        try:
            module = importlib.import_module(name)
        except ModuleNotFoundError as exc:
            if exc.name != name:
                raise
            continue
        module.add_parser(sub)
    return parser


def _fail(text: str) -> int:
    print(f"{PROG}: error: {text}", file=sys.stderr)
    return 2


def main_fit(args) -> int:
    from friction_ros.cli.fit import parse_columns
    from friction_ros.core.fleet import driver
    from friction_ros.core.fleet.discovery import discover
    from friction_ros.core.identification.fit.models import check_model_names
    from friction_ros.core.validation import ParameterError

    try:
        if args.workers is not None and args.workers < 1:
            raise ParameterError(f"--workers {args.workers}: must be >= 1")
        if args.workers is not None and args.scheduler:
            raise ParameterError(
                "--workers and --scheduler exclude each other: the scheduler has its own workers"
            )
        if args.maxiter < 1:
            raise ParameterError(f"--maxiter {args.maxiter}: must be >= 1")
        if not args.train_seconds > 0:
            raise ParameterError(f"--train-seconds {args.train_seconds}: must be > 0")
        if not args.time_scale > 0:
            raise ParameterError(f"--time-scale {args.time_scale}: must be > 0")
        models = check_model_names(args.models)
        table_path = driver.check_table_path(args.table)
        tasks, notes = discover(
            args.roots,
            args.pattern,
            joint_type=args.joint_type,
            topic=args.topic,
            temperature_column=args.temperature_column,
            temperature_topic=args.temperature_topic,
            columns=parse_columns(args.columns),
            time_scale=args.time_scale,
        )
    except ParameterError as exc:
        return _fail(str(exc).splitlines()[0])
    options = {
        "models": tuple(models),
        "maxiter": args.maxiter,
        "train_seconds": args.train_seconds,
        "seed": args.seed,
    }
    for n in notes:
        print(f"{PROG}: {n}", file=sys.stderr)
    progress = _Progress(quiet=args.quiet)
    try:
        res = driver.fit_fleet(
            tasks,
            table_path,
            workers=args.workers,
            scheduler=args.scheduler,
            options=options,
            refit_failed=args.refit_failed,
            on_start=progress.start,
            on_task=progress.task,
        )
    except ParameterError as exc:
        return _fail(str(exc).splitlines()[0])
    except KeyboardInterrupt:
        print(
            f"{PROG}: interrupted: the runs written so far are in {table_path}; run again to go on",
            file=sys.stderr,
        )
        return 130
    finally:
        progress.stop()
    rate = res.fitted + res.failed
    per_min = f", {60.0 * rate / res.seconds:.1f} runs/min" if rate and res.seconds > 0 else ""
    mem = (
        f", peak memory per worker {', '.join(f'{mb:.0f}' for mb in res.worker_peak_mb.values())} MB"
        if res.worker_peak_mb
        else ""
    )
    print(
        f"{PROG}: {res.fitted} fitted, {res.failed} failed, {res.skipped} already in the table "
        f"({res.seconds:.1f} s, {res.workers} workers{per_min}{mem}): {table_path}"
    )
    return 1 if res.failed else 0


class _Progress:
    """A rich progress bar on a terminal, else one plain line per run (on stderr)."""

    def __init__(self, quiet: bool = False):
        self.quiet = quiet
        self.bar = None
        self.job = None
        self.done = 0
        self.total = 0

    def start(self, todo: int, skipped: int) -> None:
        self.total = todo
        if self.quiet:
            return
        print(f"{PROG}: {todo} joint runs to fit, {skipped} already in the table", file=sys.stderr)
        if todo and sys.stderr.isatty():
            from rich.console import Console
            from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn

            self.bar = Progress(
                TextColumn("fitting"),
                BarColumn(),
                MofNCompleteColumn(),
                TimeElapsedColumn(),
                console=Console(stderr=True),
            )
            self.bar.start()
            self.job = self.bar.add_task("fit", total=todo)

    def task(self, task, rows, seconds: float) -> None:
        self.done += 1
        if self.quiet:
            return
        if self.bar is not None:
            self.bar.advance(self.job)
            return
        first = rows[0]
        rec = next((r for r in rows if r["recommended"]), None)
        what = (
            f"error: {first['error']}"
            if first["error"] and not first["model"]
            else f"{rec['model'] if rec else 'no model'}: {first['verdict']}"
        )
        when = task.run_time.isoformat() if task.run_time else "?"
        print(
            f"{PROG}: [{self.done}/{self.total}] {task.robot} {task.joint or '-'} {when}: {what} ({seconds:.1f} s)",
            file=sys.stderr,
        )

    def stop(self) -> None:
        if self.bar is not None:
            self.bar.stop()
            self.bar = None


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    return args.func(args)


if __name__ == "__main__":
    sys.exit(main())
