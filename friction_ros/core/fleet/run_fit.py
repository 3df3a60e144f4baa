"""One (run, joint) in, its fleet-table rows out: the friction-fit pipeline, no files written.

The run is read by :func:`~friction_ros.core.identification.data.log_loading.load_log` and fitted by
:func:`~friction_ros.core.identification.fit.pipeline.fit_records` with the options of
:data:`QUICK_OPTIONS` (a short daily run: the models the wear trend reads, no learned residual,
fewer global-search generations);
the joint type, units, recommendation and verdict are friction-fit's
(:func:`~friction_ros.core.identification.fit.recommendation.verdict_label`). One row per model
(the inverse-dynamics baseline included); a run that cannot be read or fitted gives one row with
``error`` set and ``compensate`` False. Never raises for a bad run. Pure: no rclpy.

Run statistics: ``load_rms = sqrt(mean(tau^2))`` of the measured effort, ``speed_rms =
sqrt(mean(v^2))``, ``duration_s = samples x dt``.
"""

from __future__ import annotations

import datetime as dt
import math
import os

import numpy as np

from friction_ros.core.fleet.discovery import RunTask
from friction_ros.core.fleet.temperature import run_temperature
from friction_ros.core.joint_type import quantity_units

#: fit options for short daily identification runs (friction-fit's defaults otherwise). The models
#: are the ones whose coefficients the wear trend follows (:data:`.trend.WEAR_COEFFICIENTS`: fc, fs,
#: fv): ``coulomb_viscous`` is linear in its coefficients (solved by least squares, no search) and
#: ``stribeck`` adds fs with a 3-coefficient search; the dynamic models (lugre, gms4: presliding,
#: 6x the CPU time per run) add nothing the trend reads.
QUICK_OPTIONS = {
    "models": ("coulomb_viscous", "stribeck"),
    "train_seconds": 10.0,
    "maxiter": 30,
    "residual": "none",
    "seed": 3,
    "max_samples": 60_000,
    "load": "auto",
}

#: test-only hook: a task whose path contains this text ends its worker process (a killed worker)
CRASH_MARK_ENV = "FRICTION_FLEET_TEST_CRASH"


def software_version() -> str:
    from friction_ros.core.bag.writer import package_version

    return f"friction_ros {package_version()}"


def _base_row(task: RunTask, joint_type: str) -> dict:
    return {
        "robot": task.robot,
        "joint": task.joint or "",
        "run_time": task.run_time,
        "model": "",
        "recommended": False,
        "coef_names": [],
        "coef_values": [],
        "coef_stderr": [],
        "joint_type": joint_type,
        "effort_unit": quantity_units(joint_type)["effort"],
        "validation_rms": math.nan,
        "validation_nmse_percent": math.nan,
        "explains": "",
        "compensate": False,
        "verdict": "fit failed",
        "error": "",
        "temperature_mean": math.nan,
        "temperature_min": math.nan,
        "temperature_max": math.nan,
        "load_rms": math.nan,
        "speed_rms": math.nan,
        "samples": 0,
        "duration_s": math.nan,
        "software_version": software_version(),
        "source_path": task.path,
        "source_sha256": task.source_sha256,
        "fitted_at": dt.datetime.now(dt.UTC),
    }


def error_rows(task: RunTask, why: str, joint_type: str | None = None) -> list[dict]:
    """The one row of a run that could not be fitted."""
    jt = joint_type or (task.joint_type if task.joint_type != "auto" else "revolute")
    return [{**_base_row(task, jt), "error": why or "failed"}]


