"""Benchmark real_data, section 1 (and shared helpers): identification on the realistic synthetic joint
(known truth). See bench/real_data.py for what is measured."""

from __future__ import annotations

import math
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.append(str(ROOT / "bench"))  # after site-packages: bench/can.py must not shadow python-can

from _common import print_table, warm_kernels  # noqa: E402

from friction_ros.core.friction.learned_residual import LearnedResidual  # noqa: E402
from friction_ros.core.identification.data.records import concat_records, prepare  # noqa: E402
from friction_ros.core.identification.fit.pipeline import fit_records  # noqa: E402
from friction_ros.core.identification.report.fit_logs import cross_validate_runs  # noqa: E402
from friction_ros.core.synthetic.realistic_joint import (  # noqa: E402
    JointTruth,
    pooled_measured_input_nmse_percent,
    pooled_noise_floor_nmse_percent,
    realistic_runs,
)

RIPPLE_PERIOD = 2.0 * math.pi / 100.0  # the truth's ripple: motor angle of the 100:1 harmonic drive
MAP_SPEEDS = np.geomspace(0.005, 0.4, 200)  # |v| [rad/s] of the friction-map comparison
STEP_CALLS = 10_000


def _f(x, digits: int = 3) -> str:
    """A float for a table cell (NaN/None as '-')."""
    if x is None or (isinstance(x, float) and not math.isfinite(x)):
        return "-"
    return f"{x:.{digits}f}"


def _nmse(pred, y) -> float:
    pred, y = np.asarray(pred, float), np.asarray(y, float)
    return float(100.0 * np.mean((pred - y) ** 2) / np.var(y))


def _warm_kernels(rec) -> None:
    warm_kernels(rec, ("lugre",))


def _map_error_percent(model, truth: JointTruth) -> float:
    """max |F_fit(v) - F_true(v)| / max |F_true(v)| over 0.005 <= |v| <= 0.4 rad/s, both directions [%]."""
    v = np.concatenate([-MAP_SPEEDS[::-1], MAP_SPEEDS])
    ft = truth.friction_map(v)
    ff = np.asarray(model.steady_state(v), dtype=float)
    return float(100.0 * np.max(np.abs(ff - ft)) / np.max(np.abs(ft)))


def _load_errors(model, truth: JointTruth) -> dict:
    """Identified load terms against the truth (gravity and k_L in %, the others as values)."""
    ld = model.extra.get("load") or {}
    out = {"load": ld}
    g = ld.get("gravity")
    kl = ld.get("load_friction")
    out["gravity_error_percent"] = 100.0 * abs(g - truth.gravity) / truth.gravity if g is not None else None
    out["load_friction_error_percent"] = (
        100.0 * abs(kl - truth.load_friction) / truth.load_friction if ld and kl is not None else None
    )
    out["spring"] = ld.get("spring")
    out["offset"] = ld.get("offset")  # truth: offset + sensor offset (one constant to a fitter)
    out["gravity_phase"] = ld.get("gravity_phase")
    return out


def _model_rows(res, truth: JointTruth) -> dict:
    out = {}
    for n, m in res.models.items():
        le = _load_errors(m, truth)
        out[n] = {
            "nmse_percent": float(m.metrics.get("nmse_percent", math.nan)),
            "rmse": float(m.metrics.get("rmse", math.nan)),
            "fit_s": float(m.seconds),
            "n_params": int(m.metrics.get("n_params", 0)),
            "map_error_percent": _map_error_percent(m, truth),
            "J": float(m.coefficients.get("J", math.nan)),
            "coefficients": {
                k: float(v) for k, v in m.coefficients.items() if np.isscalar(v) and not isinstance(v, str)
            },
            **le,
        }
    return out


def _residual_entries(label: str, res) -> list[dict]:
    """Every '<name>+residual' model of a fit: its report and the 10,000-call step() median."""
    out = []
    for n, m in res.models.items():
        if "residual_report" not in m.extra:
            continue
        cfg = m.extra["residual"]
        rec = concat_records(res.validation)
        out.append(
            {
                "data": label,
                "model": n,
                "chosen": cfg.get("kind"),
                "candidates": m.extra["residual_report"],
                "step_us_median_10k": _time_step(LearnedResidual(cfg), rec.position, rec.velocity),
                "nmse_percent": float(m.metrics["nmse_percent"]),
                "base_nmse_percent": float(res.models[n.split("+")[0]].metrics["nmse_percent"]),
                "recommended": res.recommended == n,
            }
        )
    return out


