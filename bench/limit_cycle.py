"""Benchmark `limit_cycle`: CPU cost of the run-time limit-cycle (hunting) detector per sample.

    .venv/bin/python bench/limit_cycle.py [--samples 20000] [--repeats 5]

``LimitCycleDetector.update`` runs once per control period in every compensating controller, so its
cost adds to each 1 kHz cycle. Fed a 3 Hz, 1 mrad error oscillation with a 0.5 N*m command (below its
firing thresholds, so every sample takes the full path) through a 60,000-count encoder; the figure is
the best of ``--repeats`` passes (the least disturbed by other processes).
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.append(str(ROOT / "bench"))  # after site-packages: bench/can.py must not shadow python-can

from _common import print_table, write_results  # noqa: E402

from friction_ros.core.control.limit_cycle import LimitCycleDetector  # noqa: E402

COUNT = 2 * math.pi / 60000  # encoder resolution [rad]: abb_m19s, 20000 cpr at the motor x 3


def per_sample_us(n: int, repeats: int) -> tuple[float, float, bool]:
    det = LimitCycleDetector()
    t = np.arange(n) * 1e-3
    e = (1e-3 * np.sin(2 * np.pi * 3.0 * t)).tolist()
    u = (0.5 * np.sin(2 * np.pi * 3.0 * t + 0.3)).tolist()
    v = (0.02 * np.cos(2 * np.pi * 3.0 * t)).tolist()
    p = (np.round(np.sin(2 * np.pi * 3.0 * t) / COUNT) * COUNT).tolist()
    tl = t.tolist()
    times = []
    for _ in range(repeats):
        det.reset()
        t0 = time.perf_counter()
        for k in range(n):
            det.update(tl[k], e[k], u[k], v[k], p[k], 1e-3)
        times.append((time.perf_counter() - t0) / n * 1e6)
    return min(times), float(np.median(times)), det.fired


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0], allow_abbrev=False)
    ap.add_argument("--samples", type=int, default=20000, help="samples per pass (>= 1000)")
    ap.add_argument("--repeats", type=int, default=5, help="passes (>= 1)")
    a = ap.parse_args()
    if a.samples < 1000 or a.repeats < 1:
        print("error: --samples must be >= 1000 and --repeats >= 1", file=sys.stderr)
        return 2
    best, median, fired = per_sample_us(a.samples, a.repeats)
    print_table(
        "limit-cycle detector, CPU per sample",
        ["samples", "passes", "best [us]", "median [us]", "fired"],
        [[a.samples, a.repeats, round(best, 2), round(median, 2), fired]],
    )
    write_results(
        "limit_cycle",
        {"samples": a.samples, "repeats": a.repeats, "best_us": best, "median_us": median, "fired": fired},
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