def flat_coefficients(coefficients: dict, stderr: dict | None) -> tuple[list[str], list[float], list[float]]:
    """Coefficient names, values and standard errors, list-valued ones (GMS ``k``, ``alpha``) as
    ``k[0]``, ``k[1]`` ...; a standard error not determined is NaN."""
    names, values, errs = [], [], []
    stderr = stderr or {}
    for name in sorted(coefficients):
        v = coefficients[name]
        se = stderr.get(name)
        if isinstance(v, (list, tuple, np.ndarray)):
            ses = se if isinstance(se, (list, tuple, np.ndarray)) else [None] * len(v)
            for i, (x, s) in enumerate(zip(v, ses, strict=False)):
                names.append(f"{name}[{i}]")
                values.append(float(x))
                errs.append(math.nan if s is None else float(s))
            continue
        try:
            values.append(float(v))
        except (TypeError, ValueError):
            continue
        names.append(name)
        errs.append(math.nan if se is None or isinstance(se, (list, dict)) else float(se))
    return names, values, errs


def run_rows(task: RunTask, options: dict | None = None) -> list[dict]:
    """The rows of one (run, joint) (see module doc); ``options``: :data:`QUICK_OPTIONS` overrides."""
    mark = os.environ.get(CRASH_MARK_ENV)
    if mark and mark in task.path:
        os._exit(17)  # test hook: the worker dies mid-fit
    if task.problem:
        return error_rows(task, task.problem)
    try:
        return _fit(task, {**QUICK_OPTIONS, **(options or {})})
    except Exception as exc:  # a failed run never stops the others: its row says why
        text = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        return error_rows(task, text)


def _fit(task: RunTask, opts: dict) -> list[dict]:
    from friction_ros.core.identification.data.log_loading import is_csv, load_log
    from friction_ros.core.identification.fit.pipeline import fit_records
    from friction_ros.core.identification.fit.recommendation import verdict_label
    from friction_ros.core.identification.report.fit_logs import log_joint_type

    opts = dict(opts)
    models = tuple(opts.pop("models"))
    csv = is_csv(task.path)
    rec = load_log(
        task.path,
        task.topic,
        None if csv else task.joint,
        columns=task.columns,
        time_scale=task.time_scale,
    )
    jt, _ = log_joint_type(task.joint_type, [rec], [task.path], None if csv else task.joint)
    row = _base_row(task, jt)
    temps = run_temperature(task.path, task.temperature_column, task.temperature_topic)
    row.update(
        temperature_mean=temps[0],
        temperature_min=temps[1],
        temperature_max=temps[2],
        load_rms=float(np.sqrt(np.mean(np.square(rec.torque)))),
        speed_rms=float(np.sqrt(np.mean(np.square(rec.velocity)))),
        samples=int(rec.n),
        duration_s=float(rec.duration),
    )
    try:
        res = fit_records([rec], models, label=task.path, joint_type=jt, **opts)
    except Exception as exc:
        return [{**row, "error": str(exc).splitlines()[0] if str(exc) else type(exc).__name__}]
    label, nmse = verdict_label(res)
    text = (res.options.get("verdict") or {}).get("text") or (
        f"the recommended model {res.recommended} explains the measured torque (validation NMSE {nmse:.3g} %)"
        if res.recommended and nmse is not None
        else "no model is recommended"
    )
    rows = []
    for name in sorted(res.models):
        m = res.models[name]
        names, values, errs = flat_coefficients(m.coefficients, (m.identifiability or {}).get("stderr"))
        is_rec = name == res.recommended
        rows.append(
            {
                **row,
                "model": name,
                "recommended": is_rec,
                "coef_names": names if m.fitted else [],
                "coef_values": values if m.fitted else [],
                "coef_stderr": errs if m.fitted else [],
                "validation_rms": float(m.metrics.get("rmse", math.nan)) if m.fitted else math.nan,
                "validation_nmse_percent": float(m.metrics.get("nmse_percent", math.nan))
                if m.fitted
                else math.nan,
                "explains": text,
                "compensate": bool(is_rec and label == "ok" and m.config is not None),
                "verdict": label if res.recommended else "nothing recommended",
                "error": "" if m.fitted else f"{m.status}: {m.reason}",
            }
        )
    return rows
