"""Every joint of a bag (``friction-fit BAG --joint all`` or ``--joint j1,j3``): one fit per joint,
one parameter file for the multi-joint nodes.

Each joint is fitted by :func:`~friction_ros.core.identification.report.fit_logs.fit_bag` exactly as
``friction-fit BAG --joint J --out OUT/J`` fits it (same options; its report, summary, plots and
single-joint parameter file go to ``OUT/J/``). The fits are independent: with ``jobs > 1`` they run
in a process pool; results are gathered in joint order, so every file is the same for any ``jobs``.

The parameter file holds ``compensating_controller`` and ``friction_estimator`` in the per-joint
layout of :mod:`friction_ros.core.joint_config`: ``joints: [...]``, ``<section>.<joint>.<key>``
(``friction.j3.model``, ``compensation.j3.source``, ``load.j3.gravity``, ``residual.j3.*``) and
``gains.<joint>.<key>`` for the PID keys and the plain keys (``gains.j3.p``, ``gains.j3.inertia``).
Every joint has its own ``friction.<joint>.model`` (none at node level) and its own
``gains.<joint>.effort_limit`` (the controller refuses to start without one): the plant preset's
torque limit, else 1.5 x the log's peak |effort| (:func:`~friction_ros.core.identification.data.data_scale.effort_limit_of_log`). A
value is written at node level only when every joint has the same one. Compensation is written
disabled (``compensation.<joint>.source: none``, the reason in ``refused_reasons`` for every
source in ``refused``: the node refuses to run them unless ``allow_refused``) for a joint whose fit
failed, whose recommended model explains nothing (validation NMSE >= 100 %, no better than a
constant; ``friction.<joint>.model: none``) or explains little (NMSE above the verdict's threshold:
the model is kept for inspection); each is named in a warning.
``OUT/index.md`` (and ``index.json``) tabulate every joint: model, validation NMSE, verdict.
"""

from __future__ import annotations

import json
import math
import multiprocessing
import os
import time
from collections.abc import Callable, Sequence
from concurrent.futures import ProcessPoolExecutor
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

from friction_ros.core.config import Schema, flatten, unflatten
from friction_ros.core.identification.data.joint_selection import (  # noqa: F401 (re-exported)
    ALL,
    bag_joint_names,
    is_joint_list,
    requested_joints,
)
from friction_ros.core.identification.fit.fit_units import fit_joint_type, units_note
from friction_ros.core.joint_config import JointLayout, joint_values
from friction_ros.core.validation import ParameterError

#: what a joint that is not compensated gets in the controller section
NOT_COMPENSATED = {"friction": {"model": "none"}, "compensation": {"source": "none"}}
#: the compensation sources written refused for a joint that is not compensated
REFUSED_SOURCES = ("feedforward", "feedback", "blended")
#: sections never written at node level (a per-joint model replaces the whole section)
PER_JOINT_ONLY = ("friction",)


# ------------------------------------------------------------------------------------ one joint
@dataclass
class JointFit:
    """What one joint's fit left for the multi-joint file and the index (plain data: crosses processes).

    ``verdict``: ``ok`` (compensated), ``explains little`` (its model written, compensation
    disabled with the reason), ``explains nothing`` or ``fit failed`` (both written with
    ``friction.<joint>.model: none``). ``document``: the single-joint parameter document (None when
    the fit failed). ``reason``: why compensation is disabled ("" when compensated).
    ``effort_limit``: the joint's torque (force) limit (nan when the log has no effort).
    """

    joint: str
    verdict: str
    recommended: str | None = None
    nmse_percent: float | None = None
    written_model: str = "none"
    compensation: str = "none"
    coefficients: dict = field(default_factory=dict)
    document: dict | None = None
    warnings: list[str] = field(default_factory=list)
    files: dict = field(default_factory=dict)
    seconds: float = 0.0
    joint_type: str = "revolute"
    reason: str = ""
    effort_limit: float = math.nan

    @property
    def compensated(self) -> bool:
        return self.verdict == "ok"


