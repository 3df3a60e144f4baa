"""Outputs of a fit: Markdown report with PNG plots, JSON summary, ROS parameter YAML.

Layout of ``out_dir`` (FIGAROH-style report + machine-readable summary):

* ``report.md``: data, excitation, plateaus/breakaway, ABB M19-S paper Table 1 analogue (validation NMSE
  high/low velocity, max error, parameter count, AIC/BIC), recommended model, coefficients with
  95 % confidence intervals, identifiability flags, notes;
* ``summary.json``: for every model ``coefficients``, ``config`` (library form or null),
  ``metrics``, ``identifiability`` and ``steady_state`` (``velocity``/``friction`` on a
  log-spaced grid covering the data in both directions), plus data description and recommendation;
* ``friction_params.yaml``: ``node_name: ros__parameters:`` for compensating_controller,
  friction_estimator and plant_simulator (recommended model);
* ``plots/friction_velocity.png``, ``plots/presliding.png``, ``plots/validation.png``,
  ``plots/residuals.png``.
"""

from __future__ import annotations

import json
import math
import time
from pathlib import Path

import numpy as np

from friction_ros.core.identification.fit.fit_units import coefficient_unit, fit_joint_type, units, units_note
from friction_ros.core.identification.report import export


def _clean(x):
    if isinstance(x, dict):
        return {str(k): _clean(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_clean(v) for v in x]
    if isinstance(x, np.ndarray):
        return _clean(x.tolist())
    if isinstance(x, (np.floating, float)):
        f = float(x)
        return f if math.isfinite(f) else None
    if isinstance(x, np.integer):
        return int(x)
    return x


def summary(res, sources=None, topic=None, joint=None) -> dict:
    tr, va = res.train, res.validation
    jt = fit_joint_type(res)
    return _clean(
        {
            "tool": "friction-fit",
            "created": time.strftime("%Y-%m-%dT%H:%M:%S"),
            "sources": sources or [],
            "topic": topic,
            "joint": joint,
            "joint_type": jt,
            "units": units(jt),
            "data": {
                "train_samples": sum(r.n for r in tr),
                "validation_samples": sum(r.n for r in va),
                "dt": tr[0].dt,
                "encoder_resolution": tr[0].resolution,
                "high_velocity_threshold": res.high_threshold,
                "velocity_filter": "Savitzky-Golay order 3, 21 ms (velocity) / 41 ms (acceleration)",
                # a long log cut down by content: samples used, of how many, kept sample ranges
                "decimation": next((r.meta["decimation"] for r in tr if "decimation" in r.meta), None),
            },
            "warnings": list(getattr(res, "warnings", [])),
            "excitation": vars(res.excitation),
            "plateaus": [vars(p) for p in res.plateaus],
            "breakaways": [vars(b) for b in res.breakaways],
            "options": {k: v for k, v in res.options.items() if k != "gate_options"},
            "recommended": res.recommended,
            "recommendation": getattr(res, "recommendation", {}),
            "gate": {m: v.as_dict() for m, v in (getattr(res, "gate", None) or {}).items()},
            "models": {
                n: {
                    "method": m.method,
                    "coefficients": m.coefficients,
                    "config": m.config,
                    "metrics": m.metrics,
                    "identifiability": m.identifiability,
                    "fit_seconds": m.seconds,
                    "notes": m.notes,
                    "status": m.status,
                    "reason": m.reason,
                    "steady_state": m.extra.get("steady_state_grid"),
                    "load": m.extra.get("load"),
                    "residual": m.extra.get("residual_report"),
                }
                for n, m in res.models.items()
            },
            "seconds": res.seconds,
        }
    )


def _fmt(x, nd=4):
    if x is None:
        return "-"
    if isinstance(x, (list, tuple)):
        return "[" + ", ".join(_fmt(v, nd) for v in x) + "]"
    if isinstance(x, (int, np.integer)):
        return str(x)
    try:
        f = float(x)
    except (TypeError, ValueError):
        return str(x)
    return "nan" if not math.isfinite(f) else f"{f:.{nd}g}"


def _n_rest(res) -> int:
    return max((int(m.metrics.get("n_rest_excluded", 0)) for m in res.models.values()), default=0)


def markdown(res, sources=None, plots: dict | None = None) -> str:
    jt = fit_joint_type(res)
    u = units(jt)
    L = ["# Friction identification report", ""]
    if sources:
        L += ["Sources: " + ", ".join(f"`{s}`" for s in sources), ""]
    if res.warnings:  # first, so that nobody reads a figure without them
        L += ["## Warnings", ""] + [f"- {w}" for w in res.warnings] + [""]
    tr, va = res.train, res.validation
    ex = res.excitation
    L += [
        "## Data",
        f"- joint type: {jt} (positions in {u['position']}, velocities in {u['velocity']}, friction in "
        f"{u['friction']}, inertia in {u['J']})",
        f"- training: {sum(r.n for r in tr)} samples, validation: {sum(r.n for r in va)} samples, "
        f"dt = {tr[0].dt * 1e3:.3g} ms, encoder resolution "
        + (f"{tr[0].resolution:.3g} {u['position']}" if tr[0].resolution > 0 else "unknown (no position)"),
        (
            f"- split: first {res.options['train_seconds']:g} s of each record for training, the rest for validation "
            "(ABB M19-S paper A.3)"
            if res.options.get("train_window") == "first"
            else f"- split: the {res.options['train_seconds']:g} s window of each record with the most velocity reversals "
            "and speed range for training (chosen by content: "
            + ", ".join(f"{a:.1f}-{b:.1f} s" for a, b in res.options.get("train_windows_s", []))
            + "), everything else for validation"
            if res.options.get("train_window") == "window"
            else f"- split: about {res.options['train_seconds']:g} s of each record for training, chosen by content: the "
            "record is cut into chunks (at the experiment's START events and every train_seconds/4), the moving chunks are "
            "sorted by (has a velocity reversal, RMS speed) and evenly spaced ones in that order train (at most half), so "
            "training and validation both span the speed range with and without reversals; training: "
            + ", ".join(f"{a:.1f}-{b:.1f} s" for a, b in res.options.get("train_windows_s", []))
            + "; everything else validates"
        ),
        (
            "- velocity/acceleration: Savitzky-Golay differentiation of the position (order 3, 21 ms / 41 ms, zero phase)"
            if tr[0].meta.get("velocity_source", "").startswith("Savitzky")
            else f"- velocity: {tr[0].meta.get('velocity_source', 'given')}; acceleration: its Savitzky-Golay derivative"
        ),
        f"- excitation: max speed +{ex.max_speed_pos:.3g} / -{ex.max_speed_neg:.3g} {u['velocity']}, {ex.reversals} reversals, "
        f"{len(res.plateaus)} plateaus, {len(res.breakaways)} breakaway events",
        f"- high/low velocity split: 1 s velocity RMS of the *moving* samples above/below {res.high_threshold:.3g} {u['velocity']} "
        "(samples at rest are in neither)",
        f"- scored: every validation sample except standstills (at rest for more than 0.5 s: the friction there is "
        f"whatever torque holds the joint; {_n_rest(res)} samples left out); a subset metric whose measured torque "
        "varies no more than its noise, or with fewer than 200 samples, is n/a",
        "",
        "## Model comparison (validation data; ABB M19-S paper Table 1 analogue)",
        "",
        "| model | method | NMSE high [%] (max err) | NMSE low [%] (max err) | NMSE all [%] | rel. error [%] "
        "| params | AIC | BIC | fit [s] |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for n, m in res.models.items():
        mt = m.metrics
        star = " **(recommended)**" if n == res.recommended else ""
        if m.status != "fitted":  # a model that failed or diverged has no figures
            L.append(f"| {n} | **{m.status}**: {m.reason} | | | | | | | | |")
            continue
        L.append(
            f"| {n}{star} | {m.method} | {_fmt(mt.get('nmse_high_percent'), 3)} ({_fmt(mt.get('max_error_high'), 3)}) | "
            f"{_fmt(mt.get('nmse_low_percent'), 3)} ({_fmt(mt.get('max_error_low'), 3)}) | {_fmt(mt.get('nmse_percent'), 3)} | "
            f"{_fmt(mt.get('rel_error_percent'), 3)} | "
            f"{mt.get('n_params')} | {_fmt(mt.get('aic'), 6)} | {_fmt(mt.get('bic'), 6)} | {m.seconds:.2f} |"
        )
    L += [
        "",
        "The baseline is the classical inverse-dynamics least-squares fit (inertia, viscous, Coulomb, offset and "
        "the load terms chosen): a model is recommended only when it beats it on validation. Relative error = "
        "100 ||y - y_hat|| / ||y||, as system-identification benchmarks report it.",
    ]
    L += [
        "",
        "ABB M19-S paper Table 1: Coulomb 4.00 / 17.92 %, Stribeck 0.55 / 9.59 %, LuGre 0.41 / 4.30 %, "
        "GMS-4 0.40 / 1.39 %, GMS-10 0.38 / 1.19 % (high / low velocity).",
        "",
    ]
    na = sorted(
        {
            f"{k.split('_')[1]} velocity: {v}"
            for m in res.models.values()
            for k, v in m.metrics.items()
            if k.endswith("_note")
        }
    )
    L += [f"- n/a: {x}" for x in na] + ([""] if na else [])
    L += [
        f"**Recommended model: {res.recommended}** ({(res.recommendation or {}).get('rule') or 'lowest validation BIC'}"
        + (f"; {res.recommendation['reason']}" if (res.recommendation or {}).get("reason") else "")
        + ").",
        "",
    ]
    L += _load_section(res) + _verdict_section(res) + _cross_validation_section(res)
    L += ["## Coefficients"]
    for n, m in res.models.items():
        L += ["", f"### {n}", ""]
        if m.status != "fitted":
            L += [f"{m.status}: {m.reason}"]
            continue
        ci = m.identifiability.get("ci95", {}) if m.identifiability else {}
        L += ["| coefficient | value | unit | 95 % CI |", "|---|---|---|---|"]
        for k, v in m.coefficients.items():
            unit = coefficient_unit(n, m.config, k, jt)
            if isinstance(v, dict):
                L.append(f"| {k} | {json.dumps(_clean(v))} | {unit} | |")
                continue
            held = k in (m.identifiability or {}).get("held", [])
            cell = "held at the plateau fit" if held else (_fmt(ci.get(k), 4) if k in ci else "")
            L.append(f"| {k} | {_fmt(v, 5)} | {unit} | {cell} |")
        if m.config:
            L += ["", f"Library config: `{json.dumps(_clean(m.config))}`"]
        idf = m.identifiability or {}
        if idf.get("not_identifiable"):
            L += ["", "**Not separately identifiable:** " + ", ".join(idf["not_identifiable"])]
            for g in idf.get("collinear_groups", []):
                L.append(f"- collinear direction: {json.dumps(_clean(g['null_direction']))}")
        if idf.get("high_correlations"):
            L += [
                "",
                "High correlations: "
                + ", ".join(f"{p['a']}/{p['b']} ({p['rho']:+.3f})" for p in idf["high_correlations"]),
            ]
        if "condition_number" in idf:
            L.append(
                f"\nJacobian condition number: {_fmt(idf['condition_number'], 3)} "
                "(CIs assume white residuals: optimistic when the model is wrong)"
            )
        for note in m.notes:
            L.append(f"- {note}")
    if getattr(res, "gate", None):
        L += [
            "",
            "## Compensation safety gate",
            "",
            "Each mode in closed loop on the identified plant (fitted inertia and friction, measured lag and "
            "delay), plant friction perturbed by +-20 %; a mode worse than none or not robustly stable is "
            "written disabled.",
            "",
            "| mode | state | RMS none | RMS mode | worst ratio | reason |",
            "|---|---|---|---|---|---|",
        ]
        for mode, v in res.gate.items():
            L.append(
                f"| {mode} | {'enabled' if v.enabled else 'refused'} | {_fmt(v.rms_none, 4)} | {_fmt(v.rms_mode, 4)} "
                f"| {_fmt(v.worst_ratio, 3)} | {v.reason} |"
            )
    if res.plateaus:
        L += [
            "",
            "## Plateaus",
            "",
            f"| v [{u['velocity']}] | friction [{u['friction']}] | std [{u['friction']}] | n | source |",
            "|---|---|---|---|---|",
        ]
        for p in res.plateaus:
            L.append(f"| {p.velocity:.4g} | {p.torque:.4g} | {p.torque_std:.3g} | {p.n} | {p.source} |")
    if res.breakaways:
        effort = "torque" if jt == "revolute" else "force"
        L += ["", "## Breakaway", "", f"| t [s] | {effort} [{u['friction']}] | direction |", "|---|---|---|"]
        for b in res.breakaways:
            L.append(f"| {b.time:.3f} | {b.torque:.4g} | {b.direction:+d} |")
    if plots:
        L += ["", "## Plots", ""]
        for title, rel in plots.items():
            L += [f"### {title}", "", f"![{title}]({rel})", ""]
    return "\n".join(L) + "\n"


def _load_section(res) -> list[str]:
    """Load, gravity and position terms: what the selection tried and the recommended model's values."""
    terms = res.options.get("load_terms", "none")
    if terms == "none" and not res.options.get("load_selection"):
        return []
    L = ["## Load, gravity and position terms", "", f"Identified jointly with every model: **{terms}**.", ""]
    steps = res.options.get("load_selection") or []
    if steps:
        L += (
            [
                "Chosen by validation (forward selection on a linear backbone; a term is kept when it lowers the "
                "validation MSE by >= 5 %):",
                "",
            ]
            + [f"- {s}" for s in steps]
            + [""]
        )
    m = res.models.get(res.recommended) if res.recommended else None
    load = (m.extra.get("load") if m else None) or {}
    if load:
        L += [
            f"Values of {res.recommended} (the `load` section of the parameter file, used as feedforward):",
            "",
        ]
        L += ["| term | value |", "|---|---|"]
        for k, v in load.items():
            L.append(f"| {k} | {json.dumps(_clean(v)) if isinstance(v, list) else _fmt(v, 5)} |")
        L += [
            "",
            "A constant `offset` cannot be told apart from an offset of the torque measurement: zero the sensor "
            "if it is one, before compensating with it.",
            "",
        ]
    return L


def _verdict_section(res) -> list[str]:
    v = res.options.get("verdict") or {}
    if not v.get("explains_little"):
        return []
    return ["## Verdict: the model explains little", "", v["text"], ""]


def _cross_validation_section(res) -> list[str]:
    cv = res.options.get("cross_validation")
    if not cv:
        return []
    names = list(cv["mean_nmse_percent"])
    L = [
        "## Cross-validation over runs",
        "",
        "Each run validated by models trained on all the other runs (what a deployed model meets).",
        "",
        "| validation run | recommended | " + " | ".join(f"{n} NMSE [%]" for n in names) + " |",
        "|---|---|" + "---|" * len(names),
    ]
    for f in cv["folds"]:
        L.append(
            f"| {f['validation']} | {f['recommended']} | "
            + " | ".join(_fmt(f["nmse_percent"].get(n), 4) for n in names)
            + " |"
        )
    L.append("| mean | | " + " | ".join(_fmt(cv["mean_nmse_percent"][n], 4) for n in names) + " |")
    return L + [""]


def write_outputs(
    res, out_dir: Path, *, params_file=None, plots=True, sources=None, topic=None, joint=None
) -> dict:
    """Write report.md, summary.json, the parameter YAML and the plots; returns {kind: path}."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    files = {}
    if plots:
        from friction_ros.core.identification.report.report_plots import make_plots

        plot_files = make_plots(res, out_dir / "plots")
    else:
        plot_files = {}
    for k, v in plot_files.items():
        files[f"plot:{k}"] = str(out_dir / v)
    js = summary(res, sources, topic, joint)
    (out_dir / "summary.json").write_text(json.dumps(js, indent=1) + "\n")
    files["summary"] = str(out_dir / "summary.json")
    pf = Path(params_file) if params_file else out_dir / "friction_params.yaml"
    if res.recommended:
        doc = export.fit_parameter_document(res)
        header = (
            f"# friction-fit: recommended model {res.recommended} from {', '.join(sources or [])}\n"
            f"# joint_type {fit_joint_type(res)}: coefficients SI ({units_note(fit_joint_type(res))}); "
            f"see {out_dir / 'report.md'}"
        )
        pf.parent.mkdir(parents=True, exist_ok=True)
        pf.write_text(export.dump_yaml(doc, header))
        files["params"] = str(pf)
    (out_dir / "report.md").write_text(markdown(res, sources, plot_files))
    files["report"] = str(out_dir / "report.md")
    res.files = files
    return files
