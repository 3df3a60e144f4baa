"""The identification pipeline: records -> fitted models -> comparison -> outputs.

Public entry points (stable signatures):

* :func:`fit_bag` ``(bag_paths, topic, joint, models, out_dir, **options) -> FitResult``
  reads one or more bags and writes the report, JSON summary, plots and parameter YAML;
* :func:`fit_records` ``(records, models, **options) -> FitResult`` on prepared
  :class:`~friction_ros.core.identification.records.JointData` (no files);
* :func:`load_bag` ``(path, topic, joint, ...) -> JointData``.
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from friction_ros.core.experiment.events import Event
from friction_ros.core.identification import export, identifiability, learned, metrics
from friction_ros.core.identification.breakaway_detection import Breakaway, find_breakaways
from friction_ros.core.identification.dynamic_fit import DynamicFit, fit_time_domain
from friction_ros.core.identification.excitation_checks import (
    Excitation,
    check_excitation,
    check_motion,
    excitation,
)
from friction_ros.core.identification.models import (
    DEFAULT_EPS,
    LEARNED,
    check_model_names,
    sat_sign,
    spec_for,
)
from friction_ros.core.identification.plateau_detection import (
    Plateau,
    chattering_plateaus,
    find_plateaus,
    load_offset,
)
from friction_ros.core.identification.records import ExcitationError, JointData, concat_records, prepare
from friction_ros.core.identification.static_fit import StaticFit, fit_plateaus, stribeck_map
from friction_ros.core.identification.training_split import split, training_segments, training_window
from friction_ros.core.identification.velocity_regimes import (
    high_velocity_mask,
    mask_runs,
    moving_mask,
    standstill_mask,
)
from friction_ros.core.validation import ParameterError, check_choice

DEFAULT_MODELS = ("coulomb", "stribeck", "lugre", "gms4")
EXPLAINS_LITTLE_NMSE = 30.0  # [%] validation NMSE above which a recommendation comes with a warning


@dataclass
class ModelResult:
    """One fitted model with everything the report needs."""

    name: str
    method: str  # "plateaus", "time-domain (de)", "learned"
    coefficients: dict
    config: dict | None
    metrics: dict
    identifiability: dict
    seconds: float
    steady_state: Callable[[np.ndarray], np.ndarray]
    predict: Callable[[JointData], np.ndarray]
    notes: list[str] = field(default_factory=list)
    extra: dict = field(default_factory=dict)


@dataclass
class FitResult:
    """Everything one fit produced; ``files`` lists what :func:`fit_bag` wrote."""

    models: dict[str, ModelResult]
    recommended: str | None
    train: list[JointData]
    validation: list[JointData]
    plateaus: list[Plateau]
    breakaways: list[Breakaway]
    excitation: Excitation
    high_threshold: float
    options: dict
    files: dict[str, str] = field(default_factory=dict)
    warnings: list[str] = field(default_factory=list)
    seconds: float = 0.0
    recommendation: dict = field(default_factory=dict)
    gate: dict = field(default_factory=dict)

    @property
    def inertia(self) -> float:
        m = self.models.get(self.recommended) if self.recommended else None
        return float(m.coefficients.get("J", 0.0)) if m else 0.0

    def parameter_document(self, model: str | None = None, **gate_options) -> dict:
        """``gate_options``: ``gate`` (verdicts), ``gains``, ``load_feedforward`` (export.parameter_document)."""
        name = model or self.recommended
        m = self.models[name]
        if m.config is None:
            raise ParameterError(f"model {name!r} has no friction-library form: choose a parametric model")
        opts = dict(self.options.get("gate_options") or {}, **gate_options)
        opts.setdefault("load_feedforward", float(self.options.get("load_offset", 0.0) or 0.0))
        return export.parameter_document(
            m.config, m.coefficients.get("J", 0.0), plant_preset=self.options.get("plant_preset"), **opts
        )


# ------------------------------------------------------------------------------------ loading
def load_bag(
    path,
    topic: str = "/joint_states",
    joint: str | None = None,
    *,
    events_topic: str | None = "/experiment_events",
    current_topic: str | None = None,
    current_field: str | None = None,
    torque_constant: float | None = None,
    gear_ratio: float = 1.0,
    velocity_window: float = 0.021,
    acceleration_window: float = 0.041,
    torque_delay: float = 0.0,
) -> JointData:
    """Read a joint of a JointState topic (and event markers) from a bag into JointData."""
    from friction_ros.core.bag import BagError, read_bag

    path = Path(path)
    if not path.exists():
        raise ExcitationError(f"bag {path}: no such file or directory")
    try:
        bag = read_bag(path, topics=None)
    except BagError as exc:
        raise ExcitationError(f"bag {path}: {exc}") from None
    bag_warnings = [str(w) for w in getattr(bag, "warnings", [])]
    if getattr(bag, "truncated", False) and not bag_warnings:
        bag_warnings.append(f"bag {path} is truncated: the messages after the cut are lost")
    if topic not in bag:
        have = ", ".join(sorted(bag.topics)) if hasattr(bag, "topics") else "?"
        raise ExcitationError(
            f"bag {path} has no topic {topic} (topics: {have}): record the joint states "
            "(sensor_msgs/JointState) with the identification experiment, or pass --topic"
        )
    js = bag[topic]
    names = js.joint_names
    if joint is None:
        if len(names) != 1:
            raise ExcitationError(
                f"bag {path}: topic {topic} has joints {', '.join(names)}: choose one with --joint"
            )
        joint = names[0]
    try:
        series = js.joint(joint)
    except BagError as exc:
        raise ExcitationError(str(exc)) from None
    try:
        stamps = series.stamp
    except BagError:
        stamps = series.time
    if not np.all(np.isfinite(stamps)) or np.all(stamps == 0):
        stamps = series.time
    events = []
    if events_topic and events_topic in bag:
        ev = bag[events_topic]
        try:
            et = ev.stamp
        except BagError:
            et = ev.time
        for i in range(len(ev)):
            events.append(
                Event(
                    float(et[i]),
                    str(ev["program"][i]),
                    str(ev["segment"][i]),
                    int(ev["index"][i]),
                    int(ev["event"][i]),
                    float(ev["target"][i]),
                    str(ev["note"][i]),
                )
            )
    current = current_t = None
    effort = series.effort
    if current_field:
        ct = bag[current_topic] if current_topic else js
        current = ct[current_field]
        if current.ndim > 1:
            col = names.index(joint) if ct is js else 0
            current = current[:, col]
        current_t = ct.time
        effort = None
    elif not np.any(np.isfinite(effort)):
        raise ExcitationError(
            f"bag {path}: joint {joint!r} on {topic} has no effort: pass the motor current with "
            "--current-topic/--current-field plus --torque-constant and --gear-ratio"
        )
    data = prepare(
        stamps,
        series.position,
        series.velocity,
        effort,
        current=current,
        current_t=current_t,
        torque_constant=torque_constant,
        gear_ratio=gear_ratio,
        events=events,
        velocity_window=velocity_window,
        acceleration_window=acceleration_window,
        torque_delay=torque_delay,
        source=str(path),
    )
    data.meta["warnings"] = bag_warnings + data.meta.get("warnings", [])
    return data


# ------------------------------------------------------------------------------------ fitting
def _grid(records: list[JointData]) -> np.ndarray:
    v = np.concatenate([np.abs(r.velocity) for r in records])
    vmax = float(np.max(v))
    moving = v[v > 1e-6]
    vmin = max(float(np.percentile(moving, 1)) if moving.size else 1e-4, 1e-4, vmax * 1e-4)
    g = np.geomspace(vmin, max(vmax, vmin * 10), 60)
    return np.concatenate([-g[::-1], g])


def fit_records(
    records: JointData | list[JointData],
    models=DEFAULT_MODELS,
    *,
    train_seconds: float = 10.0,
    train_window: str = "content",
    optimizer: str = "de",
    maxiter: int | dict | None = None,
    popsize: int = 12,
    seed: int = 3,
    eps: float = DEFAULT_EPS,
    high_threshold: float | None = None,
    identifiability_check: bool = True,
    two_stage: bool = True,
    progress: Callable[[str, float], None] | None = None,
    label: str = "data",
) -> FitResult:
    """Fit ``models`` to prepared records (see module and package docstrings).

    ``train_window``: ``"content"`` (default) trains on chunks stratified by content
    (:func:`~friction_ros.core.identification.training_split.training_segments`, about ``train_seconds``
    in all) and validates on the rest; ``"window"`` on the single most exciting ``train_seconds``
    window (:func:`~friction_ros.core.identification.training_split.training_window`); ``"first"`` on the
    first ``train_seconds`` (seed 003 A.3).
    """
    check_choice("train_window", train_window, ["content", "window", "first"])
    t_start = time.perf_counter()
    records = [records] if isinstance(records, JointData) else list(records)
    names = check_model_names(models)
    if not records:
        raise ParameterError("records = []: need at least one record")
    for r in records:
        check_motion(r, r.meta.get("source", label))
    load, load_note = load_offset([p for r in records for p in find_plateaus(r)])
    if load:
        records = [dataclasses.replace(r, torque=r.torque - load) for r in records]
    train, val, val_from = [], [], []
    windows = []
    for r in records:
        if r.duration > train_seconds + 1.0:
            if train_window == "first":
                segs = [(0, split(r, train_seconds)[0].n)]
            elif train_window == "window":
                segs = [training_window(r, train_seconds)]
            else:
                segs = training_segments(r, train_seconds)
            keep = np.ones(r.n, bool)
            for i0, i1 in segs:
                keep[i0:i1] = False
                train.append(r.slice(i0, i1))
                windows.append((float(r.t[i0]), float(r.t[i1 - 1])))
            val.append(concat_records([r.slice(a, b) for a, b in mask_runs(keep)]))
            val_from.append((r, keep))
    if not val:  # records too short to split: validate on the training data (reported)
        train = list(records)
        val = list(records)
        val_from = [(r, np.ones(r.n, bool)) for r in records]
        warnings_pre = [
            f"records shorter than train_seconds + 1 s ({train_seconds:g} s): validated on training data"
        ]
    else:
        warnings_pre = []
    for r in records:  # what reading the data found: a truncated bag, missing positions ...
        warnings_pre += [f"{r.meta.get('source', label)}: {w}" for w in r.meta.get("warnings", [])]
    if load:
        warnings_pre.append(load_note)

    def predict_val(model) -> np.ndarray:
        # dynamic states run through the whole record (one simulation); validation = outside the window
        return np.concatenate([model.predict(full)[keep] for full, keep in val_from])

    plateaus = [p for r in records for p in find_plateaus(r)]
    chatter = chattering_plateaus(plateaus)
    if chatter:
        worst = max(p.torque_std / max(abs(p.torque), 1e-300) for p in chatter)
        res_note = f" ({records[0].resolution:.3g} per count)" if records[0].resolution > 0 else ""
        warnings_pre.append(
            f"the velocity loop chattered on {len(chatter)} of {len(plateaus)} plateaus (torque scatter up to "
            f"{worst:.1f} times the mean): their mean torque is not the friction at that speed, so every map "
            f"fitted to them is suspect; a coarse encoder{res_note} or loop gains too high for it"
        )
    breakaways = [b for r in records for b in find_breakaways(r)]
    if note := _imprecise_breakaways(breakaways):
        warnings_pre.append(note)
    ex = excitation(records[0] if len(records) == 1 else concat_records(records), plateaus)
    dynamic_wanted = any(spec_for(n).dynamic for n in names if n not in LEARNED)
    static_from_plateaus = len(plateaus) >= 3
    check_excitation(ex, dynamic=dynamic_wanted, static_from_plateaus=False, label=label)
    if dynamic_wanted:
        ex_train = excitation(concat_records(train), [])
        if ex_train.reversals < 4:
            why = (
                f"too little excitation in the {train_seconds:g} s training window: "
                f"{ex_train.reversals} velocity reversals, need >= 4 for presliding dynamics (run seed 003's "
                "'random' excitation, or lower/raise --train-seconds)"
            )
            dynamic = [n for n in names if n not in LEARNED and spec_for(n).dynamic]
            if not static_from_plateaus or len(dynamic) == len(names):
                raise ExcitationError(f"{label}: {why}")
            # the plateaus still determine the static models: fit those, name what was skipped
            names = [n for n in names if n not in dynamic]
            warnings_pre.append(f"dynamic models skipped ({', '.join(dynamic)}): {why}")
    vall = concat_records(val)
    mv = moving_mask(vall.velocity, vall.resolution, vall.dt)
    hm, thr = high_velocity_mask(vall.velocity, vall.dt, high_threshold, moving=mv)
    lm = mv & ~hm
    # long standstills are not scored: at rest the friction is whatever torque holds the joint
    scored = ~np.concatenate(
        [standstill_mask(full.velocity, full.resolution, full.dt)[keep] for full, keep in val_from]
    )
    results: dict[str, ModelResult] = {}
    warnings: list[str] = list(warnings_pre)
    grid = _grid(records)

    def prog(name):
        return (lambda f: progress(name, f)) if progress else None

    for name in [n for n in names if n not in LEARNED]:
        spec = spec_for(name, eps)
        if not spec.dynamic and static_from_plateaus:
            res = _fit_static_plateaus(name, plateaus, train, eps, breakaways)
            if progress:
                progress(name, 1.0)
        else:
            static0 = per = None
            if static_from_plateaus and "stribeck" in results and results["stribeck"].method == "plateaus":
                static0 = results["stribeck"].coefficients
                per = results["stribeck"].extra.get("per_direction")
            fit_train = train
            x0 = spec.initial_theta(static0) if static0 else None
            if static0 and two_stage and spec.dynamic and "r" in spec.nonlinear:
                # two-stage identification (anchors 3.3): the steady-state curve from the plateaus
                # is kept, only the presliding/dynamic coefficients are searched in the time domain
                spec.fix_steady_state(static0)
                x0 = spec.initial_theta(static0)
                if per:  # asymmetric joint: the symmetric dynamics fit the torque less d(v)
                    d = _direction_part(per, static0)
                    fit_train = [dataclasses.replace(r, torque=r.torque - d(r.velocity)) for r in train]
            else:
                per = None
            if spec.family == "gms":  # start from a smaller GMS already fitted (elements repeated)
                smaller = [r for n, r in results.items() if n.startswith("gms") and "theta" in r.extra]
                if smaller:
                    prev = smaller[-1]
                    th = np.asarray(prev.extra["theta"])
                    sp = spec_for(prev.name, eps)
                    xs = np.resize(th[4 : 4 + sp.n_elements], spec.n_elements)
                    x0 = np.concatenate([th[:4], xs])
                    if spec.damped:  # the smaller fit's damping, else the middle of its range
                        sd = th[-1] if sp.damped else np.sqrt(spec.lower[-1] * spec.upper[-1])
                        x0 = np.append(x0, sd)
            mi = maxiter.get(name) if isinstance(maxiter, dict) else maxiter
            fit = fit_time_domain(
                spec,
                fit_train,
                optimizer=optimizer,
                maxiter=mi,
                popsize=popsize,
                seed=seed,
                x0=x0,
                progress=prog(name),
            )
            res = _wrap_dynamic(name, fit, eps, grid, identifiability_check, fit_train)
            if per:
                res = _with_direction_levels(res, per, static0)
        yhat = predict_val(res)
        res.metrics = metrics.compare(yhat, vall.torque, hm, spec.n_params, low_mask=lm, scored=scored)
        res.extra["validation_prediction"] = yhat
        results[name] = res
    for name in [n for n in names if n in LEARNED]:
        t0 = time.perf_counter()
        ref = _best_parametric(results)
        J = results[ref].coefficients.get("J", 0.0) if ref else 0.0
        vx, fy, src = _learning_data(plateaus, train, J, eps)
        dm = learned.fit_directional(name, vx, fy)
        k = 8 if name == "anfis" else dm.positive.n_support + dm.negative.n_support + 2
        pred = _static_predictor(dm.steady_state, J)
        yhat = np.concatenate([pred(r) for r in val])
        res = ModelResult(
            name,
            f"learned ({src})",
            {"J": J, **dm.params()},
            None,
            metrics.compare(yhat, vall.torque, hm, k + 1, low_mask=lm, scored=scored),
            {},
            time.perf_counter() - t0,
            dm.steady_state,
            pred,
            notes=[f"per-direction {name} map trained on {len(vx)} {src}; inertia J from {ref or 'none'}"],
        )
        res.extra["validation_prediction"] = yhat
        results[name] = res
        if progress:
            progress(name, 1.0)
    candidates = {n: r for n, r in results.items() if r.config is not None}
    recommendation = metrics.recommend_with_rule({n: r.metrics for n, r in candidates.items()})
    nmse = [r.metrics.get("nmse_percent", math.nan) for r in candidates.values()]
    if len(plateaus) >= 3 and nmse and all(not (x < metrics.NO_SIGNAL_NMSE) for x in nmse):
        recommendation = metrics.recommend_by_plateaus(
            {n: (r.steady_state, r.metrics.get("n_params", 1)) for n, r in candidates.items()}, plateaus
        )
    rec = recommendation["model"]
    if rec is not None:
        nm = float(results[rec].metrics.get("nmse_percent", math.nan))
        if math.isfinite(nm) and nm > EXPLAINS_LITTLE_NMSE:
            warnings.append(
                f"the recommended model {rec} explains little of the measured torque (validation NMSE {nm:.1f} % "
                f"> {EXPLAINS_LITTLE_NMSE:g} %): a load or gravity term, more excitation or a sensor problem is "
                "missing; do not compensate with it before checking"
            )
    for r in results.values():
        r.extra["steady_state_grid"] = {
            "velocity": grid.tolist(),
            "friction": np.asarray(r.steady_state(grid)).tolist(),
        }
    return FitResult(
        results,
        rec,
        train,
        val,
        plateaus,
        breakaways,
        ex,
        thr,
        {
            "train_seconds": train_seconds,
            "load_offset": load,
            "train_window": train_window,
            "train_windows_s": windows,
            "optimizer": optimizer,
            "seed": seed,
            "eps": eps,
            "models": names,
        },
        warnings=warnings,
        seconds=time.perf_counter() - t_start,
        recommendation=recommendation,
    )


def _static_predictor(ss, J):
    return lambda r: J * r.acceleration + ss(r.velocity)


def _best_parametric(results: dict[str, ModelResult]) -> str | None:
    ok = [n for n, r in results.items() if r.config is not None]
    if not ok:
        return None
    return min(ok, key=lambda n: results[n].extra.get("train_mse", math.inf))


def _learning_data(plateaus, train, J, eps):
    pos = [p for p in plateaus if p.velocity > 0]
    neg = [p for p in plateaus if p.velocity < 0]
    if len(pos) >= 6 and len(neg) >= 6:
        return (
            np.array([p.velocity for p in plateaus]),
            np.array([p.torque for p in plateaus]),
            "plateau means",
        )
    r = concat_records(train)
    m = np.abs(r.velocity) > max(20 * eps, 0.02)
    return (
        r.velocity[m],
        (r.torque - J * r.acceleration)[m],
        f"sliding samples (|v| > {max(20 * eps, 0.02):.3g} rad/s)",
    )


#: a breakaway reading is used only when the ramp's stated detection lag (an upper bound: one step
#: plus the excess torque that moves 2 counts within a step, no Stribeck drop assumed) is below
#: this share of it; sized ramps state 0.6-1 % (abb_m19s, seed001, seed004), 8-28 % (seed002, whose
#: readings were within 0.3 % of the truth) and 250 % (seed000's 60-count encoder behind a damped
#: voltage drive: readings 2.7 times the friction level)
BREAKAWAY_LAG_SHARE = 0.5


def _breakaway_levels(breakaways) -> dict[int, float]:
    """Median breakaway torque magnitude per direction (the static friction level), from the
    experiment's breakaway ramps only (``source == "events"``): a breakaway detected in an arbitrary
    log (a plateau start, a reversal) is not a slow ramp from rest and would mislead the fit. A
    ramp whose detection lag (START note) exceeds BREAKAWAY_LAG_SHARE of its reading is left out
    (:func:`_imprecise_breakaways`)."""
    out = {}
    for d in (1, -1):
        x = [
            abs(b.torque)
            for b in breakaways
            if b.direction == d and b.source == "events" and np.isfinite(b.torque) and not _imprecise(b)
        ]
        if x:
            out[d] = float(np.median(x))
    return out


def _imprecise(b) -> bool:
    return bool(np.isfinite(b.lag) and b.lag > BREAKAWAY_LAG_SHARE * abs(b.torque))


def _imprecise_breakaways(breakaways) -> str:
    """A warning naming breakaway readings left out for their detection lag ('' if none)."""
    bad = [b for b in breakaways if b.source == "events" and np.isfinite(b.torque) and _imprecise(b)]
    if not bad:
        return ""
    worst = max(bad, key=lambda b: b.lag / abs(b.torque))
    return (
        f"{len(bad)} breakaway reading(s) left out: the ramp could read up to {worst.lag:.3g} N*m above the "
        f"true breakaway ({100 * worst.lag / abs(worst.torque):.0f} % of the {abs(worst.torque):.3g} N*m read; "
        "the encoder sees sliding only after it has moved 2 counts), so the static level comes from the "
        "plateaus"
    )


def _fit_static_plateaus(name, plateaus, train, eps, breakaways=()) -> ModelResult:
    levels = _breakaway_levels(breakaways)
    sf: StaticFit = fit_plateaus(plateaus, name, breakaway=levels or None)
    per = sf.per_direction if sf.asymmetric else None
    coefs = dict(sf.coefficients)

    def ss(v, c=coefs, per=per):
        v = np.asarray(v, dtype=float)
        if per:
            return np.where(v >= 0, stribeck_map(v, per["positive"]), stribeck_map(v, per["negative"]))
        return stribeck_map(v, c)

    # inertia by NNLS on the training records with the map fixed (acceleration is ~0 on plateaus)
    r = concat_records(train)
    resid = r.torque - ss(r.velocity)
    a = r.acceleration
    J = max(float(a @ resid / max(a @ a, 1e-300)), 0.0)
    coefs["J"] = J
    cfg = export.library_config(name, coefs, eps=0.0, per_direction=per)
    _validate_config(cfg)
    notes = [f"fitted to {sf.n_points} plateau means (robust soft-L1 least squares), rms {sf.rms:.3g} N*m"]
    if levels and name == "stribeck":
        notes.append(
            "static level fs from the breakaway ramps ("
            + ", ".join(f"{'+' if d > 0 else '-'}{x:.4g}" for d, x in levels.items())
            + " N*m), the rest of the curve from the plateaus"
        )
    if sf.asymmetric:
        notes.append("directions differ significantly: asymmetric model exported")
    ci95 = {k: [coefs[k] - 1.96 * s, coefs[k] + 1.96 * s] for k, s in sf.stderr.items()}
    ident = {
        "stderr": sf.stderr,
        "ci95": ci95,
        "not_identifiable": [],
        "useless_ci": identifiability.useless_intervals(ci95, coefs),
        "per_direction": sf.per_direction,
    }
    if ident["useless_ci"]:
        notes.append(
            "95 % confidence interval wider than the value (the data do not determine it): "
            + ", ".join(ident["useless_ci"])
        )
    m = ModelResult(name, "plateaus", coefs, cfg, {}, ident, sf.seconds, ss, _static_predictor(ss, J), notes)
    m.extra["train_mse"] = float(np.mean((J * a + ss(r.velocity) - r.torque) ** 2))
    if per:
        m.extra["per_direction"] = {"positive": per["positive"], "negative": per["negative"]}
    return m


def _direction_part(per: dict, joint: dict) -> Callable[[np.ndarray], np.ndarray]:
    """``d(v) = F_dir(v) - F_joint(v)``: what the direction-dependent steady state adds to the
    symmetric one (both Stribeck maps of the plateau fit)."""

    def d(v):
        v = np.asarray(v, dtype=float)
        f = np.where(v >= 0, stribeck_map(v, per["positive"]), stribeck_map(v, per["negative"]))
        return f - stribeck_map(v, joint)

    return d


def _with_direction_levels(m: ModelResult, per: dict, joint: dict) -> ModelResult:
    """A symmetric dynamic fit made direction-dependent (an asymmetric joint, seed 004 B.3): the
    time-domain fit saw the torque less ``d(v)`` (:func:`_direction_part`); prediction and steady
    state add it back, and the exported config is the library's ``asymmetric`` wrapper with the
    presliding coefficients shared and each direction's ``fc, fs, vs, delta, fv`` from the plateaus."""
    d = _direction_part(per, joint)
    base_predict, base_ss = m.predict, m.steady_state
    m.predict = lambda data: base_predict(data) + d(data.velocity)
    m.steady_state = lambda v: base_ss(v) + d(v)
    if m.config is not None:
        body = {k: v for k, v in m.config.items() if k != "model"}
        sets = {}
        for key in ("positive", "negative"):
            p = per[key]
            sets[key] = {
                **body,
                "fc": p["fc"],
                "fs": max(p.get("fs", p["fc"]), p["fc"]),
                "fv": p.get("fv", 0.0),
            }
            sets[key].update({k: p[k] for k in ("vs", "delta") if k in p})
        cfg = {"model": "asymmetric", "base": m.config["model"], **sets}
        _validate_config(cfg)
        m.config = cfg
    m.identifiability["per_direction"] = per
    m.notes.append(
        "directions differ significantly: asymmetric model exported (levels per direction from the plateaus)"
    )
    return m


