"""Gauntlet section of bench/real_data.py: the fitter on every class of log users bring.

Each seeded log of :mod:`friction_ros.core.synthetic.logs` (default length, seed 0) is written to a
CSV and read back with ``load_csv`` and the options a user would pass, then fitted by
``fit_records`` with friction-fit's defaults (models coulomb, stribeck, lugre, gms4; learned
residual auto); the real DFKI double pendulum (both joints of the full runs when
/work/shared/data/dfki_double_pendulum is present, else of the 3 s excerpt in test/data) runs the
same way. One row per log: samples, seconds, the recommended model and its validation NMSE, the
worst model NMSE (a diverged model shows there), the verdict, the warning count, and, where the
truth has them, the recommended model's Coulomb and viscous levels against it. A log the fitter
refuses gives its one-line error instead.

    .venv/bin/python bench/real_data.py --gauntlet          # this section alone (~4 min CPU)
    .venv/bin/python bench/real_data.py --gauntlet --quick  # coulomb_viscous and stribeck, no residual (~10 s)
"""

from __future__ import annotations

import math
import tempfile
import time
import traceback
from pathlib import Path

from _common import print_table

from friction_ros.core.identification.data.csv_loading import load_csv
from friction_ros.core.identification.fit.pipeline import fit_records
from friction_ros.core.synthetic.logs import GENERATORS, make_log

ROOT = Path(__file__).resolve().parents[1]
SHARED_DOUBLE = Path("/work/shared/data/dfki_double_pendulum")
EXCERPT_DOUBLE = ROOT / "test" / "data" / "dfki_double_pendulum" / "design_A0_sysid_trajectory_00_first3s.csv"
DEFAULT_MODELS = ["coulomb", "stribeck", "lugre", "gms4"]  # friction-fit's default --models
QUICK_MODELS = ["coulomb_viscous", "stribeck"]


def _real_cases() -> list[tuple[str, list[Path], dict, dict]]:
    """(label, files, load_csv keywords, truth) of the real double-pendulum joints."""
    if SHARED_DOUBLE.is_dir():
        files = [SHARED_DOUBLE / f"design_{d}_sysid_trajectory_00.csv" for d in ("A0", "C0")]
    else:
        files = [EXCERPT_DOUBLE]
    out = []
    for f in files:
        for j in (1, 2):
            cols = {
                "time": "time",
                "position": f"pos_meas{j}",
                "velocity": f"vel_meas{j}",
                "effort": f"tau_meas{j}",
            }
            label = f"dfki_double_pendulum {f.stem.split('_sysid')[0].removeprefix('design_')} joint {j}"
            out.append((label, [f], {"columns": cols}, {}))
    return out


def _synthetic_cases(d: Path) -> list[tuple[str, list[Path], dict, dict]]:
    out = []
    for name in GENERATORS:
        log = make_log(name)
        files = [log.write_csv(d / f"{name}.csv")]
        if log.validation is not None:
            files.append(log.validation.write_csv(d / f"{name}_validation.csv"))
        out.append((name, files, dict(log.load), log.truth))
    return out


def _truth_levels(truth: dict) -> tuple[float | None, float | None]:
    """(Coulomb, viscous) of the truth's friction model, None when it has none."""
    f = truth.get("friction") or {}
    if "shoulder" in f:  # the arm: the fitted joint
        f = f["shoulder"]
    return f.get("fc"), f.get("fv")