def _time_step(model: LearnedResidual, q, v, n: int = STEP_CALLS) -> float:
    """Median time [us] of ``n`` single step() calls on a record's samples (cycled)."""
    q = np.resize(np.asarray(q, float), n).tolist()
    v = np.resize(np.asarray(v, float), n).tolist()
    model.reset()
    step, clock = model.step, time.perf_counter
    for a, b in zip(q[:1000], v[:1000]):  # warm-up (caches, allocator) before the timed calls
        step(a, b, 0.0)
    model.reset()
    times = []
    for a, b in zip(q, v):
        t0 = clock()
        step(a, b, 0.0)
        times.append(clock() - t0)
    model.reset()
    return float(np.median(times) * 1e6)


# ------------------------------------------------------------------------------------ synthetic
def synthetic(quick: bool) -> tuple[dict, object]:
    truth = JointTruth()
    duration = 20.0 if quick else 40.0
    models = ["coulomb_viscous", "stribeck"] if quick else ["coulomb_viscous", "stribeck", "lugre", "nusvr"]
    runs = realistic_runs(truth, duration=duration, seed=0)
    recs = [prepare(r.stamp, r.position, r.velocity, r.effort, source=r.name) for r in runs]
    _warm_kernels(recs[0])
    floors = {
        "noise_floor_nmse_percent": pooled_noise_floor_nmse_percent(runs),
        "measured_input_nmse_percent": pooled_measured_input_nmse_percent(runs),
        "per_run": [r.summary() for r in runs],
        "noise_rms": float(np.sqrt(np.mean(np.concatenate([r.torque_noise for r in runs]) ** 2))),
        "measured_input_rms": float(
            np.sqrt(np.mean(np.concatenate([r.measured_input_torque() - r.effort for r in runs]) ** 2))
        ),
    }
    opts = dict(identifiability_check=False, ripple_period=RIPPLE_PERIOD)
    t0 = time.perf_counter()
    res = fit_records(recs, models, load="auto", residual="auto", **opts)
    auto_s = time.perf_counter() - t0
    # the floor on the fitter's own inputs: the true model on the validation samples' velocity and
    # acceleration as the loader derives them from the logged positions (what every model gets)
    y = np.concatenate([r.torque for r in res.validation])
    e = y - np.concatenate(
        [truth.torque(r.position, r.velocity, r.acceleration) + truth.sensor_offset for r in res.validation]
    )
    floors["loader_input_nmse_percent"] = float(100.0 * np.mean(e**2) / np.var(y))
    floors["loader_input_rms"] = float(np.sqrt(np.mean(e**2)))
    t0 = time.perf_counter()
    res_none = fit_records(recs, models, load="none", residual="auto", **opts)
    none_s = time.perf_counter() - t0
    t0 = time.perf_counter()
    cv = cross_validate_runs(recs, ["coulomb_viscous", "stribeck"], residual="none", **opts)
    cv_s = time.perf_counter() - t0

    out = {
        "notes": _synthetic_notes(res, res_none, cv, floors, truth),
        "truth": truth.to_dict(),
        "duration_s": duration,
        "runs": len(runs),
        "samples": [r.n for r in recs],
        "ripple_period": RIPPLE_PERIOD,
        "models": models,
        "floors": floors,
        "load_auto": {
            "total_s": auto_s,
            "recommended": res.recommended,
            "load_terms": res.options["load_terms"],
            "load_selection": res.options["load_selection"],
            "warnings": list(res.warnings),
            "models": _model_rows(res, truth),
        },
        "load_none": {
            "total_s": none_s,
            "recommended": res_none.recommended,
            "warnings": list(res_none.warnings),
            "models": _model_rows(res_none, truth),
        },
        "cross_validation": {**cv, "total_s": cv_s},
    }
    a = out["load_auto"]
    rows = []
    for n, m in a["models"].items():
        rows.append(
            [
                n + (" *" if n == res.recommended else ""),
                _f(m["nmse_percent"], 4),
                _f(m["rmse"], 4),
                _f(m["fit_s"], 2),
                _f(m["map_error_percent"], 2),
                _f(m["gravity_error_percent"], 2),
                _f(m["load_friction_error_percent"], 1),
                _f(m["spring"], 3),
                _f(m["offset"], 3),
                _f(m["J"], 3),
            ]
        )
    rows.append(
        ["noise floor (pooled)", _f(floors["noise_floor_nmse_percent"], 4), _f(floors["noise_rms"], 4)]
    )
    rows.append(
        [
            "true model, measured q, v (pooled)",
            _f(floors["measured_input_nmse_percent"], 4),
            _f(floors["measured_input_rms"], 4),
        ]
    )
    rows.append(
        [
            "true model, loader's q, v, a (validation)",
            _f(floors["loader_input_nmse_percent"], 4),
            _f(floors["loader_input_rms"], 4),
        ]
    )
    rows = [r + ["-"] * (10 - len(r)) for r in rows]
    print_table(
        f"Realistic synthetic joint: {len(runs)} runs x {duration:g} s at 2 ms, load=auto ({a['load_terms']}), "
        f"ripple_period = 2 pi/100; truth gravity {truth.gravity:g}, k_L {truth.load_friction:g}, spring "
        f"{truth.spring:g}, offset+sensor {truth.offset + truth.sensor_offset:g}, J {truth.J:g}; map error over "
        "0.005-0.4 rad/s; * = recommended",
        [
            "model",
            "val NMSE %",
            "RMS [N*m]",
            "fit [s]",
            "map err %",
            "gravity err %",
            "k_L err %",
            "spring",
            "offset",
            "J",
        ],
        rows,
    )
    nn = out["load_none"]["models"]
    print_table(
        "What the load terms bring (same models, load=none; validation NMSE %, RMS and friction-map error)",
        ["model", "NMSE auto", "NMSE none", "RMS none [N*m]", "map err % none", "J none"],
        [
            [
                n,
                _f(a["models"][n]["nmse_percent"], 4) if n in a["models"] else "-",
                _f(m["nmse_percent"], 3),
                _f(m["rmse"], 3),
                _f(m["map_error_percent"], 1),
                _f(m["J"], 3),
            ]
            for n, m in nn.items()
        ],
    )
    print_table(
        "Cross-validation over runs (train on the other two runs, validate on this one; load=auto, no residual)",
        ["validation run", "recommended", "coulomb_viscous NMSE %", "stribeck NMSE %"],
        [
            [
                f["validation"],
                f["recommended"],
                _f(f["nmse_percent"].get("coulomb_viscous"), 4),
                _f(f["nmse_percent"].get("stribeck"), 4),
            ]
            for f in cv["folds"]
        ]
        + [
            [
                "mean",
                "-",
                _f(cv["mean_nmse_percent"].get("coulomb_viscous"), 4),
                _f(cv["mean_nmse_percent"].get("stribeck"), 4),
            ]
        ],
    )
    return out, res


