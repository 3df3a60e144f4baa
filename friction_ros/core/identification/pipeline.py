"""The identification pipeline: records -> fitted models -> comparison -> outputs.

Public entry points (stable signatures):

* :func:`fit_bag` ``(bag_paths, topic, joint, models, out_dir, **options) -> FitResult``
  reads one or more bags and writes the report, JSON summary, plots and parameter YAML;
* :func:`fit_records` ``(records, models, **options) -> FitResult`` on prepared
  :class:`~friction_ros.core.identification.records.JointData` (no files);
* :func:`~friction_ros.core.identification.bag_loading.load_bag` ``(path, topic, joint, ...) -> JointData``.
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Callable

import numpy as np

from friction_ros.core.identification import learned, metrics
from friction_ros.core.identification.baseline import NAME as BASELINE
from friction_ros.core.identification.baseline import validated_baseline
from friction_ros.core.identification.breakaway_detection import find_breakaways
from friction_ros.core.identification.data_scale import data_scale, with_scale
from friction_ros.core.identification.decimation import DEFAULT_MAX_SAMPLES, bound_records
from friction_ros.core.identification.dynamic_fit import fit_time_domain
from friction_ros.core.identification.excitation_checks import (
    check_motion,
    excitation,
    one_direction_note,
)
from friction_ros.core.identification.fit_results import FitResult, ModelResult
from friction_ros.core.identification.load_terms import (
    terms_for_fit,
    with_transmitted,
)
from friction_ros.core.identification.model_fits import (
    direction_part,
    fit_static_plateaus,
    imprecise_breakaways,
    learning_data,
    static_predictor,
    with_direction_levels,
    wrap_dynamic,
)
from friction_ros.core.identification.model_status import (
    failed_model,
    judge_divergence,
)
from friction_ros.core.identification.models import (
    DEFAULT_EPS,
    LEARNED,
    check_model_names,
    spec_for,
)
from friction_ros.core.identification.plateau_detection import (
    chattering_plateaus,
    find_plateaus,
    load_offset,
)
from friction_ros.core.identification.recommendation import checked_recommendation, verdict
from friction_ros.core.identification.records import (
    JointData,
    concat_records,
)
from friction_ros.core.identification.residual_learning import with_residual
from friction_ros.core.identification.search_space import (
    slowest_stribeck_velocity,
    static_linear_zone,
    velocity_grid,
)
from friction_ros.core.identification.training_split import split, training_segments, training_window
from friction_ros.core.identification.velocity_regimes import (
    high_velocity_mask,
    mask_runs,
    moving_mask,
    standstill_mask,
)
from friction_ros.core.joint_type import JOINT_TYPES
from friction_ros.core.validation import ParameterError, check_choice

DEFAULT_MODELS = ("coulomb", "stribeck", "lugre", "gms4")
EXPLAINS_LITTLE_NMSE = 30.0  # [%] validation NMSE above which a recommendation comes with a warning


# ------------------------------------------------------------------------------------ fitting


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
    eps: float | None = None,
    high_threshold: float | None = None,
    identifiability_check: bool = True,
    two_stage: bool = True,
    progress: Callable[[str, float], None] | None = None,
    label: str = "data",
    load="auto",
    ripple_period: float = 2.0 * math.pi,
    load_eps: float | None = None,
    validation_records: list[JointData] | None = None,
    residual: str = "none",
    joint_type: str = "revolute",
    max_samples: int | None = DEFAULT_MAX_SAMPLES,
) -> FitResult:
    """Fit ``models`` to prepared records (see module and package docstrings).

    ``train_window``: ``"content"`` (default) trains on chunks stratified by content
    (:func:`~friction_ros.core.identification.training_split.training_segments`, about ``train_seconds``
    in all) and validates on the rest; ``"window"`` on the single most exciting ``train_seconds``
    window (:func:`~friction_ros.core.identification.training_split.training_window`); ``"first"`` on the
    first ``train_seconds`` (ABB M19-S paper A.3).

    ``load``: the load, gravity and position terms identified jointly with every model
    (:mod:`~friction_ros.core.identification.load_terms`): ``"auto"`` (default: chosen by validation
    when the records have no constant-velocity plateaus; with plateaus, the experiment's own load
    offset handling applies), ``"none"``, a term list such as ``"gravity,offset,ripple=4"`` or a
    :class:`~friction_ros.core.identification.load_terms.LoadTerms`. ``ripple_period`` [rad]: the
    period of the position-dependent friction (2 pi / N for the motor angle of an N:1 gear);
    ``load_eps`` [rad/s]: the linear zone of sgn(v) in those terms (default: ``eps``, at least
    three times the velocity noise). ``validation_records``: validate on these whole records and
    train on the whole of ``records`` (cross-validation over runs, :func:`cross_validate_runs`).
    Load terms chosen automatically must also lower the recommended model's validation NMSE (one
    more fit of that model without them); otherwise the whole fit is repeated without load terms
    and a warning says so.
    ``residual``: a learned residual on top of the best physics model
    (:mod:`~friction_ros.core.identification.residual_learning`; ``none`` (default here; friction-fit
    defaults to ``auto``), ``auto`` (for records without plateaus: mlp or rff by validation), ``mlp``
    or ``rff``); the combined model ``<physics>+residual`` competes in
    the recommendation like any other (its parameter count includes the network's).
    ``joint_type``: ``revolute`` (rad, N*m) or ``prismatic`` (m, N); a prismatic joint has no
    angle-dependent load terms (gravity is constant along the axis: the offset takes it).
    Every model is compared with the inverse-dynamics baseline (:mod:`baseline`); a model that
    cannot be fitted or diverges is listed with the reason (:mod:`model_status`).
    ``max_samples``: a longer log is cut down to this many samples chosen by content
    (:mod:`~friction_ros.core.identification.decimation`; a warning says what was used; None: all).
    """
    check_choice("train_window", train_window, ["content", "window", "first"])
    check_choice("joint_type", joint_type, list(JOINT_TYPES))
    records = bound_records([records] if isinstance(records, JointData) else list(records), max_samples)
    call = dict(locals())  # the arguments as given: the load-term check below refits with them
    t_start = time.perf_counter()
    records = [records] if isinstance(records, JointData) else list(records)
    names = check_model_names(models)
    if not records:
        raise ParameterError("records = []: need at least one record")
    scale = data_scale(records)  # every speed threshold and bound follows the log's own scales
    records = with_scale(records, scale)
    if validation_records:
        validation_records = with_scale(validation_records, scale)
    eps = DEFAULT_EPS * scale.velocity if eps is None else eps
    for r in records:
        check_motion(r, r.meta.get("source", label))
    offset, offset_note = load_offset([p for r in records for p in find_plateaus(r)])
    if offset:
        records = [dataclasses.replace(r, torque=r.torque - offset) for r in records]
    train, val, val_from = [], [], []
    windows = []
    if validation_records:
        train = list(records)
        val = list(validation_records)
        val_from = [(r, np.ones(r.n, bool)) for r in val]
    for r in [] if validation_records else records:
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
    if not val and not validation_records:  # records too short to split: validate on the training data
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
    if offset:
        warnings_pre.append(offset_note)

    def predict_val(model) -> np.ndarray:
        # dynamic states run through the whole record (one simulation); validation = outside the window
        return np.concatenate([model.predict(full)[keep] for full, keep in val_from])

    dropped: list[str] = []
    plateaus = [p for r in records for p in find_plateaus(r, dropped=dropped)]
    if dropped:  # every plateau left out is named with the reason
        shown = "; ".join(dropped[:8]) + (f"; and {len(dropped) - 8} more" if len(dropped) > 8 else "")
        warnings_pre.append(f"{len(dropped)} of {len(dropped) + len(plateaus)} plateaus left out: {shown}")
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
    if note := imprecise_breakaways(breakaways):
        warnings_pre.append(note)
    ex = excitation(records[0] if len(records) == 1 else concat_records(records), plateaus)
    dynamic_wanted = any(spec_for(n).dynamic for n in names if n not in LEARNED)
    static_from_plateaus = len(plateaus) >= 3
    skipped: dict[str, str] = {}  # model -> why the log cannot determine it (listed as not fitted)
    if note := one_direction_note(ex):
        warnings_pre.append(note)
    if dynamic_wanted:
        ex_train = excitation(concat_records(train), [])
        if ex_train.reversals < 4:
            why = (
                f"too little excitation in the {train_seconds:g} s training window: "
                f"{ex_train.reversals} velocity reversals, need >= 4 for presliding dynamics (run ABB M19-S paper's "
                "'random' excitation, or lower/raise --train-seconds)"
            )
            dynamic = [n for n in names if n not in LEARNED and spec_for(n).dynamic]
            skipped.update(dict.fromkeys(dynamic, why))
            names = [n for n in names if n not in dynamic]
            warnings_pre.append(f"dynamic models not fitted ({', '.join(dynamic)}): {why}")
    terms, selection = terms_for_fit(load, plateaus, train, val, ripple_period, load_eps, eps, joint_type)
    if terms.load_friction:  # the torque the gear transmits, from the selection backbone
        tr = (selection.inertia, selection.joint_load)
        train, val = with_transmitted(train, *tr), with_transmitted(val, *tr)
        val_from = [
            (r, keep)
            for r, keep in zip(with_transmitted([f for f, _ in val_from], *tr), [k for _, k in val_from])
        ]
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
    grid = velocity_grid(records)

    def prog(name):
        return (lambda f: progress(name, f)) if progress else None

    baseline = validated_baseline(train, terms, predict_val, vall, hm, lm, scored)
    results[baseline.name] = baseline
    for name, why in skipped.items():
        results[name] = failed_model(name, "not fitted", why)

    for name in [n for n in names if n not in LEARNED]:
        try:
            spec = spec_for(name, eps, scale.velocity)
            if not terms.empty:
                spec.load = terms
                if not spec.dynamic:  # see static_linear_zone
                    static_linear_zone(spec, terms.eps)
            slowest_stribeck_velocity(spec, train)
            if spec.model.plateau_shape and static_from_plateaus and terms.empty:
                res = fit_static_plateaus(name, plateaus, train, eps, breakaways)
                if progress:
                    progress(name, 1.0)
            else:
                static0 = per = None
                nested = results.get(spec.model.nested)  # its plateau fit: the measured steady state
                if static_from_plateaus and nested is not None and nested.method == "plateaus":
                    static0 = nested.coefficients
                    per = nested.extra.get("per_direction")
                fit_train = train
                x0 = spec.initial_theta(static0) if static0 else None
                if static0 and two_stage and spec.model.two_stage:
                    # two-stage identification (anchors 3.3): the steady-state curve from the plateaus
                    # is kept, only the presliding/dynamic coefficients are searched in the time domain
                    spec.fix_steady_state(static0)
                    x0 = spec.initial_theta(static0)
                    if per:  # asymmetric joint: the symmetric dynamics fit the torque less d(v)
                        d = direction_part(per, static0)
                        fit_train = [dataclasses.replace(r, torque=r.torque - d(r.velocity)) for r in train]
                else:
                    per = None
                fitted = [(n, np.asarray(r.extra["theta"])) for n, r in results.items() if "theta" in r.extra]
                warm = spec.model.warm_start(spec, fitted)  # e.g. a GMS from a smaller GMS fitted before
                if warm is not None:
                    x0 = warm
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
                res = wrap_dynamic(name, fit, eps, grid, identifiability_check, fit_train)
                if per:
                    res = with_direction_levels(res, per, static0)
                if not terms.empty:
                    res.extra["load"] = terms.joint_load(fit.load_coefficients).to_config()
                    res.extra["load_coefficients"] = fit.load_coefficients
                    res.extra["load_part"] = _load_part(fit)
            yhat = predict_val(res)
            res.metrics = metrics.compare(yhat, vall.torque, hm, spec.n_params, low_mask=lm, scored=scored)
            res.extra["validation_prediction"] = yhat
            results[name] = res
        except Exception as exc:  # a model that cannot be fitted is listed with the reason; the rest proceed
            results[name] = failed_model(name, "not fitted", f"{type(exc).__name__}: {exc}")
            continue
        judge_divergence(res, vall.torque, baseline)

    for name in [n for n in names if n in LEARNED]:
        try:
            t0 = time.perf_counter()
            ref = _best_parametric(results)
            J = results[ref].coefficients.get("J", 0.0) if ref else 0.0
            load_part = results[ref].extra.get("load_part") if ref else None
            ltrain = train
            if load_part is not None:  # learn the friction map on the torque less the reference's load terms
                ltrain = [dataclasses.replace(r, torque=r.torque - load_part(r)) for r in train]
            vx, fy, src = learning_data(plateaus, ltrain, J, eps)
            dm = learned.fit_directional(name, vx, fy)
            k = 8 if name == "anfis" else dm.positive.n_support + dm.negative.n_support + 2
            pred = static_predictor(dm.steady_state, J)
            if load_part is not None:
                pred = (lambda p, lp: lambda r: p(r) + lp(r))(pred, load_part)
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
                notes=[
                    f"per-direction {name} map trained on {len(vx)} {src}; inertia J from {ref or 'none'}"
                ],
            )
            res.extra["validation_prediction"] = yhat
            results[name] = res
            if progress:
                progress(name, 1.0)
        except Exception as exc:  # listed with the reason; the other models proceed
            results[name] = failed_model(name, "not fitted", f"{type(exc).__name__}: {exc}")
            continue
        judge_divergence(res, vall.torque, baseline)

    if not any(r.fitted for r in results.values()):
        raise ParameterError(
            f"{label}: no model could be fitted: "
            + "; ".join(f"{n} {r.status}: {r.reason}" for n, r in results.items())
        )
    candidates = {
        n: r for n, r in results.items() if r.config is not None and r.fitted and n != baseline.name
    }
    recommendation = metrics.recommend_with_rule({n: r.metrics for n, r in candidates.items()})
    # the model the load terms must help: the recommended one, else the first parametric model asked
    # for (its fit with the terms may have failed or diverged: then it counts as infinitely worse)
    rec0 = recommendation["model"] or next((n for n in names if n not in LEARNED), None)
    if load == "auto" and selection is not None and not terms.empty and rec0 is not None:
        # the terms were ranked on a linear backbone: they must also help the recommended model
        try:
            alt = fit_records(
                **{**call, "models": [rec0], "load": "none", "residual": "none", "progress": None},
            )
            without = float(alt.models[rec0].metrics.get("nmse_percent", math.inf))
        except ParameterError:  # nothing fits without the terms (a pendulum without gravity): keep them
            without = math.inf
        with_terms = float(results[rec0].metrics.get("nmse_percent", math.inf))
        if without <= with_terms:
            res = fit_records(**{**call, "load": "none"})
            res.warnings.insert(
                0,
                f"the load terms chosen on the linear backbone ({terms.describe()}) did not lower the validation "
                f"NMSE of {rec0} ({with_terms:.4g} % with them, {without:.4g} % without): fitted without load terms",
            )
            res.options["load_selection"] = selection.table() + ["rejected: no gain on the recommended model"]
            return res
    check_choice("residual", residual, ["auto", "none", "mlp", "rff"])
    if residual == "auto":
        residual = "none" if len(plateaus) >= 3 else "auto"
    if residual != "none" and recommendation["model"] is not None:
        combined = with_residual(
            results[recommendation["model"]], train, val, vall, residual, seed, hm, lm, scored, warnings
        )
        if combined is not None:
            results[combined.name] = candidates[combined.name] = combined
            recommendation = metrics.recommend_with_rule({n: r.metrics for n, r in candidates.items()})
    nmse = [r.metrics.get("nmse_percent", math.nan) for r in candidates.values()]
    if len(plateaus) >= 3 and nmse and all(not (x < metrics.NO_SIGNAL_NMSE) for x in nmse):
        recommendation = metrics.recommend_by_plateaus(
            {n: (r.steady_state, r.metrics.get("n_params", 1)) for n, r in candidates.items()}, plateaus
        )
    if recommendation["model"] is not None or baseline.fitted:
        recommendation = checked_recommendation(recommendation, candidates, baseline)
    rec = recommendation["model"]
    if rec is None:
        warnings.append(
            "no model is recommended and no parameter file is written: "
            + (recommendation.get("reason") or recommendation.get("rule") or "no model could be exported")
        )
    judged = verdict(results, rec, val, vall, terms, eps, tried=selection is not None and load == "auto")
    if judged["explains_little"]:
        warnings.append(judged["text"])
    for r in [r for r in results.values() if r.fitted]:
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
            "load_offset": offset,
            "train_window": train_window,
            "train_windows_s": windows,
            "load_terms": terms.describe(),
            "load_selection": selection.table() if selection is not None else [],
            "validation_records": len(validation_records or []),
            "verdict": judged,
            "optimizer": optimizer,
            "seed": seed,
            "eps": eps,
            "data_scale": {"velocity": scale.velocity, "torque": scale.torque},
            "joint_type": joint_type,
            "models": names,
        },
        warnings=warnings,
        seconds=time.perf_counter() - t_start,
        recommendation=recommendation,
    )


def _load_part(fit) -> Callable[[JointData], np.ndarray]:
    """record -> the load-term torque of a fit (its load columns times their coefficients)."""
    from friction_ros.core.identification.dynamic_fit import fit_signals

    spec = fit.spec
    idx = [spec.linear_all.index(n) for n in spec.load_names]
    b = fit.beta[idx]

    def part(r: JointData) -> np.ndarray:
        v, _ = fit_signals(r, fit.signals)
        return spec.load_matrix(r, v) @ b

    return part


def _best_parametric(results: dict[str, ModelResult]) -> str | None:
    ok = [n for n, r in results.items() if r.config is not None and n != BASELINE]
    if not ok:
        return None
    return min(ok, key=lambda n: results[n].extra.get("train_mse", math.inf))


# ------------------------------------------------------------------------------------ bag -> files
