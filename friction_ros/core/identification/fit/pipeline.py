"""The identification pipeline: records -> fitted models -> comparison -> recommendation.

:func:`fit_records` ``(records, models, options=None, *, validation_records=None, progress=None,
**options) -> FitResult`` on prepared :class:`~friction_ros.core.identification.data.records.JointData`
(no files; logs in, files out: :func:`~friction_ros.core.identification.report.fit_logs.fit_bag`). The
options are a :class:`~friction_ros.core.identification.fit.fit_options.FitOptions` or its keyword
arguments. A fit runs as named stages over one
:class:`~friction_ros.core.identification.fit.fit_context.FitContext`: the data stages
(:mod:`~friction_ros.core.identification.fit.fit_data`: prepare and scale -> split train/validation ->
features -> load terms), then the model stages here: parametric models (each with its
identifiability) -> learned models -> ranking -> the load-term check -> learned residual ->
recommendation and verdict -> result.
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Callable

import numpy as np

from friction_ros.core.identification.data.decimation import bound_records
from friction_ros.core.identification.data.records import JointData
from friction_ros.core.identification.fit import learned, metrics
from friction_ros.core.identification.fit.baseline import NAME as BASELINE
from friction_ros.core.identification.fit.baseline import validated_baseline
from friction_ros.core.identification.fit.dynamic_fit import fit_time_domain
from friction_ros.core.identification.fit.fit_context import FitContext
from friction_ros.core.identification.fit.fit_data import (
    choose_load_terms,
    find_features,
    prepare_data,
    split_train_validation,
)
from friction_ros.core.identification.fit.fit_options import FitOptions
from friction_ros.core.identification.fit.fit_results import FitResult, ModelResult
from friction_ros.core.identification.fit.model_fits import (
    direction_part,
    fit_static_plateaus,
    learning_data,
    static_predictor,
    with_direction_levels,
    wrap_dynamic,
)
from friction_ros.core.identification.fit.model_status import failed_model, judge_divergence
from friction_ros.core.identification.fit.models import LEARNED, spec_for
from friction_ros.core.identification.fit.recommendation import checked_recommendation, verdict
from friction_ros.core.identification.fit.residual_learning import with_residual
from friction_ros.core.identification.fit.search_space import slowest_stribeck_velocity, static_linear_zone
from friction_ros.core.validation import ParameterError

DEFAULT_MODELS = ("coulomb", "stribeck", "lugre", "gms4")


def fit_records(
    records: JointData | list[JointData],
    models=DEFAULT_MODELS,
    options: FitOptions | None = None,
    *,
    validation_records: list[JointData] | None = None,
    progress: Callable[[str, float], None] | None = None,
    **kw,
) -> FitResult:
    """Fit ``models`` to prepared records (see the module docstring for the stages).

    ``options``: a :class:`~friction_ros.core.identification.fit.fit_options.FitOptions` (what each
    option does, its default and unit); keyword arguments ``kw`` set or override single options
    (``fit_records(recs, models, train_seconds=5.0)``); an unknown name is refused.
    ``validation_records``: validate on these whole records and train on the whole of ``records``
    (cross-validation over runs, :func:`~friction_ros.core.identification.report.fit_logs.cross_validate_runs`).
    ``progress(model, fraction)``: called as each model's fit proceeds.
    Every model is compared with the inverse-dynamics baseline (:mod:`baseline`); a model that
    cannot be fitted or diverges is listed with the reason (:mod:`model_status`). Load terms chosen
    automatically must also lower the recommended model's validation NMSE
    (:func:`refit_without_unhelpful_load_terms`).
    """
    opts = FitOptions.resolve(options, kw)
    records = bound_records([records] if isinstance(records, JointData) else list(records), opts.max_samples)
    ctx = FitContext(opts, models, records, validation_records, progress, time.perf_counter())
    prepare_data(ctx)
    split_train_validation(ctx)
    find_features(ctx)
    choose_load_terms(ctx)
    fit_parametric_models(ctx)
    fit_learned_models(ctx)
    rank_models(ctx)
    refit = refit_without_unhelpful_load_terms(ctx)
    if refit is not None:
        return refit
    add_residual(ctx)
    recommend(ctx)
    return fit_result(ctx)


# ------------------------------------------------------------------------------------ model stages


def fit_parametric_models(ctx: FitContext) -> None:
    """The inverse-dynamics baseline (:mod:`~friction_ros.core.identification.fit.baseline`), then each
    parametric model (:func:`fit_parametric`); one that cannot be fitted is listed with the reason,
    one whose validation prediction runs away is judged diverged
    (:mod:`~friction_ros.core.identification.fit.model_status`)."""
    ctx.baseline = validated_baseline(
        ctx.train, ctx.terms, ctx.predict_val, ctx.vall, ctx.high_mask, ctx.low_mask, ctx.scored
    )
    ctx.results[ctx.baseline.name] = ctx.baseline
    for name, why in ctx.skipped.items():
        ctx.results[name] = failed_model(name, "not fitted", why)
    for name in [n for n in ctx.names if n not in LEARNED]:
        try:
            res = fit_parametric(ctx, name)
        except Exception as exc:  # a model that cannot be fitted is listed with the reason; the rest proceed
            ctx.results[name] = failed_model(name, "not fitted", f"{type(exc).__name__}: {exc}")
            continue
        judge_divergence(res, ctx.vall.torque, ctx.baseline)


def fit_parametric(ctx: FitContext, name: str) -> ModelResult:
    """One parametric model: on the plateau means when the log has >= 3 plateaus and the model is a
    steady-state map (:func:`~friction_ros.core.identification.fit.model_fits.fit_static_plateaus`), else
    in the time domain (:func:`~friction_ros.core.identification.fit.dynamic_fit.fit_time_domain`),
    two-stage when its nested model was fitted on plateaus (anchors 3.3: the steady-state curve is
    kept, only the presliding coefficients are searched); its identifiability with it
    (``identifiability_check``); validation metrics (:func:`~friction_ros.core.identification.fit.metrics.compare`)."""
    o, results, train, eps = ctx.options, ctx.results, ctx.train, ctx.eps
    spec = spec_for(name, eps, ctx.scale.velocity)
    if not ctx.terms.empty:
        spec.load = ctx.terms
        if not spec.dynamic:  # see static_linear_zone
            static_linear_zone(spec, ctx.terms.eps)
    slowest_stribeck_velocity(spec, train)
    static_from_plateaus = len(ctx.plateaus) >= 3
    if spec.model.plateau_shape and static_from_plateaus and ctx.terms.empty:
        res = fit_static_plateaus(name, ctx.plateaus, train, eps, ctx.breakaways)
        if ctx.progress:
            ctx.progress(name, 1.0)
    else:
        static0 = per = None
        nested = results.get(spec.model.nested)  # its plateau fit: the measured steady state
        if static_from_plateaus and nested is not None and nested.method == "plateaus":
            static0 = nested.coefficients
            per = nested.extra.get("per_direction")
        fit_train = train
        x0 = spec.initial_theta(static0) if static0 else None
        if static0 and o.two_stage and spec.model.two_stage:
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
        fit = fit_time_domain(
            spec,
            fit_train,
            optimizer=o.optimizer,
            maxiter=o.maxiter_for(name),
            popsize=o.popsize,
            seed=o.seed,
            x0=x0,
            progress=ctx.progress_of(name),
        )
        res = wrap_dynamic(name, fit, eps, ctx.grid, o.identifiability_check, fit_train)
        if per:
            res = with_direction_levels(res, per, static0)
        if not ctx.terms.empty:
            res.extra["load"] = ctx.terms.joint_load(fit.load_coefficients).to_config()
            res.extra["load_coefficients"] = fit.load_coefficients
            res.extra["load_part"] = _load_part(fit)
    yhat = ctx.predict_val(res)
    res.metrics = metrics.compare(
        yhat, ctx.vall.torque, ctx.high_mask, spec.n_params, low_mask=ctx.low_mask, scored=ctx.scored
    )
    res.extra["validation_prediction"] = yhat
    results[name] = res
    return res


def fit_learned_models(ctx: FitContext) -> None:
    """Each learned model (anfis, nusvr: :mod:`~friction_ros.core.identification.fit.learned`): a
    per-direction friction map on the plateau means or sliding samples, with the inertia (and the
    load terms) of the best parametric fit; listed with the reason when it cannot be fitted."""
    for name in [n for n in ctx.names if n in LEARNED]:
        try:
            res = fit_learned(ctx, name)
        except Exception as exc:  # listed with the reason; the other models proceed
            ctx.results[name] = failed_model(name, "not fitted", f"{type(exc).__name__}: {exc}")
            continue
        judge_divergence(res, ctx.vall.torque, ctx.baseline)


def fit_learned(ctx: FitContext, name: str) -> ModelResult:
    """One learned model (see :func:`fit_learned_models`) with its validation metrics."""
    t0 = time.perf_counter()
    results = ctx.results
    ref = _best_parametric(results)
    J = results[ref].coefficients.get("J", 0.0) if ref else 0.0
    load_part = results[ref].extra.get("load_part") if ref else None
    ltrain = ctx.train
    if load_part is not None:  # learn the friction map on the torque less the reference's load terms
        ltrain = [dataclasses.replace(r, torque=r.torque - load_part(r)) for r in ctx.train]
    vx, fy, src = learning_data(ctx.plateaus, ltrain, J, ctx.eps)
    dm = learned.fit_directional(name, vx, fy)
    k = 8 if name == "anfis" else dm.positive.n_support + dm.negative.n_support + 2
    pred = static_predictor(dm.steady_state, J)
    if load_part is not None:
        pred = (lambda p, lp: lambda r: p(r) + lp(r))(pred, load_part)
    yhat = np.concatenate([pred(r) for r in ctx.val])
    res = ModelResult(
        name,
        f"learned ({src})",
        {"J": J, **dm.params()},
        None,
        metrics.compare(
            yhat, ctx.vall.torque, ctx.high_mask, k + 1, low_mask=ctx.low_mask, scored=ctx.scored
        ),
        {},
        time.perf_counter() - t0,
        dm.steady_state,
        pred,
        notes=[f"per-direction {name} map trained on {len(vx)} {src}; inertia J from {ref or 'none'}"],
    )
    res.extra["validation_prediction"] = yhat
    results[name] = res
    if ctx.progress:
        ctx.progress(name, 1.0)
    return res


def rank_models(ctx: FitContext) -> None:
    """The candidates (fitted models with a friction-library form, not the baseline) ranked by
    :func:`~friction_ros.core.identification.fit.metrics.recommend_with_rule`; no fitted model at all is
    a ParameterError listing every model's reason."""
    results = ctx.results
    if not any(r.fitted for r in results.values()):
        raise ParameterError(
            f"{ctx.options.label}: no model could be fitted: "
            + "; ".join(f"{n} {r.status}: {r.reason}" for n, r in results.items())
        )
    ctx.candidates = {
        n: r for n, r in results.items() if r.config is not None and r.fitted and n != ctx.baseline.name
    }
    ctx.recommendation = metrics.recommend_with_rule({n: r.metrics for n, r in ctx.candidates.items()})