def _synthetic_notes(res, res_none, cv, floors, truth: JointTruth) -> list[str]:
    """Plain statements of what the synthetic fits show (computed, so they follow the numbers)."""
    notes = []
    rec = res.recommended
    m = res.models[rec]
    nm = float(m.metrics["nmse_percent"])
    fl = floors["measured_input_nmse_percent"]
    fv = floors["loader_input_nmse_percent"]
    notes.append(
        f"synthetic: recommended {rec} validates at NMSE {nm:.4f} % = {nm / fv:.2f} x the true model on the same "
        f"validation inputs ({fv:.4f} %), {nm / fl:.2f} x the true model on the drive's velocity and the true "
        f"acceleration ({fl:.4f} %; the loader differentiates the positions instead) and "
        f"{nm / floors['noise_floor_nmse_percent']:.0f} x the pooled noise floor"
    )
    js = {n: float(r.coefficients.get("J", math.nan)) for n, r in res.models.items() if "+" not in n}
    notes.append(
        "synthetic: identified inertia J (truth "
        + f"{truth.J:g} kg m^2): "
        + ", ".join(f"{n} {j:.3f}" for n, j in js.items())
    )
    rn = res_none.recommended
    if rn:
        mn = res_none.models[rn]
        notes.append(
            f"synthetic, load=none: recommended {rn} at NMSE {float(mn.metrics['nmse_percent']):.2f} %"
            + (" (flagged)" if res_none.options["verdict"]["explains_little"] else " (not flagged)")
            + "; physics models alone: "
            + ", ".join(
                f"{n} {float(r.metrics['nmse_percent']):.1f} %"
                for n, r in res_none.models.items()
                if "+" not in n
            )
        )
    worst = max(cv["folds"], key=lambda f: min(f["nmse_percent"].values()))
    notes.append(
        f"synthetic, cross-validation: the hardest held-out run is {worst['validation']} (best NMSE "
        f"{min(worst['nmse_percent'].values()):.3f} %) against a mean of "
        + ", ".join(f"{n} {v:.3f} %" for n, v in cv["mean_nmse_percent"].items())
    )
    return notes
