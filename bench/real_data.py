"""Benchmark: identification on realistic and real joint data (issue 17).

1. Realistic synthetic joint (:mod:`friction_ros.core.identification.realistic_joint`, known truth:
   gravity 12 N*m, spring, offset + sensor offset, Stribeck map, load-dependent friction k_L = 0.03 and
   a Coulomb ripple at the motor angle of the 100:1 harmonic drive; 3 runs x 40 s at 2 ms, seed 0).
   ``fit_records`` with load="auto", residual="auto" and ``ripple_period = 2 pi / 100`` (the truth's
   ripple repeats once per wave-generator turn = 1/100 of a link turn; the fitter's default 2 pi would
   look for it at the link angle and miss it), models coulomb_viscous, stribeck, lugre, nusvr:
   validation NMSE, RMS, fit time, the static friction map against the truth's (max |F_fit - F_true| /
   max |F_true| over 0.005 <= |v| <= 0.4 rad/s, both directions), gravity and load-friction errors,
   next to the noise floors (pooled noise floor; the true model fed the logged position and velocity).
   The same fit with load="none" shows what the load terms bring; cross-validation over the runs
   (train on two, validate on the third) shows what a user deploying the model gets on a new run.
2. Real pendulum (DFKI torque-limited simple pendulum, AK80-6 motor, real logs): per run
   (pd_system_identification, energy_shaping, gravity_compensation) coulomb_viscous and stribeck with
   load="auto" and load="none" (train_seconds ~40 % of the run; residual="auto" as friction-fit): NMSE, RMS, recommended model, the
   chosen load terms, the identified gravity m g l against the authors' m cx g = 0.1022 * 9.81 = 1.003
   N*m, whether the fit was flagged (verdict explains_little). Data checks: the authors' own model
   (system_identification.txt) on every run, tau against a sin q + b, the share of torque beyond the
   kit's 4 N*m limit. Uses /work/shared/data/dfki_pendulum when present, else the sys-id run copied
   into test/data/dfki_pendulum (a user's clone): the printed notes and the JSON say which.
3. Learned residual inference time: per residual candidate the report's step() time, and for every
   exported residual the median of 10,000 single ``LearnedResidual.step`` calls (goal < 20 us).
4. Gauntlet (bench/_gauntlet.py): the fitter with friction-fit's defaults on every class of log users
   bring (friction_ros.core.synthetic_logs: ball-screw axis in m/N, hobby servo, coupled arm, LuGre
   creep, coarse encoder, jittered/missing samples, saturation, one direction only) and both joints
   of the real DFKI double pendulum: recommended model, validation NMSE, verdict and warnings per log.
5. Long logs (``bench/long_logs.py``): friction-fit on a 60 s, 10 min and 1 h log (bag, and the 1 h
   one as CSV) and on a 7-joint 21 s arm bag with ``--jobs 2``: seconds and peak RSS, each in its own
   process.

    .venv/bin/python bench/real_data.py            # full (~100 s CPU + the gauntlet's ~4 min CPU)
    .venv/bin/python bench/real_data.py --quick    # 20 s runs, no lugre/nusvr (smoke test)
    .venv/bin/python bench/real_data.py --gauntlet # section 4 alone (bench/_gauntlet.py)
    .venv/bin/python bench/real_data.py --section long_logs   # friction-fit on 60 s .. 1 h logs, 7-joint arm
"""

from __future__ import annotations

import argparse
import math
import os
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.append(str(ROOT / "bench"))  # after site-packages: bench/can.py must not shadow python-can

from _common import print_table, write_results  # noqa: E402
from _gauntlet import gauntlet  # noqa: E402

from friction_ros.core.friction.learned_residual import LearnedResidual  # noqa: E402
from friction_ros.core.identification.csv_loading import load_csv  # noqa: E402
from friction_ros.core.identification.fit_logs import cross_validate_runs  # noqa: E402
from friction_ros.core.identification.models import spec_for  # noqa: E402
from friction_ros.core.identification.pipeline import fit_records  # noqa: E402
from friction_ros.core.identification.realistic_joint import (  # noqa: E402
    JointTruth,
    pooled_measured_input_nmse_percent,
    pooled_noise_floor_nmse_percent,
    realistic_runs,
)
from friction_ros.core.identification.records import concat_records, prepare  # noqa: E402
from friction_ros.core.identification.residual_learning import fit_residual  # noqa: E402

