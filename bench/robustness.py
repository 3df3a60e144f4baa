"""Benchmark `robustness` (issue 14): the main job on every preset x 3 experiment seeds.

For each preset in params/ and each seed of the identification experiment's random excitation,
runs friction-demo's pipeline (lockstep ROS graph, quick profile): experiment sized to the joint,
fit, safety gate, tracking runs. Per cell: the recommended model, the steady-state map error
against the preset's truth (largest relative error over the plateau speed range, and the static
peak: the largest map value below the lowest plateau speed), RMS tracking error per mode and
whether the mode was enabled or refused.

``encoder cap``: the largest reduction any controller could show on that run, since even perfect
tracking reads the reference's distance to the nearest encoder count.

Goals: 100 % of cells complete; no enabled mode worse than none; static peak within 10 % and
sliding map within 3 % on every preset; best enabled mode at least -90 % on abb_m19s and at least
-50 % on every other preset.

    .venv/bin/python bench/robustness.py                 # every preset, seeds 1 2 3
    .venv/bin/python bench/robustness.py --presets abb_m19s --seeds 1
"""

from __future__ import annotations

import argparse
import math
import sys
import tempfile
import time
from pathlib import Path

sys.path.append(str(Path(__file__).resolve().parent))  # bench/can.py must not shadow python-can
from _common import print_table, write_results  # noqa: E402

from friction_ros.cli import demo, demo_results  # noqa: E402
from friction_ros.core.presets import PRESET_NAMES  # noqa: E402

MODES = ("feedforward", "feedback", "blended")


def encoder_cap(run, preset: str) -> float:
    """The demo's encoder cap of this run (``friction_ros.cli.demo_results.encoder_cap``)."""
    from friction_ros.core.presets import load_preset

    return demo_results.encoder_cap(run, demo._resolution(load_preset(preset)))


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--presets", nargs="+", default=list(PRESET_NAMES))
    ap.add_argument("--seeds", nargs="+", type=int, default=[1, 2, 3])
    ap.add_argument("--duration", type=float, default=4.0, help="simulated seconds per tracking run")
    opts = ap.parse_args()
    rows, cells = [], []
    t_all = time.monotonic()
    with tempfile.TemporaryDirectory(prefix="friction_robustness_") as tmp:
        for preset in opts.presets:
            for seed in opts.seeds:
                args = demo.build_parser().parse_args(
                    [
                        "--preset",
                        preset,
                        "--quick",
                        "--seed",
                        str(seed),
                        "--results",
                        f"{tmp}/{preset}_{seed}",
                    ]
                )
                args.duration = opts.duration
                args.bag = None
                cell = {"preset": preset, "seed": seed}
                try:
                    res = demo.run_preset(args, preset, Path(tmp) / f"{preset}_{seed}")
                except Exception as exc:  # a failed cell is a result, reported in the table
                    cell.update(complete=False, error=str(exc).splitlines()[0][:120])
                    cells.append(cell)
                    rows.append([preset, seed, "FAILED", "-", "-", cell["error"], "", "", "", "", ""])
                    print(f"cell {preset} seed {seed} FAILED: {exc!r}", file=sys.stderr)
                    continue
                none = res.runs["none"].rms
                worse = [m for m in MODES if res.runs[m].enabled and res.runs[m].rms > none * 1.02]
                cell.update(
                    complete=True,
                    model=res.model,
                    map_error=res.map_error,
                    rms_mrad={m: r.rms * 1e3 for m, r in res.runs.items()},
                    enabled={m: res.runs[m].enabled for m in MODES},
                    reasons={m: res.runs[m].reason for m in MODES},
                    best=res.best,
                    best_reduction_percent=res.reduction(res.best) if res.best != "none" else 0.0,
                    enabled_worse_than_none=worse,
                    warnings=res.warnings,
                    encoder_cap_percent=encoder_cap(res.runs["none"], preset),
                )
                cells.append(cell)
                rows.append(
                    [
                        preset,
                        seed,
                        res.model,
                        f"{res.map_error['sliding_percent']:.2f}",
                        f"{res.map_error['static_peak_percent']:+.2f}",
                        f"{none * 1e3:.4g}",
                        *[
                            f"{res.runs[m].rms * 1e3:.4g}" + ("" if res.runs[m].enabled else " (refused)")
                            for m in MODES
                        ],
                        f"{res.best} {cell['best_reduction_percent']:.1f} %",
                        f"{cell['encoder_cap_percent']:.1f} %",
                    ]
                )
    print_table(
        "Robustness: presets x experiment seeds (quick profile, lockstep ROS graph); RMS tracking error in "
        "mrad (mm for linear axes); map errors vs the preset's truth",
        [
            "preset",
            "seed",
            "model",
            "sliding map err %",
            "static peak err %",
            "none",
            "feedforward",
            "feedback",
            "blended",
            "best enabled",
            "encoder cap",
        ],
        rows,
    )
    done = [c for c in cells if c["complete"]]
    by_preset: dict[str, list[dict]] = {}
    for c in done:
        by_preset.setdefault(c["preset"], []).append(c)

    def goal_red(p):
        return 90.0 if p == "abb_m19s" else 50.0

    summary = {
        "cells": len(cells),
        "complete_percent": 100.0 * len(done) / max(len(cells), 1),
        "enabled_worse_than_none": sum(len(c["enabled_worse_than_none"]) for c in done),
        "max_sliding_map_error_percent": max(
            (c["map_error"]["sliding_percent"] for c in done), default=math.nan
        ),
        "max_static_peak_error_percent": max(
            (abs(c["map_error"]["static_peak_percent"]) for c in done), default=math.nan
        ),
        "presets_meeting_reduction_goal": sorted(
            p for p, cs in by_preset.items() if all(c["best_reduction_percent"] >= goal_red(p) for c in cs)
        ),
        "wall_seconds": time.monotonic() - t_all,
    }
    print_table(
        "Robustness goals",
        ["goal", "measured", "met"],
        [
            [
                "100 % of cells complete",
                f"{summary['complete_percent']:.0f} %",
                summary["complete_percent"] == 100,
            ],
            [
                "no enabled mode worse than none",
                summary["enabled_worse_than_none"],
                summary["enabled_worse_than_none"] == 0,
            ],
            [
                "sliding map within 3 % on every preset",
                f"{summary['max_sliding_map_error_percent']:.2f} % (worst cell)",
                summary["max_sliding_map_error_percent"] <= 3.0,
            ],
            [
                "static peak within 10 % on every preset",
                f"{summary['max_static_peak_error_percent']:.2f} % (worst cell)",
                summary["max_static_peak_error_percent"] <= 10.0,
            ],
            [
                "best enabled mode <= -90 % (abb_m19s), <= -50 % (others)",
                (", ".join(summary["presets_meeting_reduction_goal"]) or "none")
                + "".join(
                    f"; not {p}: best {min(c['best_reduction_percent'] for c in cs):.1f} %, encoder cap "
                    f"{min(c['encoder_cap_percent'] for c in cs):.1f} %"
                    for p, cs in by_preset.items()
                    if p not in summary["presets_meeting_reduction_goal"]
                ),
                len(summary["presets_meeting_reduction_goal"]) == len(opts.presets),
            ],
        ],
    )
    write_results("robustness", {"summary": summary, "cells": cells}, ".venv/bin/python bench/robustness.py")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
