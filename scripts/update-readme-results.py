#!/usr/bin/env python3
"""Rewrite the results block of docs/benchmarks.md from bench/results/*.json (run by `make bench`).

Each benchmark stores the tables it printed, the command that produced them and the machine; this
script copies them between the markers ``<!-- BENCH:BEGIN -->`` and ``<!-- BENCH:END -->``.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
ORDER = [
    "demo",
    "robustness",
    "real_data",
    "learned_residual",
    "manipulator",
    "models",
    "compensation",
    "fitting",
    "loop",
    "can",
    "drive_soak",
    "bags",
]
TITLES = {
    "demo": "Main job: identify and compensate the simulated ABB M19-S joint",
    "robustness": "Main job on every preset x 3 experiment seeds",
    "models": "Friction models and plant speed",
    "compensation": "Compensation experiments of the source documents",
    "fitting": "Offline identification",
    "loop": "Closed loop across processes over DDS",
    "can": "CAN codec and drive node",
    "drive_soak": "Drive node under load: stale telemetry and a killed drive",
    "bags": "MCAP recording and reading",
    "real_data": "Identification on a realistic synthetic joint and a real pendulum",
    "learned_residual": "Learned residual on a physics backbone: candidates",
    "manipulator": "A 7-joint arm: one node per role, the friction add-on on a plain PD",
}
BEGIN, END = "<!-- BENCH:BEGIN -->", "<!-- BENCH:END -->"


def _sections(block: str) -> dict[str, str]:
    """The block's ``### title`` sections (title -> text), so a benchmark not run keeps its figures."""
    out: dict[str, str] = {}
    for chunk in block.split("\n### ")[1:]:
        title = chunk.split("\n", 1)[0].strip()
        out[title] = "### " + chunk.rstrip() + "\n"
    return out


def main() -> int:
    results = {
        p.stem: json.loads(p.read_text())
        for p in sorted((ROOT / "bench" / "results").glob("*.json"))
        if not p.stem.endswith("_quick")  # smoke runs (--quick) are not results
    }
    readme = ROOT / "docs" / "benchmarks.md"
    text = readme.read_text()
    if BEGIN not in text or END not in text:
        print(f"{readme} has no BENCH markers", file=sys.stderr)
        return 1
    kept = _sections(text.split(BEGIN, 1)[1].split(END, 1)[0])
    parts = []
    for name in ORDER + sorted(set(results) - set(ORDER)):
        r = results.get(name)
        if r is None or not r.get("tables"):
            # no new figures for this benchmark here: keep the section the page already has
            old = kept.get(TITLES.get(name, name))
            if old:
                parts.append(old)
            continue
        m = r.get("machine", {})
        parts.append(f"### {TITLES.get(name, name)}\n")
        parts.append(
            f"Command: `{r['command']}` (measured {m.get('date', '?')}, {m.get('cpu_count', '?')} cores, "
            f"Python {m.get('python', '?')})\n"
        )
        parts += [t + "\n" for t in r["tables"]]
    head, rest = text.split(BEGIN, 1)
    _, tail = rest.split(END, 1)
    readme.write_text(head + BEGIN + "\n\n" + "\n".join(parts) + "\n" + END + tail)
    print(
        f"docs/benchmarks.md: results of {len(parts) and sum(1 for n in results if results[n].get('tables'))} benchmarks updated"
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