def refit_without_unhelpful_load_terms(ctx: FitContext) -> FitResult | None:
    """Load terms chosen automatically were ranked on a linear backbone: they must also lower the
    validation NMSE of the recommended model (else of the first parametric model asked for; its fit
    with them may have failed or diverged: then it counts as infinitely worse). One more fit of that
    model without them decides; when it is no worse, the whole fit is repeated without load terms
    (returned, with a warning). None: the terms stay."""
    o, results, terms = ctx.options, ctx.results, ctx.terms
    rec0 = ctx.recommendation["model"] or next((n for n in ctx.names if n not in LEARNED), None)
    if not (o.load == "auto" and ctx.selection is not None and not terms.empty and rec0 is not None):
        return None
    again = dict(validation_records=ctx.validation_in)
    try:
        alt = fit_records(ctx.records_in, [rec0], o.replace(load="none", residual="none"), **again)
        without = float(alt.models[rec0].metrics.get("nmse_percent", math.inf))
    except ParameterError:  # nothing fits without the terms (a pendulum without gravity): keep them
        without = math.inf
    with_terms = float(results[rec0].metrics.get("nmse_percent", math.inf))
    if without > with_terms:
        return None
    res = fit_records(ctx.records_in, ctx.models, o.replace(load="none"), progress=ctx.progress, **again)
    res.warnings.insert(
        0,
        f"the load terms chosen on the linear backbone ({terms.describe()}) did not lower the validation "
        f"NMSE of {rec0} ({with_terms:.4g} % with them, {without:.4g} % without): fitted without load terms",
    )
    res.options["load_selection"] = ctx.selection.table() + ["rejected: no gain on the recommended model"]
    return res


