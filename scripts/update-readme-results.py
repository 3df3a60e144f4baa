#!/usr/bin/env python3
"""Rewrite README.md's results block from bench/results/*.json (run by `make bench`).

Each benchmark stores the tables it printed, the command that produced them and the machine; this
script copies them between the markers ``<!-- BENCH:BEGIN -->`` and ``<!-- BENCH:END -->``.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
ORDER = ["demo", "models", "compensation", "fitting", "loop", "can", "bags"]
TITLES = {
    "demo": "Main job: identify and compensate the simulated ABB M19-S joint (issue 9)",
    "models": "Friction models and plant speed (issue 3)",
    "compensation": "Compensation experiments of the seeds (issue 4)",
    "fitting": "Offline identification (issue 8)",
    "loop": "Closed loop across processes over DDS (issue 5)",
    "can": "CAN codec and drive node (issue 6)",
    "bags": "MCAP recording and reading (issue 7)",
}
BEGIN, END = "<!-- BENCH:BEGIN -->", "<!-- BENCH:END -->"


def main() -> int:
    results = {
        p.stem: json.loads(p.read_text())
        for p in sorted((ROOT / "bench" / "results").glob("*.json"))
        if not p.stem.endswith("_quick")  # smoke runs (--quick) are not results
    }
    parts = []
    for name in ORDER + sorted(set(results) - set(ORDER)):
        r = results.get(name)
        if r is None or not r.get("tables"):
            continue
        m = r.get("machine", {})
        parts.append(f"### {TITLES.get(name, name)}\n")
        parts.append(
            f"Command: `{r['command']}` (measured {m.get('date', '?')}, {m.get('cpu_count', '?')} cores, "
            f"Python {m.get('python', '?')})\n"
        )
        parts += [t + "\n" for t in r["tables"]]
    readme = ROOT / "README.md"
    text = readme.read_text()
    if BEGIN not in text or END not in text:
        print("README.md has no BENCH markers", file=sys.stderr)
        return 1
    head, rest = text.split(BEGIN, 1)
    _, tail = rest.split(END, 1)
    readme.write_text(head + BEGIN + "\n\n" + "\n".join(parts) + "\n" + END + tail)
    print(
        f"README.md: results of {len(parts) and sum(1 for n in results if results[n].get('tables'))} benchmarks updated"
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
