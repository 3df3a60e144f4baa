"""Benchmark `demo` (issue 9): the main job end to end, as `make demo` runs it.

Prints the demo's table (model chosen, fit NMSE, RMS/max tracking error with and without the
fitted compensation, reduction) and the wall time of each stage (goal: under 5 minutes on this
2-core machine).

    .venv/bin/python bench/demo.py            # = friction-demo (quick experiment profile, 10 s runs)
"""

from __future__ import annotations

import sys
from pathlib import Path

sys.path.append(str(Path(__file__).resolve().parent))  # bench/can.py must not shadow python-can
from _common import print_table, write_results  # noqa: E402

from friction_ros.cli import demo  # noqa: E402


def main() -> int:
    args = demo.build_parser().parse_args(sys.argv[1:])
    res = demo.run(args)
    rows = [
        [
            k,
            "-" if k == "none" else ("enabled" if r.enabled else "refused"),
            r.rms * 1e3,
            r.max * 1e3,
            res.reduction(k),
            r.metrics.get("stick_fraction"),
            r.metrics.get("hunting_reversals"),
            r.samples,
        ]
        for k, r in res.runs.items()
    ]
    print_table(
        f"friction-demo on {args.preset}: fitted {res.model} (validation NMSE high {res.fit_nmse['high']:.3f} %, "
        f"low {res.fit_nmse['low']:.3f} %), {args.duration:g} s reference sized to the joint, lockstep ROS graph",
        [
            "compensation",
            "state",
            "RMS error mrad",
            "max error mrad",
            "RMS reduction %",
            "stick fraction",
            "hunting reversals",
            "samples",
        ],
        rows,
    )
    print_table(
        "friction-demo wall time (goal: under 5 minutes)",
        ["stage", "seconds"],
        [[k, v] for k, v in res.timings.items()],
    )
    figures = {
        "model": res.model,
        "fit_nmse_percent": res.fit_nmse,
        "runs": {
            k: {"rms_mrad": r.rms * 1e3, "max_mrad": r.max * 1e3, "enabled": r.enabled, "reason": r.reason}
            for k, r in res.runs.items()
        },
        "gate": res.gate,
        "warnings": res.warnings,
        "best": res.best,
        "timings_s": res.timings,
    }
    write_results("demo", figures, "make demo   (= .venv/bin/python bench/demo.py)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