RIPPLE_PERIOD = 2.0 * math.pi / 100.0  # the truth's ripple: motor angle of the 100:1 harmonic drive
MAP_SPEEDS = np.geomspace(0.005, 0.4, 200)  # |v| [rad/s] of the friction-map comparison
SHARED = Path("/work/shared/data/dfki_pendulum")
IN_REPO = ROOT / "test" / "data" / "dfki_pendulum"
PENDULUM_RUNS = ("pd_system_identification", "energy_shaping", "gravity_compensation")
AUTHORS = {"J": 6.259e-02, "mcx": 1.022e-01, "Fv": 4.707e-02, "Fc": 1.839e-01, "offset": -7.586e-02}
G = 9.81
AUTHORS_GRAVITY = AUTHORS["mcx"] * G  # m cx g [N*m]
KIT_TORQUE_LIMIT = 4.0  # [N*m] sp_parameters_gravity.yaml torque_limit
TRAIN_SHARE = 0.4  # pendulum: train_seconds ~40 % of the run (rounded to 0.5 s)
STEP_CALLS = 10_000
GOAL = {"map_percent": 5.0, "gravity_percent": 2.0, "load_friction_percent": 10.0, "floor_ratio": 1.5}
STEP_GOAL_US = 20.0


def _f(x, digits: int = 3) -> str:
    """A float for a table cell (NaN/None as '-')."""
    if x is None or (isinstance(x, float) and not math.isfinite(x)):
        return "-"
    return f"{x:.{digits}f}"


def _nmse(pred, y) -> float:
    pred, y = np.asarray(pred, float), np.asarray(y, float)
    return float(100.0 * np.mean((pred - y) ** 2) / np.var(y))


def _warm_kernels(rec) -> None:
    """Compile (or load from the numba cache) the dynamic kernels so fit times are fit times."""
    tr = rec.slice(0, 200)
    for name in ("lugre",):
        spec = spec_for(name)
        spec.grams(
            spec.from_search(np.array([np.mean(b) for b in spec.search_bounds()]))[None, :],
            tr.velocity[:100],
            tr.acceleration[:100],
            tr.torque[:100],
            tr.dt,
        )


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


# ------------------------------------------------------------------------------------ pendulum
def _authors_torque(rec) -> np.ndarray:
    a = AUTHORS
    return (
        a["J"] * rec.acceleration
        + a["mcx"] * G * np.sin(rec.position)
        + a["Fv"] * rec.velocity
        + a["Fc"] * np.arctan(100.0 * rec.velocity)
        + a["offset"]
    )


def _data_checks(rec, res) -> dict:
    """Measured properties of one real run (not assumed)."""
    y = rec.torque
    x = np.column_stack([np.sin(rec.position), np.ones(rec.n)])
    c, *_ = np.linalg.lstsq(x, y, rcond=None)
    big = np.abs(y) > KIT_TORQUE_LIMIT
    val = concat_records(res.validation)
    # the best any rigid-body pendulum with friction can do, fitted in-sample by least squares
    rb = np.column_stack(
        [
            rec.acceleration,
            np.sin(rec.position),
            np.cos(rec.position),
            rec.velocity,
            np.tanh(rec.velocity / 0.05),
            np.ones(rec.n),
        ]
    )
    cr, *_ = np.linalg.lstsq(rb, y, rcond=None)
    return {
        "samples": rec.n,
        "dt_s": float(rec.dt),
        "duration_s": float(rec.duration),
        "torque_range": [float(y.min()), float(y.max())],
        "velocity_range": [float(rec.velocity.min()), float(rec.velocity.max())],
        "authors_nmse_percent": _nmse(_authors_torque(rec), y),
        "authors_nmse_validation_percent": _nmse(_authors_torque(val), val.torque),
        "sin_fit": {"a": float(c[0]), "b": float(c[1]), "nmse_percent": _nmse(x @ c, y)},
        "rigid_body_lstsq": {
            "columns": "J a + g_s sin q + g_c cos q + Fv v + Fc tanh(v / 0.05) + offset (whole run, in-sample)",
            "J": float(cr[0]),
            "gravity": float(math.hypot(cr[1], cr[2])),
            "gravity_sin": float(cr[1]),
            "Fv": float(cr[3]),
            "Fc": float(cr[4]),
            "offset": float(cr[5]),
            "nmse_percent": _nmse(rb @ cr, y),
        },
        "beyond_torque_limit": {
            "limit": KIT_TORQUE_LIMIT,
            "sample_share_percent": float(100.0 * np.mean(big)),
            "energy_share_percent": float(100.0 * np.sum(y[big] ** 2) / np.sum(y**2)),
        },
    }


