"""Shared helpers for benchmarks: a printed table and bench/results/<name>.json."""

from __future__ import annotations

import json
import os
import platform
import time
from pathlib import Path

RESULTS = Path(__file__).resolve().parent / "results"
_TABLES: list[str] = []  # every table printed by this benchmark run (copied into README by make bench)


def machine() -> dict:
    """Describe the machine the figures were measured on."""
    return {
        "cpu_count": os.cpu_count(),
        "python": platform.python_version(),
        "machine": platform.machine(),
        "date": time.strftime("%Y-%m-%d"),
    }


def print_table(title: str, headers: list[str], rows: list[list]) -> None:
    """Print rows as an aligned plain-text table (also valid Markdown)."""

    def fmt(x):
        if isinstance(x, float):
            return f"{x:.4g}"
        return str(x)

    cells = [[fmt(c) for c in r] for r in rows]
    widths = [max(len(h), *(len(r[i]) for r in cells)) if cells else len(h) for i, h in enumerate(headers)]
    lines = [
        f"{title}",
        "",
        "| " + " | ".join(h.ljust(w) for h, w in zip(headers, widths)) + " |",
        "|" + "|".join("-" * (w + 2) for w in widths) + "|",
    ]
    lines += ["| " + " | ".join(c.ljust(w) for c, w in zip(r, widths)) + " |" for r in cells]
    print("\n" + "\n".join(lines[:1] + lines[2:]))
    _TABLES.append("\n".join(lines))


def write_results(name: str, figures: dict, command: str | None = None) -> Path:
    """Write ``figures`` to bench/results/<name>.json with the command and machine description."""
    RESULTS.mkdir(parents=True, exist_ok=True)
    path = RESULTS / f"{name}.json"
    payload = {
        "benchmark": name,
        "command": command or f".venv/bin/python bench/{name}.py",
        "machine": machine(),
        "figures": figures,
        "tables": list(_TABLES),
    }
    path.write_text(json.dumps(payload, indent=2, default=float) + "\n")
    print(f"\nwrote {path.relative_to(RESULTS.parent.parent)}")
    return path


def warm_kernels(record, names=("dahl", "lugre", "gms4", "gms4d")) -> None:
    """Compile (or load from the numba cache) the dynamic fit kernels of ``names`` on 100 samples of
    ``record``, so that the timings that follow are fit times, not compile times."""
    import numpy as np

    from friction_ros.core.identification.fit.models import spec_for

    tr = record.slice(0, 200)
    for name in names:
        spec = spec_for(name)
        x = spec.from_search(np.array([np.mean(b) for b in spec.search_bounds()]))[None, :]
        spec.grams(x, tr.velocity[:100], tr.acceleration[:100], tr.torque[:100], tr.dt)