def _validate_config(cfg):
    if cfg is None:
        return
    from friction_ros.core.friction import model_from_config

    model_from_config(cfg)


def _wrap_dynamic(name, fit: DynamicFit, eps, grid, ident_check, train) -> ModelResult:
    coefs = fit.coefficients
    cfg = export.library_config(name, coefs, eps=eps)
    notes = []
    try:
        _validate_config(cfg)
    except ParameterError as exc:
        notes.append(f"library config rejected: {exc}")
        cfg = None
    spec = fit.spec

    def ss(v, c=coefs):
        v = np.asarray(v, dtype=float)
        if spec.family == "dahl":
            return c["fc"] * np.sign(v)
        if spec.family in ("coulomb", "stribeck"):
            return stribeck_map(v, {**c, "fs": c.get("fs", c["fc"])}) * np.abs(sat_sign(v, c.get("eps", eps)))
        return stribeck_map(v, {**c, "fv": c.get("fv", c.get("sigma2", 0.0))})

    ident = {}
    if ident_check:
        try:
            jac, res, names, values = identifiability.time_domain_jacobian(fit, train)
            ident = identifiability.analyse(jac, res, names, values)
        except (np.linalg.LinAlgError, ValueError) as exc:
            notes.append(f"identifiability analysis failed: {exc}")
    if ident.get("not_identifiable"):
        notes.append("not separately identifiable from these data: " + ", ".join(ident["not_identifiable"]))
    useless = [n for n in ident.get("useless_ci", []) if n not in ident.get("not_identifiable", [])]
    if useless:
        notes.append(
            "95 % confidence interval wider than the value (the data do not determine it): "
            + ", ".join(useless)
        )
    m = ModelResult(
        name,
        f"time-domain output error ({fit.optimizer} + Nelder-Mead)"
        if spec.nonlinear
        else "time-domain linear least squares",
        coefs,
        cfg,
        {},
        ident,
        fit.seconds,
        ss,
        fit.predict,
        notes,
    )
    m.extra["train_mse"] = fit.train_mse
    m.extra["theta"] = fit.theta.tolist()
    m.extra["evaluations"] = fit.evaluations
    return m