def _pendulum_fit(res) -> dict:
    rec = res.recommended
    m = res.models.get(rec) if rec else None
    ld = (m.extra.get("load") or {}) if m else {}
    g = ld.get("gravity")
    return {
        "recommended": rec,
        "load_terms": res.options["load_terms"],
        "flagged": bool(res.options["verdict"]["explains_little"]),
        "verdict": res.options["verdict"].get("text", ""),
        "warnings": list(res.warnings),
        "total_s": float(res.seconds),
        "gravity": g,
        "gravity_vs_authors_percent": 100.0 * (g / AUTHORS_GRAVITY - 1.0) if g is not None else None,
        "models": {
            n: {
                "nmse_percent": float(mm.metrics.get("nmse_percent", math.nan)),
                "rmse": float(mm.metrics.get("rmse", math.nan)),
                "fit_s": float(mm.seconds),
                "gravity": (mm.extra.get("load") or {}).get("gravity"),
                "load": mm.extra.get("load"),
                "coefficients": {
                    k: float(v)
                    for k, v in mm.coefficients.items()
                    if np.isscalar(v) and not isinstance(v, str)
                },
            }
            for n, mm in res.models.items()
        },
    }


def pendulum(quick: bool) -> tuple[dict, dict]:
    if SHARED.is_dir():
        source, names = SHARED, PENDULUM_RUNS
    else:
        source, names = IN_REPO, PENDULUM_RUNS[:1]
    out: dict = {"source": str(source), "authors": dict(AUTHORS, gravity_mcx_g=AUTHORS_GRAVITY), "runs": {}}
    fits = {}
    for name in names:
        rec = load_csv(source / f"control_method_{name}.csv")
        ts = max(0.5, round(TRAIN_SHARE * rec.duration * 2.0) / 2.0)
        run: dict = {"train_seconds": ts}
        for load in ("auto", "none"):
            res = fit_records(
                rec,
                ["coulomb_viscous", "stribeck"],
                identifiability_check=False,
                load=load,
                train_seconds=ts,
                residual="auto",
            )
            run[f"load_{load}"] = _pendulum_fit(res)
            fits[(name, load)] = res
        run["data"] = _data_checks(rec, fits[(name, "auto")])
        out["runs"][name] = run

    rows = []
    for name, run in out["runs"].items():
        for load in ("auto", "none"):
            f = run[f"load_{load}"]
            mm = f["models"]
            rows.append(
                [
                    name,
                    load,
                    f"{run['train_seconds']:g}",
                    f["recommended"],
                    f["load_terms"],
                    _f(mm["coulomb_viscous"]["nmse_percent"], 2),
                    _f(mm["stribeck"]["nmse_percent"], 2),
                    _f(mm[f["recommended"]]["rmse"], 3) if f["recommended"] else "-",
                    _f(f["gravity"], 3),
                    "yes" if f["flagged"] else "no",
                ]
            )
    print_table(
        f"Real pendulum (DFKI, {source}): validation NMSE % per fit; gravity = identified m g l of the "
        f"recommended model vs the authors' m cx g = {AUTHORS_GRAVITY:.3f} N*m; flagged = verdict explains_little",
        [
            "run",
            "load",
            "train [s]",
            "recommended",
            "load terms",
            "coulomb_viscous",
            "stribeck",
            "RMS rec. [N*m]",
            "gravity [N*m]",
            "flagged",
        ],
        rows,
    )
    print_table(
        "Real pendulum data checks: the authors' model (tau = J qdd + m cx g sin q + Fv qd + Fc atan(100 qd) + "
        f"offset) NMSE %, tau ~ a sin q + b, the in-sample least-squares rigid-body fit (J a + gravity sin/cos + "
        f"Fv v + Fc tanh(v/0.05) + offset), torque beyond the kit's {KIT_TORQUE_LIMIT:g} N*m limit",
        [
            "run",
            "samples",
            "dt [ms]",
            "authors NMSE (run)",
            "authors NMSE (validation)",
            "a [N*m]",
            "b [N*m]",
            "a sin q + b NMSE",
            "rigid-body LS NMSE",
            "LS J",
            "|tau| > limit: samples %",
            "energy %",
        ],
        [
            [
                name,
                run["data"]["samples"],
                _f(1e3 * run["data"]["dt_s"], 2),
                _f(run["data"]["authors_nmse_percent"], 1),
                _f(run["data"]["authors_nmse_validation_percent"], 1),
                _f(run["data"]["sin_fit"]["a"], 3),
                _f(run["data"]["sin_fit"]["b"], 3),
                _f(run["data"]["sin_fit"]["nmse_percent"], 3),
                _f(run["data"]["rigid_body_lstsq"]["nmse_percent"], 1),
                _f(run["data"]["rigid_body_lstsq"]["J"], 4),
                _f(run["data"]["beyond_torque_limit"]["sample_share_percent"], 1),
                _f(run["data"]["beyond_torque_limit"]["energy_share_percent"], 1),
            ]
            for name, run in out["runs"].items()
        ],
    )
    out["findings"] = _findings(out)
    return out, fits


