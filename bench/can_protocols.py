"""drive_interface CPU per axis at 1 kHz for each registered drive protocol, side by side.

    .venv/bin/python bench/can_protocols.py [--duration 8] [--protocols odrive_cansimple,mit,cia402]

The measurement of ``bench/can.py`` (its ``run_rate``: the real ``drive_interface`` node in a child
process, ``drive_emulator`` with the abb_m19s plant in a process of its own on the ``friction_local``
bus, a PD controller over DDS in this process), repeated per protocol with 1 and 3 axes on one bus.
``node CPU % per axis`` is the node process's CPU time / wall time / axes. CiA 402 adds a SYNC per
period and sends its RPDO after it; ODrive and MIT answer each command with their own telemetry.
Shared 2-core machine: other processes' load shows up as faults and missed periods; rerun it quiet.
"""

from __future__ import annotations

import argparse
import importlib.util
import os
import sys
from pathlib import Path

_BENCH = Path(__file__).resolve().parent
sys.path[:] = [p for p in sys.path if Path(p or ".").resolve() != _BENCH]  # python-can is "can"


def _load(name: str, file: str):
    spec = importlib.util.spec_from_file_location(name, _BENCH / file)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0], allow_abbrev=False)
    ap.add_argument("--duration", type=float, default=8.0, help="seconds per row (> 0)")
    ap.add_argument("--protocols", default="odrive_cansimple,mit,cia402", help="comma-separated")
    ap.add_argument("--axes", default="1,3", help="axes on one bus per row, comma-separated")
    a = ap.parse_args()
    if a.duration <= 0:
        print(f"error: --duration {a.duration:g}: must be > 0 s", file=sys.stderr)
        return 2
    os.environ.setdefault("ROS_DOMAIN_ID", str(os.getpid() % 100 + 1))
    os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    common = _load("_bench_common", "_common.py")
    rows, figures = [], {}
    for protocol in a.protocols.split(","):
        os.environ["FRICTION_BENCH_PROTOCOL"] = protocol  # the child (node + emulator) reads it
        can_bench = _load("_bench_can", "can.py")
        for axes in map(int, a.axes.split(",")):
            r = can_bench.run_rate(1000.0, a.duration, 0.0, "friction_local", False, axes)
            ok = bool(r["enabled_throughout"])
            per_axis = 100 * r["node_cpu"] / axes
            rows.append([
                protocol, axes, r["cycle_rate_hz"], r["overruns"], 100 * r["node_cpu"], per_axis,
                100 * r["emulator_cpu"], "yes" if ok else f"FAULT ({r['fault_reason']})",
                "yes" if can_bench.sustained(r) else "no",
            ])  # fmt: skip
            figures[f"{protocol}_{axes}_axes"] = {
                "node_cpu_percent_per_axis": per_axis if ok else None,
                "cycles_per_s": r["cycle_rate_hz"],
                "overruns": r["overruns"],
                "enabled_throughout": ok,
                "sustained": can_bench.sustained(r),
            }
    common.print_table(
        "drive_interface at 1 kHz per protocol (friction_local, emulator in its own process)",
        ["protocol", "axes", "cycles/s", "overruns", "node CPU %", "node CPU % per axis", "emulator CPU %",
         "enabled", "sustained"],
        rows,
    )  # fmt: skip
    common.write_results("can_protocols", figures)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
