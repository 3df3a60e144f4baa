"""friction-fleet: friction of a whole fleet of robots over time.

friction-fleet trend fleet.parquet --out trends/    coefficient trends and wear alarms
"""

from __future__ import annotations

import argparse
import sys


def build_parser() -> argparse.ArgumentParser:
    from friction_ros.cli import fleet_trend

    ap = argparse.ArgumentParser(
        allow_abbrev=False, prog="friction-fleet", description=__doc__.splitlines()[0]
    )
    sub = ap.add_subparsers(dest="cmd", required=True)
    fleet_trend.add_parser(sub)
    return ap


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    return args.func(args)


if __name__ == "__main__":
    sys.exit(main())
