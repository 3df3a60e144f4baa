"""friction-fit's console summary of one fit: the model table, recommendation, gate verdicts, files."""

from __future__ import annotations

import math

from friction_ros.cli.reasons import footnotes, grouped


def print_summary(res) -> None:
    """The console summary of a FitResult: a table of the models (a long failure reason once under
    it, marked in its row), the recommendation, the safety gate's verdicts (modes with the same
    reason on one line), warnings and the files written."""

    def pct(x) -> str:
        return "n/a" if x is None or x != x else f"{x:.4g}"

    print(
        f"{'model':<16} {'NMSE %':>10} {'rel.err %':>10} {'NMSE high %':>12} {'NMSE low %':>12} "
        f"{'params':>7} {'BIC':>14}"
    )
    markers, notes = footnotes({n: m.reason for n, m in res.models.items() if m.status != "fitted"})
    for n, m in res.models.items():
        mt = m.metrics
        if m.status != "fitted":  # no figure from a model that failed or diverged
            print(f"{n:<16} {m.status} {markers.get(n, '')}".rstrip())
            continue
        mark = "  <- recommended" if n == res.recommended else ""
        print(
            f"{n:<16} {pct(mt.get('nmse_percent')):>10} {pct(mt.get('rel_error_percent')):>10} "
            f"{pct(mt.get('nmse_high_percent')):>12} {pct(mt.get('nmse_low_percent')):>12} "
            f"{mt.get('n_params', 0):>7d} {mt.get('bic', math.nan):>14.6g}{mark}"
        )
    for line in notes:
        print(f"  {line}")
    rec = getattr(res, "recommendation", None) or {}
    if rec.get("rule"):
        print(f"recommended by: {rec['rule']}" + (f" ({rec['reason']})" if rec.get("reason") else ""))
    if res.options.get("load_terms", "none") != "none":
        print(f"load terms: {res.options['load_terms']}")
    cv = res.options.get("cross_validation")
    if cv:
        print("cross-validation over runs (validation NMSE %, trained on the other runs):")
        for f in cv["folds"]:
            row = ", ".join(f"{n} {x:.4g}" for n, x in f["nmse_percent"].items())
            print(f"  {f['validation']}: {row}")
    for modes, reason in grouped({mode: v.reason for mode, v in (res.gate or {}).items()}):
        print(f"compensation {modes}: {reason}")
    for w in res.warnings:
        print(f"warning: {w}")
    for kind, path in res.files.items():
        if not kind.startswith("plot:"):
            print(f"wrote {kind}: {path}")