def fit_one_joint(task: dict) -> JointFit:
    """Fit one joint (``task``: fit_bag's arguments with ``joint`` and ``out_dir``); module level so
    a process pool can run it. A fit the data refuse (ParameterError, ValueError) is a failed joint."""
    from friction_ros.core.identification.fit.recommendation import verdict_label
    from friction_ros.core.identification.report.export import fit_parameter_document
    from friction_ros.core.identification.report.fit_logs import fit_bag
    from friction_ros.core.identification.report.report import _clean

    t0 = time.perf_counter()
    joint = task["joint"]
    try:
        res = fit_bag(**task)
        if not res.recommended:
            raise ParameterError("no model could be recommended")
        doc = fit_parameter_document(res)
    except (ParameterError, ValueError) as exc:
        return JointFit(
            joint,
            "fit failed",
            warnings=[f"fit failed: {exc}"],
            seconds=time.perf_counter() - t0,
            # the joint type asked for (``auto`` when the log was to say it: revolute in the index)
            joint_type=fit_joint_type(
                {"joint_type": task.get("joint_type") if task.get("joint_type") != "auto" else None}
            ),
            reason=f"fit failed: {str(exc).splitlines()[0]}",
            effort_limit=_effort_limit_without_fit(task),
        )
    rec = res.models[res.recommended]
    label, nmse = verdict_label(res)
    out = JointFit(
        joint,
        label,
        recommended=res.recommended,
        nmse_percent=nmse,
        coefficients=_clean(dict(rec.coefficients)),
        document=_plain(doc),
        warnings=list(res.warnings) + [f"compensation {m}: {v.reason}" for m, v in (res.gate or {}).items()],
        files={k: v for k, v in res.files.items() if not k.startswith("plot:")},
        joint_type=fit_joint_type(res),
        effort_limit=float(res.effort_limit),
    )
    if label != "ok":
        nm = "n/a" if nmse is None else f"{nmse:.1f} %"
        from friction_ros.core.identification.fit.recommendation import EXPLAINS_LITTLE_NMSE

        out.reason = (
            f"the fit {label} of the measured torque (validation NMSE {nm} > {EXPLAINS_LITTLE_NMSE:g} %): "
            "do not compensate with it before checking"
        )
    if label != "explains nothing":
        cc = doc["compensating_controller"]["ros__parameters"]
        out.written_model = str(cc["friction"].get("model", "none"))
        out.compensation = (
            str(cc.get("compensation", {}).get("source", "none")) if out.compensated else "none"
        )
    out.seconds = time.perf_counter() - t0
    return out


def _worker_threads(threads: int) -> None:
    """Pool worker set-up: its share of the cores for the compiled fit kernels (the workers already
    run side by side: two workers with two threads each on two cores would contend for them)."""
    import numba

    # a user's NUMBA_NUM_THREADS (or the test runner's) caps it
    numba.set_num_threads(max(1, min(threads, numba.config.NUMBA_NUM_THREADS)))