def _findings(out: dict) -> list[str]:
    """Plain statements of what the numbers show (computed, so they follow the data)."""
    notes = []
    if out["source"] != str(SHARED):
        notes.append(
            f"{SHARED} not found: used the sys-id run copied into the repo ({out['source']}); the energy-shaping "
            "and gravity-compensation runs are not in the repo"
        )
    for name, run in out["runs"].items():
        d = run["data"]
        an = d["authors_nmse_percent"]
        notes.append(
            f"{name}: the authors' model gives NMSE {an:.1f} % on the whole run "
            f"({d['authors_nmse_validation_percent']:.1f} % on our validation part)"
            + (": it does not reproduce this run (worse than predicting the mean)" if an > 100.0 else "")
        )
        sf = d["sin_fit"]
        if sf["nmse_percent"] < 1.0:
            notes.append(
                f"{name}: the torque is {sf['a']:.3f} sin(q) {sf['b']:+.3f} N*m up to NMSE {sf['nmse_percent']:.3f} % "
                f"(max {d['torque_range'][1]:.2f} N*m): a commanded gravity compensation, not a measured joint torque; "
                f"its gravity {sf['a']:.3f} N*m is {sf['a'] / AUTHORS_GRAVITY:.2f} x the authors' m cx g = "
                f"{AUTHORS_GRAVITY:.3f} N*m and it carries no friction to identify"
            )
        rb = d["rigid_body_lstsq"]
        if rb["nmse_percent"] > 30.0:
            notes.append(
                f"{name}: even an in-sample least-squares rigid-body fit (J a + gravity + viscous + Coulomb + offset) "
                f"leaves NMSE {rb['nmse_percent']:.1f} % (J = {rb['J']:.4f} kg m^2, gravity {rb['gravity']:.3f} N*m): "
                "the logged torque does not follow the pendulum's dynamics, so no friction model can fit it"
            )
        bt = d["beyond_torque_limit"]
        if bt["sample_share_percent"] > 1.0:
            notes.append(
                f"{name}: {bt['sample_share_percent']:.1f} % of the samples exceed the kit's {KIT_TORQUE_LIMIT:g} N*m "
                f"torque limit (range {d['torque_range'][0]:.1f} to {d['torque_range'][1]:.1f} N*m) and hold "
                f"{bt['energy_share_percent']:.0f} % of sum(tau^2): short torque spikes dominate the signal"
            )
        fa, fn = run["load_auto"], run["load_none"]
        ra, rn = fa["recommended"], fn["recommended"]
        if ra and rn:
            na, nn = fa["models"][ra]["nmse_percent"], fn["models"][rn]["nmse_percent"]
            if na > nn:
                notes.append(
                    f"{name}: load=auto ({fa['load_terms']}) validates worse than load=none "
                    f"({na:.1f} % vs {nn:.1f} %): the load terms chosen on the backbone do not carry over"
                )
    return notes