def add_residual(ctx: FitContext) -> None:
    """The learned residual on the recommended model (``residual``;
    :func:`~friction_ros.core.identification.fit.residual_learning.with_residual`); ``auto`` learns none
    for a log with >= 3 plateaus. The combined model competes like any other."""
    residual = ctx.options.residual
    if residual == "auto":
        residual = "none" if len(ctx.plateaus) >= 3 else "auto"
    best = ctx.recommendation["model"]
    if residual == "none" or best is None:
        return
    combined = with_residual(
        ctx.results[best],
        ctx.train,
        ctx.val,
        ctx.vall,
        residual,
        ctx.options.seed,
        ctx.high_mask,
        ctx.low_mask,
        ctx.scored,
        ctx.warnings,
    )
    if combined is not None:
        ctx.results[combined.name] = ctx.candidates[combined.name] = combined
        ctx.recommendation = metrics.recommend_with_rule({n: r.metrics for n, r in ctx.candidates.items()})


def recommend(ctx: FitContext) -> None:
    """The final recommendation: on the plateaus when no model explains the time series
    (:func:`~friction_ros.core.identification.fit.metrics.recommend_by_plateaus`), checked against the
    baseline (:func:`~friction_ros.core.identification.fit.recommendation.checked_recommendation`);
    the verdict (:func:`~friction_ros.core.identification.fit.recommendation.verdict`) and every fitted
    model's steady-state map on the velocity grid."""
    candidates, results, plateaus = ctx.candidates, ctx.results, ctx.plateaus
    recommendation = ctx.recommendation
    nmse = [r.metrics.get("nmse_percent", math.nan) for r in candidates.values()]
    if len(plateaus) >= 3 and nmse and all(not (x < metrics.NO_SIGNAL_NMSE) for x in nmse):
        recommendation = metrics.recommend_by_plateaus(
            {n: (r.steady_state, r.metrics.get("n_params", 1)) for n, r in candidates.items()}, plateaus
        )
    if recommendation["model"] is not None or ctx.baseline.fitted:
        recommendation = checked_recommendation(recommendation, candidates, ctx.baseline)
    ctx.recommendation = recommendation
    rec = recommendation["model"]
    if rec is None:
        ctx.warnings.append(
            "no model is recommended and no parameter file is written: "
            + (recommendation.get("reason") or recommendation.get("rule") or "no model could be exported")
        )
    tried = ctx.selection is not None and ctx.options.load == "auto"
    ctx.verdict = verdict(results, rec, ctx.val, ctx.vall, ctx.terms, ctx.eps, tried=tried)
    if ctx.verdict["explains_little"]:
        ctx.warnings.append(ctx.verdict["text"])
    for r in [r for r in results.values() if r.fitted]:
        r.extra["steady_state_grid"] = {
            "velocity": ctx.grid.tolist(),
            "friction": np.asarray(r.steady_state(ctx.grid)).tolist(),
        }


