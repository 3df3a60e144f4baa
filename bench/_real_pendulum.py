"""Benchmark real_data, section 2: the real DFKI pendulum logs (data checks, fits with and without load
terms). See bench/real_data.py for what is measured."""

from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.append(str(ROOT / "bench"))  # after site-packages: bench/can.py must not shadow python-can

from _common import print_table  # noqa: E402
from _real_synthetic import _f, _nmse  # noqa: E402

from friction_ros.core.identification.data.csv_loading import load_csv  # noqa: E402
from friction_ros.core.identification.data.records import concat_records  # noqa: E402
from friction_ros.core.identification.fit.pipeline import fit_records  # noqa: E402

SHARED = Path("/work/shared/data/dfki_pendulum")
IN_REPO = ROOT / "test" / "data" / "dfki_pendulum"
PENDULUM_RUNS = ("pd_system_identification", "energy_shaping", "gravity_compensation")
AUTHORS = {"J": 6.259e-02, "mcx": 1.022e-01, "Fv": 4.707e-02, "Fc": 1.839e-01, "offset": -7.586e-02}
G = 9.81
AUTHORS_GRAVITY = AUTHORS["mcx"] * G  # m cx g [N*m]
KIT_TORQUE_LIMIT = 4.0  # [N*m] sp_parameters_gravity.yaml torque_limit
TRAIN_SHARE = 0.4  # pendulum: train_seconds ~40 % of the run (rounded to 0.5 s)


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