def _fit_one(label, files, load, truth, models, residual) -> dict:
    row: dict = {"log": label, "files": [str(f) for f in files]}
    t0 = time.perf_counter()
    try:
        recs = [load_csv(f, **load) for f in files]
        row["samples"] = sum(r.n for r in recs)
        row["seconds"] = sum(r.duration for r in recs)
        res = fit_records(recs, models, residual=residual, label=label)
    except Exception as exc:  # noqa: BLE001 - the bench records what a user would see
        row["error"] = f"{type(exc).__name__}: {exc}".splitlines()[0]
        row["traceback"] = traceback.format_exc(limit=3)
        row["fit_s"] = time.perf_counter() - t0
        return row
    row["fit_s"] = time.perf_counter() - t0
    rec = res.recommended
    nmse = {n: float(m.metrics.get("nmse_percent", math.nan)) for n, m in res.models.items()}
    base = res.models.get("baseline")
    row.update(
        recommended=rec,
        nmse_percent=nmse.get(rec, math.nan) if rec else math.nan,
        rel_error_percent=float(res.models[rec].metrics.get("rel_error_percent", math.nan))
        if rec
        else math.nan,
        baseline_nmse_percent=nmse.get("baseline", math.nan),
        beats_baseline=None if rec in (None, "baseline") else nmse[rec] < nmse.get("baseline", math.inf),
        baseline_fitted=bool(base and base.fitted),
        status={n: m.status for n, m in res.models.items()},
        reason=(res.recommendation or {}).get("reason", ""),
        nmse_all=nmse,
        verdict="explains little" if (res.options.get("verdict") or {}).get("explains_little") else "ok",
        warnings=list(res.warnings),
        load_terms=res.options.get("load_terms"),
        coefficients={
            n: {k: float(v) for k, v in m.coefficients.items() if isinstance(v, (int, float))}
            for n, m in res.models.items()
        },
    )
    fc, fv = _truth_levels(truth)
    c = res.models[rec].coefficients if rec else {}
    for key, want in (("fc", fc), ("fv", fv)):
        got = c.get(key)
        if want and got is not None:
            row[f"{key}_truth"], row[f"{key}_fit"] = want, float(got)
            row[f"{key}_error_percent"] = 100.0 * (float(got) - want) / want
    row["truth"] = truth
    return row


def _cell(x, fmt="{:.3g}") -> str:
    if x is None or (isinstance(x, float) and not math.isfinite(x)):
        return "-"
    return fmt.format(x)


def gauntlet(quick: bool) -> dict:
    models = QUICK_MODELS if quick else DEFAULT_MODELS
    residual = "none" if quick else "auto"
    rows = []
    with tempfile.TemporaryDirectory(prefix="gauntlet_") as tmp:
        for case in [*_synthetic_cases(Path(tmp)), *_real_cases()]:
            rows.append(_fit_one(*case, models, residual))
            r = rows[-1]
            print(f"  {r['log']}: {r.get('recommended', r.get('error'))} ({r['fit_s']:.1f} s)", flush=True)
    table = []
    for r in rows:
        if "error" in r:
            table.append(
                [
                    r["log"],
                    _cell(r.get("samples"), "{}"),
                    _cell(r.get("seconds"), "{:.1f}"),
                    "-",
                    "-",
                    "-",
                    "-",
                    "-",
                    "-",
                    "fails",
                    "-",
                    "-",
                    r["error"][:120],
                ]
            )
            continue
        withheld = [f"{n} {st}" for n, st in r["status"].items() if st != "fitted"]
        vs_base = (
            "is baseline"
            if r["recommended"] == "baseline"
            else ("none" if r["recommended"] is None else ("beats" if r["beats_baseline"] else "NO"))
        )
        table.append(
            [
                r["log"],
                str(r["samples"]),
                f"{r['seconds']:.1f}",
                r["recommended"] or "-",
                _cell(r["nmse_percent"]),
                _cell(r["rel_error_percent"]),
                _cell(r["baseline_nmse_percent"]),
                vs_base,
                ", ".join(withheld) or "-",
                r["verdict"],
                str(len(r["warnings"])),
                " / ".join(
                    f"{k} {r[k + '_fit']:.3g} vs {r[k + '_truth']:.3g}"
                    for k in ("fc", "fv")
                    if k + "_fit" in r
                )
                or "-",
                f"{r['fit_s']:.1f} s",
            ]
        )
    print_table(
        f"Gauntlet: fit_records ({', '.join(models)}; residual {residual}) on every class of log, "
        "validation NMSE % and relative error %; the inverse-dynamics baseline's NMSE and whether the "
        "recommendation beats it; models withheld (not fitted / diverged: no figures); "
        "Coulomb/viscous of the recommended model vs the truth (the log's own units)",
        [
            "log",
            "samples",
            "seconds",
            "recommended",
            "NMSE %",
            "rel.err %",
            "baseline NMSE %",
            "vs baseline",
            "withheld",
            "verdict",
            "warnings",
            "fc / fv fit vs truth",
            "fit / error",
        ],
        table,
    )
    return {
        "models": models,
        "residual": residual,
        "double_pendulum_source": str(SHARED_DOUBLE if SHARED_DOUBLE.is_dir() else EXCERPT_DOUBLE),
        "logs": rows,
    }
