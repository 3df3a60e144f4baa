#!/usr/bin/env python3
"""Compile the numba kernels once into their on-disk cache (``__pycache__`` beside the sources).

    .venv/bin/python scripts/warm-numba-cache.py [plants|fit]

``make test`` runs it before pytest: without it, on a fresh clone, every test worker and every node
process that starts before the first compile has finished compiles the same kernels again (about
15 s of CPU each). Runs the plant of every preset for a few steps and one offline fit of a small
real log with the default models; a second run only loads the cache (about 2 s). ``plants`` or
``fit`` does one half (``make test`` runs them in two processes: on a fresh clone with 2 cores the
plants take 6-7 s beside the fit's 24-29 s, which was 28-36 s for both in one process).
"""

from __future__ import annotations

import contextlib
import io
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
LOG = ROOT / "test" / "data" / "dfki_pendulum" / "control_method_pd_system_identification.csv"


def main() -> int:
    sys.path.insert(0, str(ROOT))
    from friction_ros.cli import fit
    from friction_ros.core.presets import PRESET_NAMES, load_preset, make_plant

    part = sys.argv[1] if len(sys.argv) > 1 else "all"
    if part not in ("all", "plants", "fit"):
        print(f"warm-numba-cache: part '{part}' is not one of plants, fit (or none: both)", file=sys.stderr)
        return 2
    t0 = time.monotonic()
    if part in ("all", "plants"):
        for name in PRESET_NAMES:
            plant = make_plant(load_preset(name))
            for _ in range(3):
                plant.step(0.01, 1e-3)
    if part in ("all", "fit"):
        with tempfile.TemporaryDirectory() as out, contextlib.redirect_stdout(io.StringIO()):
            code = fit.main([str(LOG), "--no-plots", "--quiet", "--out", out])
        if code != 0:
            print(f"warm-numba-cache: the fit of {LOG.name} exited {code}", file=sys.stderr)
            return 1
    what = "" if part == "all" else f" ({part})"
    print(f"[test] numba kernels{what} compiled or loaded from their cache in {time.monotonic() - t0:.0f} s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