# ------------------------------------------------------------------------------------ parameter file
def _plain(x):
    """Nested dicts/lists of Python values (numpy scalars and arrays converted; inf and nan kept)."""
    if isinstance(x, dict):
        return {k: _plain(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_plain(v) for v in x]
    if hasattr(x, "tolist"):
        return _plain(x.tolist())
    return x


def _same(a, b) -> bool:
    """Equal values, nan equal to nan and dict order ignored."""
    return json.dumps(a, sort_keys=True) == json.dumps(b, sort_keys=True)


def controller_layout(joints: Sequence[str]) -> JointLayout:
    """The compensating_controller's per-joint layout: its sections, ``pid`` as the gains section,
    the controller's plain fields as plain keys."""
    from friction_ros.core.control.controller_config import CONTROLLER_FIELDS, controller_parameter_schema
    from friction_ros.core.control.pid import PID_SCHEMA

    sections = [s.name for s in controller_parameter_schema() if isinstance(s, Schema)]
    return JointLayout(
        joints,
        sections,
        "pid",
        [f.name for f in PID_SCHEMA if not isinstance(f, Schema)],
        [f.name for f in CONTROLLER_FIELDS] + ["joint_type"],
    )


def estimator_layout(joints: Sequence[str]) -> JointLayout:
    """The friction_estimator's per-joint layout: its sections (``initial``, ``lugre``), its plain
    fields as ``gains.<joint>.<key>``."""
    from friction_ros.core.estimation.estimator import ESTIMATOR_SCHEMA

    items = list(ESTIMATOR_SCHEMA)
    return JointLayout(
        joints,
        [s.name for s in items if isinstance(s, Schema)],
        None,
        (),
        [f.name for f in items if not isinstance(f, Schema)] + ["joint_type"],
    )


def per_joint_section(values: dict[str, dict], layout: JointLayout) -> dict:
    """{joint: nested node values} -> one nested section: ``joints``, the values every joint shares
    at node level (never a :data:`PER_JOINT_ONLY` section), the rest as per-joint names. Checked: each
    joint's values read back through ``layout`` equal its own."""
    joints = list(values)
    flat = {j: flatten(v) for j, v in values.items()}
    common = {
        k: v
        for k, v in flat[joints[0]].items()
        if k.split(".")[0] not in PER_JOINT_ONLY
        and (len(k.split(".")) < 2 or k.split(".")[1] not in joints)  # would read as per-joint
        and all(k in f and _same(f[k], v) for f in flat.values())
    }
    out: dict[str, Any] = {"joints": joints, **common}
    for j in joints:
        out.update({layout.joint_name(j, k): v for k, v in flat[j].items() if k not in common})
    nested = unflatten(out)
    # read back as a node does: node-level values with each joint's overrides on top
    node_flat, per_joint = layout.split_all({k: v for k, v in flatten(nested).items() if k != "joints"})
    node_values = unflatten(node_flat)
    for j in joints:
        if not _same(joint_values(node_values, per_joint[j]), unflatten(flat[j])):
            raise RuntimeError(f"per-joint parameters of {j} do not read back as written (a name clash)")
    return nested


def _effort_limit_without_fit(task: dict) -> float:
    """The effort limit of a joint whose fit failed: its plant preset's, else from its log (nan
    when neither says)."""
    from friction_ros.core.identification.data.data_scale import effort_limit_of_log
    from friction_ros.core.identification.data.log_loading import load_log

    if task.get("plant_preset"):
        from friction_ros.core.experiment.joint_scale import JointScale
        from friction_ros.core.presets import load_preset

        return float(JointScale.from_preset(load_preset(task["plant_preset"])).torque_limit)
    try:
        topic = task.get("topic", "/joint_states")
        return effort_limit_of_log([load_log(p, topic, task["joint"]) for p in task["bag_paths"]])
    except (ParameterError, ValueError, OSError):
        return math.nan


def controller_values(f: JointFit) -> dict:
    """One joint's compensating_controller values (module docstring): its fitted section when it is
    compensated; else compensation disabled with the reason (the model kept when the fit explains
    little), always with its effort limit."""
    if f.compensated:
        values = dict(f.document["compensating_controller"]["ros__parameters"])
    else:
        disabled = {
            "source": "none",
            "refused": list(REFUSED_SOURCES),
            "refused_reasons": [f.reason or f"the fit {f.verdict}"] * len(REFUSED_SOURCES),
        }
        if f.verdict == "explains little" and f.document:
            values = dict(f.document["compensating_controller"]["ros__parameters"])
            values["compensation"] = {**values.get("compensation", {}), **disabled}
            for key in ("load", "load_feedforward", "residual"):  # no feedforward of any fitted term
                values.pop(key, None)
            values["compensation"].pop("gain", None)
            values["compensation"].pop("blend", None)
        else:
            values = {**NOT_COMPENSATED, "compensation": disabled, "joint_type": f.joint_type}
    if math.isfinite(f.effort_limit):
        values["effort_limit"] = float(f.effort_limit)
    return values


def joint_parameter_document(fits: Sequence[JointFit]) -> dict:
    """The multi-joint parameter document of ``fits`` (module docstring)."""
    joints = [f.joint for f in fits]
    cc = {f.joint: controller_values(f) for f in fits}
    doc = {"compensating_controller": {"ros__parameters": per_joint_section(cc, controller_layout(joints))}}
    est = {
        f.joint: (f.document or {}).get("friction_estimator", {}).get("ros__parameters", {})
        if f.compensated
        else {}
        for f in fits
    }
    if any(est.values()):  # a joint without a fit keeps the estimator's defaults
        doc["friction_estimator"] = {"ros__parameters": per_joint_section(est, estimator_layout(joints))}
    return doc


def _units_of(fits: Sequence[JointFit]) -> str:
    """The parameter file's units: the joints' one joint type's, or each joint's own."""
    types = sorted({f.joint_type for f in fits})
    if len(types) == 1:
        return units_note(types[0])
    return "each joint in its joint_type's units: " + "; ".join(f"{t}: {units_note(t)}" for t in types)


# ------------------------------------------------------------------------------------ all joints
@dataclass
class MultiFit:
    joints: list[JointFit]
    document: dict
    files: dict[str, str]

    @property
    def warnings(self) -> list[str]:
        """One line per problem, each naming its joint (a joint written without compensation first)."""
        out = []
        for f in self.joints:
            if not f.compensated:
                why = f.warnings[0] if f.verdict == "fit failed" else f"the fit {f.verdict}"
                written = (
                    f"compensation.{f.joint}.source: none (its model kept for inspection)"
                    if f.written_model != "none"
                    else f"friction.{f.joint}.model: none (no compensation)"
                )
                out.append(f"{f.joint}: {why}: written with {written}")
        for f in self.joints:
            skip = 1 if f.verdict == "fit failed" else 0
            out += [f"{f.joint}: {w}" for w in f.warnings[skip:] if not w.startswith("compensation ")]
        return out


def fit_joints(
    bag_paths: Sequence,
    joints: Sequence[str],
    models,
    out_dir,
    *,
    params_file=None,
    jobs: int = 1,
    on_joint: Callable[[JointFit], None] | None = None,
    **fit_options,
) -> MultiFit:
    """Fit each of ``joints`` as :func:`fit_bag` does (``fit_options``: its keyword arguments), into
    ``out_dir/<joint>/``; write the multi-joint parameter file (``params_file``, default
    ``out_dir/friction_params.yaml``) and ``out_dir/index.md`` / ``index.json``. ``jobs``: processes
    for the fits (1: in this process). ``on_joint``: called with each joint's result, in joint order."""
    from friction_ros.core.identification.report import export

    out = Path(out_dir)
    bag_paths = [str(p) for p in bag_paths]
    fit_options.pop("progress", None)  # a callback does not cross processes; the same for any jobs
    tasks = [
        {
            "bag_paths": bag_paths,
            "joint": j,
            "models": list(models),
            "out_dir": str(out / j),
            **fit_options,
        }
        for j in joints
    ]
    fits: list[JointFit] = []
    if jobs > 1 and len(tasks) > 1:
        # spawn: a fresh interpreter per worker (no fork of a process with threads)
        ctx = multiprocessing.get_context("spawn")
        workers = min(jobs, len(tasks))
        threads = max(1, (os.cpu_count() or 1) // workers)
        with ProcessPoolExecutor(
            max_workers=workers, mp_context=ctx, initializer=_worker_threads, initargs=(threads,)
        ) as pool:
            futures = [pool.submit(fit_one_joint, t) for t in tasks]
            for fut in futures:  # joint order, whatever order they finish in
                fits.append(fut.result())
                if on_joint:
                    on_joint(fits[-1])
    else:
        for t in tasks:
            fits.append(fit_one_joint(t))
            if on_joint:
                on_joint(fits[-1])
    doc = joint_parameter_document(fits)
    pf = Path(params_file) if params_file else out / "friction_params.yaml"
    header = (
        f"# friction-fit: joints {', '.join(joints)} from {', '.join(bag_paths)}\n"
        f"# coefficients SI ({_units_of(fits)}); per-joint reports: {out / 'index.md'}"
    )
    pf.parent.mkdir(parents=True, exist_ok=True)
    pf.write_text(export.dump_yaml(doc, header))
    result = MultiFit(fits, doc, {"params": str(pf)})
    out.mkdir(parents=True, exist_ok=True)
    (out / "index.md").write_text(index_markdown(result, bag_paths))
    (out / "index.json").write_text(json.dumps(index_json(result, bag_paths), indent=1) + "\n")
    result.files.update(index=str(out / "index.md"), index_json=str(out / "index.json"))
    return result


def _nmse(x: float | None) -> str:
    return "-" if x is None else f"{x:.4g}"


def index_rows(result: MultiFit) -> list[list[str]]:
    """[joint, recommended model, validation NMSE %, verdict, written model, compensation] per joint."""
    return [
        [f.joint, f.recommended or "-", _nmse(f.nmse_percent), f.verdict, f.written_model, f.compensation]
        for f in result.joints
    ]


INDEX_HEADER = ["joint", "model", "NMSE %", "verdict", "written", "compensation"]


def index_markdown(result: MultiFit, sources: Sequence[str]) -> str:
    L = ["# Friction identification: all joints", "", f"Data: {', '.join(sources)}", ""]
    L.append(
        "One fit per joint, as `friction-fit --joint <joint>` (its report in `<joint>/report.md`); "
        f"parameter file for the multi-joint nodes: `{result.files['params']}`. NMSE: validation NMSE of "
        "the recommended model. A joint written `none` is not compensated."
    )
    L += ["", "| joint | recommended | validation NMSE % | verdict | written model | compensation | report |"]
    L.append("|---|---|---|---|---|---|---|")
    for f, row in zip(result.joints, index_rows(result)):
        rep = f"[{f.joint}/report.md]({f.joint}/report.md)" if f.files.get("report") else "-"
        L.append("| " + " | ".join([*row, rep]) + " |")
    if result.warnings:
        L += ["", "## Warnings", ""] + [f"- {w}" for w in result.warnings]
    return "\n".join(L) + "\n"


def index_json(result: MultiFit, sources: Sequence[str]) -> dict:
    return {
        "tool": "friction-fit",
        "sources": list(sources),
        "params": result.files["params"],
        "joints": {
            f.joint: {k: v for k, v in asdict(f).items() if k not in ("joint", "document", "seconds")}
            for f in result.joints
        },
        "warnings": result.warnings,
    }