# ------------------------------------------------------------------------------------ residual
def residual_timing(syn_res, pend_fits: dict) -> dict:
    entries = _residual_entries("synthetic", syn_res)
    for (name, load), res in pend_fits.items():
        entries += _residual_entries(f"pendulum {name} load={load}", res)
    fallback = None
    if not entries:  # no residual chosen anywhere: one on the synthetic recommended model's residual
        base = syn_res.models[syn_res.recommended]
        tr = syn_res.train
        model, rep = fit_residual(
            [r.position for r in tr],
            [r.velocity for r in tr],
            None,
            [r.torque - base.predict(r) for r in tr],
            float(tr[0].dt),
            kind="auto",
            seed=0,
        )
        if model is None:  # nothing beat r = 0: time the MLP anyway (the run-time cost is the same)
            model = rep["models"]["mlp"]
        rec = concat_records(tr)
        fallback = {
            "chosen": rep["chosen"],
            "kind": model.kind,
            "candidates": {
                c: {k: v for k, v in i.items() if isinstance(v, (int, float, str, bool))}
                for c, i in rep["candidates"].items()
            },
            "step_us_median_10k": _time_step(model, rec.position, rec.velocity),
        }
    rows = []
    for e in entries:
        for c, info in e["candidates"].items():
            rows.append(
                [
                    e["data"],
                    e["model"] + (" *" if e["recommended"] else ""),
                    c + (" (chosen)" if c == e["chosen"] else ""),
                    info.get("n_params", "-"),
                    _f(info.get("fit_s"), 2),
                    _f(info.get("validation_nmse_percent"), 1),
                    _f(info.get("step_us"), 1),
                    _f(e["step_us_median_10k"], 1) if c == e["chosen"] else "-",
                ]
            )
    if fallback:
        for c, info in fallback["candidates"].items():
            rows.append(
                [
                    "synthetic (fit_residual, fallback)",
                    "-",
                    c + (" (timed)" if c == fallback["kind"] else ""),
                    info.get("n_params", "-"),
                    _f(info.get("fit_s"), 2),
                    _f(info.get("validation_nmse_percent"), 1),
                    _f(info.get("step_us"), 1),
                    _f(fallback["step_us_median_10k"], 1) if c == fallback["kind"] else "-",
                ]
            )
    print_table(
        f"Learned residual: candidates of every '+residual' model (residual validation NMSE % = of the physics "
        f"model's residual; step = per-sample run-time evaluation; goal < {STEP_GOAL_US:g} us; * = recommended)",
        [
            "data",
            "model",
            "candidate",
            "params",
            "fit [s]",
            "resid. NMSE %",
            "step [us] report",
            "step [us] 10k median",
        ],
        rows,
    )
    steps = [e["step_us_median_10k"] for e in entries] + (
        [fallback["step_us_median_10k"]] if fallback else []
    )
    return {"entries": entries, "fallback": fallback, "max_step_us": max(steps) if steps else None}


