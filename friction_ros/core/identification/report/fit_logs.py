"""Logs in, files out: read bags or CSV logs, fit, write the report, summary and parameter file.

* :func:`fit_bag` ``(bag_paths, topic, joint, models, out_dir, options=None, **kw) -> FitResult``;
* :func:`cross_validate_runs`: train on all runs but one, validate on it, for each run;
* :func:`log_joint_type`: revolute or prismatic, as asked or from the log's metadata.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from friction_ros.core.identification.data.log_loading import load_log
from friction_ros.core.identification.data.records import JointData
from friction_ros.core.identification.fit.fit_options import FitOptions
from friction_ros.core.identification.fit.fit_results import FitResult
from friction_ros.core.identification.fit.models import check_model_names
from friction_ros.core.identification.fit.pipeline import DEFAULT_MODELS, fit_records
from friction_ros.core.joint_type import JOINT_TYPES, detect_joint_type
from friction_ros.core.validation import ParameterError, check_choice


def fit_bag(
    bag_paths,
    topic: str = "/joint_states",
    joint: str | None = None,
    models=DEFAULT_MODELS,
    out_dir="friction_fit",
    *,
    events_topic: str | None = "/experiment_events",
    current_topic: str | None = None,
    current_field: str | None = None,
    torque_constant: float | None = None,
    gear_ratio: float = 1.0,
    params_file: str | None = None,
    plots: bool = True,
    torque_delay: float = 0.0,
    plant_preset: str | None = None,
    gate: dict | None = None,
    columns: dict | None = None,
    time_scale: float = 1.0,
    cross_validate: bool = False,
    validate_on=None,
    joint_type: str = "auto",
    options: FitOptions | None = None,
    progress=None,
    **kw,
) -> FitResult:
    """Read bags, fit ``models`` and write into ``out_dir``:

    ``report.md`` (Markdown report), ``summary.json`` (every model's coefficients, metrics and
    steady-state map), ``friction_params.yaml`` (or ``params_file``: ROS parameters of the
    recommended model for compensating_controller, friction_estimator, plant_simulator),
    ``plots/*.png`` (friction-velocity map, presliding hysteresis, time-domain validation,
    residuals). ``gate``: keyword arguments of
    :func:`friction_ros.core.identification.fit.gating.gate_fit`; the compensation modes of the
    parameter file are then checked in closed loop first (refused ones written disabled).
    ``cross_validate``: with several logs, also :func:`cross_validate_runs` (``options["cross_validation"]``).
    ``validate_on``: logs read like ``bag_paths`` that only validate (the inputs then only train).
    ``joint_type``: ``revolute``, ``prismatic`` or ``auto`` (:func:`log_joint_type`).
    ``options`` (:class:`~friction_ros.core.identification.fit.fit_options.FitOptions`) and ``kw`` (single
    options): :func:`~friction_ros.core.identification.fit.pipeline.fit_records`'s; ``progress`` too.
    """
    from friction_ros.core.identification.report import report

    if isinstance(bag_paths, (str, Path)):
        bag_paths = [bag_paths]
    check_model_names(models)
    opts = FitOptions.resolve(options, kw)  # a bad option is refused before any log is read
    read = dict(
        columns=columns,
        time_scale=time_scale,
        events_topic=events_topic,
        current_topic=current_topic,
        current_field=current_field,
        torque_constant=torque_constant,
        gear_ratio=gear_ratio,
        torque_delay=torque_delay,
    )
    recs = [load_log(p, topic, joint, **read) for p in bag_paths]
    val_recs = [load_log(p, topic, joint, **read) for p in (validate_on or [])]
    jt, jt_source = log_joint_type(joint_type, recs, bag_paths, joint)
    opts = opts.replace(label=", ".join(str(p) for p in bag_paths), joint_type=jt)  # the folds' too
    res = fit_records(
        recs,
        models,
        opts,
        validation_records=val_recs or None,
        progress=progress,
    )
    res.options["joint_type_source"] = jt_source
    if val_recs:
        res.options["validated_on"] = [str(p) for p in validate_on]
    if cross_validate:
        if len(recs) < 2:
            res.warnings.append("--cross-validate needs two or more runs: skipped")
        else:
            res.options["cross_validation"] = cross_validate_runs(recs, models, opts)
    res.options["plant_preset"] = plant_preset
    if gate is not None:  # the safety gate before the parameter file enables a mode
        from friction_ros.core.identification.fit.gating import gate_fit

        gate_fit(res, **gate)
    report.write_outputs(
        res,
        Path(out_dir),
        params_file=params_file,
        plots=plots,
        sources=[str(p) for p in bag_paths],
        topic=topic,
        joint=joint,
    )
    return res


def log_joint_type(requested: str, records, paths=(), joint: str | None = None) -> tuple[str, str]:
    """(joint type, where it came from): ``requested`` unless ``auto``; then what the records' or
    the logs' metadata state (:func:`~friction_ros.core.joint_type.detect_joint_type`: a bag's
    metadata, an embedded parameter file or URDF, CSV column names), else revolute."""
    check_choice("joint_type", requested, ["auto", *JOINT_TYPES])
    if requested != "auto":
        return requested, "given"
    found = {r.meta.get("joint_type") for r in records} - {None}
    if len(found) == 1 and (jt := found.pop()) in JOINT_TYPES:
        return jt, "the log's metadata"
    for p in map(Path, paths):
        columns = _csv_header(p) if p.suffix.lower() == ".csv" else None
        jt, why = detect_joint_type(columns=columns, path=p if p.is_dir() else None, joint=joint)
        if jt in JOINT_TYPES:
            return jt, why
    return (
        "revolute",
        "nothing in the log states it: revolute assumed (--joint-type prismatic for a linear axis)",
    )


def _csv_header(path: Path) -> list[str] | None:
    try:
        with path.open(errors="replace") as f:
            line = f.readline()
    except OSError:
        return None
    return [c.strip() for c in line.split(",")]


def cross_validate_runs(
    records: list[JointData],
    models=DEFAULT_MODELS,
    options: FitOptions | None = None,
    *,
    progress=None,
    **kw,
) -> dict:
    """Cross-validation over runs: for each record, train on all the others and validate on it.

    What a user deploying a model needs to know: how it does on a run it has not seen. Returns
    ``{"joint_type": ..., "folds": [{"validation": source, "recommended": name, "nmse_percent": {model: NMSE}}, ...],
    "mean_nmse_percent": {model: mean over folds}}``; needs at least two records. ``options``,
    ``kw`` and ``progress`` are :func:`fit_records`'s (without the identifiability check).
    """
    records = [records] if isinstance(records, JointData) else list(records)
    if len(records) < 2:
        raise ParameterError(f"cross-validation over runs needs >= 2 runs: got {len(records)}")
    options = FitOptions.resolve(options, kw).replace(identifiability_check=False)
    folds = []
    for k, held in enumerate(records):
        rest = records[:k] + records[k + 1 :]
        res = fit_records(rest, models, options, validation_records=[held], progress=progress)
        folds.append(
            {
                "validation": held.meta.get("source", f"run {k}"),
                "recommended": res.recommended,
                "nmse_percent": {
                    n: float(m.metrics.get("nmse_percent", math.nan)) for n, m in res.models.items()
                },
            }
        )
    names = sorted({n for f in folds for n in f["nmse_percent"]})
    mean = {n: float(np.mean([f["nmse_percent"].get(n, math.nan) for f in folds])) for n in names}
    return {"joint_type": options.joint_type, "folds": folds, "mean_nmse_percent": mean}