# ------------------------------------------------------------------------------------ bag -> files
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
    **options,
) -> FitResult:
    """Read bags, fit ``models`` and write into ``out_dir``:

    ``report.md`` (Markdown report), ``summary.json`` (every model's coefficients, metrics and
    steady-state map), ``friction_params.yaml`` (or ``params_file``: ROS parameters of the
    recommended model for compensating_controller, friction_estimator, plant_simulator),
    ``plots/*.png`` (friction-velocity map, presliding hysteresis, time-domain validation,
    residuals). ``gate``: keyword arguments of
    :func:`friction_ros.core.identification.gating.gate_fit`; the compensation modes of the
    parameter file are then checked in closed loop first (refused ones written disabled).
    """
    from friction_ros.core.identification import report

    if isinstance(bag_paths, (str, Path)):
        bag_paths = [bag_paths]
    check_model_names(models)
    recs = [
        load_bag(
            p,
            topic,
            joint,
            events_topic=events_topic,
            current_topic=current_topic,
            current_field=current_field,
            torque_constant=torque_constant,
            gear_ratio=gear_ratio,
            torque_delay=torque_delay,
        )
        for p in bag_paths
    ]
    res = fit_records(recs, models, label=", ".join(str(p) for p in bag_paths), **options)
    res.options["plant_preset"] = plant_preset
    if gate is not None:  # the safety gate before the parameter file enables a mode
        from friction_ros.core.identification.gating import gate_fit

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