# ------------------------------------------------------------------------------------ goals
def goals(syn: dict, pend: dict, resid: dict) -> list[dict]:
    a = syn["load_auto"]
    rec = a["recommended"]
    m = a["models"][rec]
    floor = syn["floors"]["loader_input_nmse_percent"]
    out = [
        {
            "goal": f"synthetic: friction map of the recommended model ({rec}) within {GOAL['map_percent']:g} %",
            "measured": m["map_error_percent"],
            "met": m["map_error_percent"] <= GOAL["map_percent"],
        },
        {
            "goal": f"synthetic: gravity within {GOAL['gravity_percent']:g} % ({rec})",
            "measured": m["gravity_error_percent"],
            "met": m["gravity_error_percent"] is not None
            and m["gravity_error_percent"] <= GOAL["gravity_percent"],
        },
        {
            "goal": f"synthetic: load-friction coefficient k_L within {GOAL['load_friction_percent']:g} % ({rec})",
            "measured": m["load_friction_error_percent"],
            "met": m["load_friction_error_percent"] is not None
            and m["load_friction_error_percent"] <= GOAL["load_friction_percent"],
        },
        {
            "goal": f"synthetic: recommended validation NMSE within {GOAL['floor_ratio']:g} x the true model on "
            f"the same validation inputs ({floor:.4f} %; velocity and acceleration from the logged positions)",
            "measured": m["nmse_percent"] / floor,
            "met": m["nmse_percent"] <= GOAL["floor_ratio"] * floor,
        },
    ]
    gc = pend["runs"].get("gravity_compensation")
    if gc:
        out.append(
            {
                "goal": "pendulum: gravity term selected on the gravity_compensation run (load=auto)",
                "measured": gc["load_auto"]["load_terms"],
                "met": "gravity" in gc["load_auto"]["load_terms"].split(", "),
            }
        )
        out.append(
            {
                "goal": "pendulum: the no-gravity fit (load=none) of the gravity_compensation run flagged",
                "measured": f"flagged: {gc['load_none']['flagged']}",
                "met": gc["load_none"]["flagged"],
            }
        )
    else:
        out.append({"goal": "pendulum: gravity_compensation run", "measured": "not available", "met": None})
    out.append(
        {
            "goal": f"learned residual step() under {STEP_GOAL_US:g} us per sample (max over exported residuals)",
            "measured": resid["max_step_us"],
            "met": resid["max_step_us"] is not None and resid["max_step_us"] < STEP_GOAL_US,
        }
    )
    print_table(
        "Goals (issue 17)",
        ["goal", "measured", "met"],
        [
            [
                g["goal"],
                _f(g["measured"], 3) if isinstance(g["measured"], float) else str(g["measured"]),
                {True: "yes", False: "NO", None: "-"}[g["met"]],
            ]
            for g in out
        ],
    )
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument(
        "--quick", action="store_true", help="20 s synthetic runs, coulomb_viscous and stribeck only"
    )
    ap.add_argument("--gauntlet", action="store_true", help="run the gauntlet section alone")
    ap.add_argument(
        "--section",
        choices=["all", "identification", "long_logs"],
        default="all",
        help="long_logs: only the long-log rows (bench/long_logs.py), merged into real_data.json",
    )
    args = ap.parse_args()
    if args.section == "long_logs":
        return _long_logs_only()
    t_wall, t_cpu = time.perf_counter(), time.process_time()
    if args.gauntlet:
        figures = {
            "gauntlet": gauntlet(args.quick),
            "quick": args.quick,
            "wall_s": time.perf_counter() - t_wall,
        }
        name = "real_data_gauntlet" + ("_quick" if args.quick else "")
        write_results(
            name,
            figures,
            ".venv/bin/python bench/real_data.py --gauntlet" + (" --quick" if args.quick else ""),
        )
        return
    load_start = os.getloadavg()[0]  # other processes on the machine slow the step() timings
    syn, syn_res = synthetic(args.quick)
    pend, pend_fits = pendulum(args.quick)
    resid = residual_timing(syn_res, pend_fits)
    gaunt = gauntlet(args.quick)
    gl = goals(syn, pend, resid)
    notes = syn["notes"] + pend["findings"]
    print("\nNotes (measured on this run):")
    for n in notes:
        print(f"- {n}")
    figures = {
        "synthetic": syn,
        "pendulum": pend,
        "residual": resid,
        "gauntlet": gaunt,
        "goals": gl,
        "notes": notes,
        "load_average_1min": {"start": load_start, "end": os.getloadavg()[0]},
        "quick": args.quick,
        "wall_s": time.perf_counter() - t_wall,
        "cpu_s": time.process_time() - t_cpu,
    }
    if args.section == "all" and not args.quick:
        import long_logs

        figures["long_logs"] = long_logs.run(print_table)
    print(
        f"\nrun time: {figures['wall_s']:.0f} s wall, {figures['cpu_s']:.0f} s CPU (1-min load average "
        f"{load_start:.1f} at the start, {figures['load_average_1min']['end']:.1f} at the end, {os.cpu_count()} cores)"
    )
    write_results(
        "real_data" + ("_quick" if args.quick else ""),
        figures,
        ".venv/bin/python bench/real_data.py" + (" --quick" if args.quick else ""),
    )


def _long_logs_only() -> None:
    """The long-log rows alone, merged into the figures of bench/results/real_data.json."""
    import json

    import long_logs

    path = ROOT / "bench" / "results" / "real_data.json"
    figures = json.loads(path.read_text()).get("figures", {}) if path.is_file() else {}
    figures["long_logs"] = long_logs.run(print_table)
    write_results("real_data", figures, ".venv/bin/python bench/real_data.py --section long_logs")


if __name__ == "__main__":
    main()
