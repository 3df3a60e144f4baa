"""friction-fleet trend: friction coefficients of every joint of a fleet over time, normalised to a
reference temperature, with wear alarms.

    friction-fleet trend fleet.parquet --out trends/

Reads the fleet table written by ``friction-fleet fit`` (a Parquet file or dataset folder) and
writes ``<out>/report.md``, ``<out>/alarms.json``, ``<out>/trends.csv`` and ``<out>/plots/*.png``
(:mod:`friction_ros.core.fleet.trend_report`). Exit codes: 0 ok (alarms or not), 2 bad input (no
table, not a fleet table, no fitted run, bad option), 1 unexpected error.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path


def add_parser(subparsers) -> argparse.ArgumentParser:
    """Register ``trend`` on the ``friction-fleet`` subparsers."""
    from friction_ros.core.fleet.drift import DEFAULT_ARL0
    from friction_ros.core.fleet.trend import WEAR_COEFFICIENTS

    p = subparsers.add_parser(
        "trend",
        allow_abbrev=False,
        help="coefficient trends, temperature-normalised, and wear alarms of a fleet table",
        description=__doc__.splitlines()[0],
    )
    p.add_argument(
        "table", help="fleet table: a Parquet file or dataset folder written by friction-fleet fit"
    )
    p.add_argument(
        "--out", required=True, help="output folder (created): report.md, alarms.json, trends.csv, plots/"
    )
    p.add_argument(
        "--baseline-days",
        type=int,
        default=14,
        help="days from each joint's first run that define its healthy baseline (default 14)",
    )
    p.add_argument(
        "--reference-temperature",
        type=float,
        default=25.0,
        help="temperature the coefficients are normalised to [degC] (default 25)",
    )
    p.add_argument(
        "--arl",
        type=float,
        default=DEFAULT_ARL0,
        help="in-control runs between false alarms on one healthy coefficient (default %(default)g)",
    )
    p.add_argument(
        "--coefficients",
        default=",".join(WEAR_COEFFICIENTS),
        help="coefficients to watch, comma-separated (default %(default)s)",
    )
    p.set_defaults(func=main)
    return p


def _options(args):
    from friction_ros.core.fleet.trend import TrendOptions
    from friction_ros.core.validation import ParameterError, check_int, check_real

    coefs = tuple(c.strip() for c in args.coefficients.split(",") if c.strip())
    if not coefs:
        raise ParameterError("--coefficients is empty: name at least one, e.g. fc,fv")
    return TrendOptions(
        baseline_days=check_int("--baseline-days", args.baseline_days, 1, 3650),
        t_ref=check_real("--reference-temperature", args.reference_temperature, -50.0, 200.0, unit="degC"),
        arl0=check_real("--arl", args.arl, 10.0, 1e15),
        coefficients=coefs,
    )


def load_table(path):
    """The fleet table at ``path``; ParameterError (one line) when it is missing, not Parquet, lacks
    columns or has no row."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    from friction_ros.core.fleet.table import read_table
    from friction_ros.core.fleet.trend import check_columns
    from friction_ros.core.validation import ParameterError

    path = Path(path)
    if not path.exists():
        raise ParameterError(
            f"fleet table {path} does not exist: give the Parquet file or folder of friction-fleet fit --table"
        )
    parts = (
        [path] if path.is_file() else sorted(p for p in path.glob("*.parquet") if not p.name.startswith("."))
    )
    if not parts:
        raise ParameterError(
            f"fleet table {path} holds no .parquet file: give the table friction-fleet fit wrote"
        )
    try:
        check_columns(pq.read_schema(parts[0]).names)
        table = read_table(path)
    except (pa.ArrowException, OSError) as exc:
        raise ParameterError(
            f"fleet table {parts[0]} is not a readable Parquet table ({str(exc).splitlines()[0]})"
        ) from None
    if table.num_rows == 0:
        raise ParameterError(f"fleet table {path} has no row: fit runs into it first (friction-fleet fit)")
    return table


def main(args) -> int:
    """Run ``friction-fleet trend`` on parsed ``args``; returns the exit code."""
    from friction_ros.core.fleet.trend import analyse
    from friction_ros.core.fleet.trend_report import write_report
    from friction_ros.core.validation import ParameterError

    try:
        options = _options(args)
        out = Path(args.out)
        if out.exists() and not out.is_dir():
            raise ParameterError(f"--out {out} is a file: must be a folder (created if missing)")
        trends = analyse(load_table(args.table), options)
        files = write_report(trends, out, options)
    except ParameterError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    import json

    found = json.loads(files["alarms"].read_text())["alarms"]
    print(f"{len(trends)} joint(s), {len(found)} wear alarm(s); report: {files['report']}")
    for a in found:
        print(f"  {a['date']}  {a['robot']}/{a['joint']}  {a['coefficient']} {a['size_percent']:+.1f} %")
    return 0