def fit_result(ctx: FitContext) -> FitResult:
    """The :class:`~friction_ros.core.identification.fit.fit_results.FitResult`, with the options used."""
    o = ctx.options
    return FitResult(
        ctx.results,
        ctx.recommendation["model"],
        ctx.train,
        ctx.val,
        ctx.plateaus,
        ctx.breakaways,
        ctx.excitation,
        ctx.high_threshold,
        {
            "train_seconds": o.train_seconds,
            "load_offset": ctx.offset,
            "train_window": o.train_window,
            "train_windows_s": ctx.windows,
            "load_terms": ctx.terms.describe(),
            "load_selection": ctx.selection.table() if ctx.selection is not None else [],
            "validation_records": len(ctx.validation or []),
            "verdict": ctx.verdict,
            "optimizer": o.optimizer,
            "seed": o.seed,
            "eps": ctx.eps,
            "data_scale": {"velocity": ctx.scale.velocity, "torque": ctx.scale.torque},
            "joint_type": o.joint_type,
            "models": ctx.names,
        },
        warnings=ctx.warnings,
        seconds=time.perf_counter() - ctx.t_start,
        recommendation=ctx.recommendation,
    )


def _load_part(fit) -> Callable[[JointData], np.ndarray]:
    """record -> the load-term torque of a fit (its load columns times their coefficients)."""
    from friction_ros.core.identification.fit.dynamic_fit import fit_signals

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
