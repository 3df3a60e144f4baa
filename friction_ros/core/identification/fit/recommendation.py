"""The recommendation's last checks and its verdict.

* :func:`checked_recommendation`: a model with an unidentifiable friction coefficient gives way to
  the best simpler candidate; a model that does not beat the inverse-dynamics baseline on
  validation gives way to the baseline;
* :func:`verdict`: does the recommended model explain the torque, and if not, what the residual
  follows (:mod:`~friction_ros.core.identification.fit.diagnosis`).
"""

from __future__ import annotations

import math

import numpy as np

from friction_ros.core.identification.fit import metrics
from friction_ros.core.identification.fit.fit_results import ModelResult
from friction_ros.core.identification.fit.model_status import beats_baseline, unidentifiable

EXPLAINS_LITTLE_NMSE = 30.0  # [%] validation NMSE above which a recommendation comes with a warning


def checked_recommendation(recommendation: dict, candidates: dict, baseline: ModelResult) -> dict:
    """The recommendation after two checks: a model with an unidentifiable friction coefficient
    (standard error > value) gives way to the best simpler candidate; a model that does not beat
    the inverse-dynamics baseline on validation gives way to the baseline."""
    rec = recommendation["model"]
    notes = []
    pool = dict(candidates)
    while rec is not None and (bad := unidentifiable(pool[rec])):
        k = pool[rec].metrics.get("n_params", 0)
        notes.append(
            f"{rec} has coefficients the log does not determine (standard error > value: {', '.join(bad)})"
        )
        pool = {n: r for n, r in pool.items() if r.metrics.get("n_params", 0) < k}
        rec = metrics.recommend_with_rule({n: r.metrics for n, r in pool.items()})["model"] if pool else None
    plateau_rule = "plateau means" in recommendation.get("rule", "")
    if rec is not None and not plateau_rule and not beats_baseline(pool[rec], baseline):
        notes.append(
            f"{rec} does not beat the inverse-dynamics baseline on validation "
            f"(NMSE {pool[rec].metrics.get('nmse_percent', math.nan):.4g} % vs "
            f"{baseline.metrics.get('nmse_percent', math.nan):.4g} %)"
        )
        rec = None
    if rec is None and baseline.fitted and baseline.config is not None:
        rec = baseline.name
        notes.append("the baseline (Coulomb + viscous + inertia + load terms, least squares) is recommended")
    elif rec is None:
        notes.append(
            "no model beats the inverse-dynamics baseline and the baseline is not exportable: nothing to recommend"
        )
    if not notes:
        return recommendation
    reason = "; ".join(filter(None, [recommendation.get("reason", "")] + notes))
    return {**recommendation, "model": rec, "reason": reason}


def verdict(results, rec, val, vall, terms, eps, tried: bool = False) -> dict:
    """Does the recommended model explain the torque? If not, what the residual follows (diagnosis;
    ``tried``: the automatic load-term selection ran, so its terms are not suggested again)."""
    from friction_ros.core.identification.fit import diagnosis

    out = {"explains_little": False, "text": "", "suggestions": []}
    if rec is None:
        return out
    nm = float(results[rec].metrics.get("nmse_percent", math.nan))
    if not (math.isfinite(nm) and nm > EXPLAINS_LITTLE_NMSE):
        return out
    used = {"load-dependent friction" if t == "load_friction" else t for t in terms.describe().split(", ")}
    if terms.ripple:
        used.add("position-dependent friction")
    if tried:  # the automatic selection tried every load term on these data: not suggested again
        used |= {"gravity", "offset", "spring", "load-dependent friction", "position-dependent friction"}
    resid = vall.torque - np.asarray(results[rec].extra["validation_prediction"])
    tips = diagnosis.suggestions(val, resid, used, max(eps, terms.eps))
    what = ", no better than a constant: it explains nothing" if nm >= metrics.NO_SIGNAL_NMSE else ""
    text = (
        f"the recommended model {rec} explains little of the measured torque (validation NMSE {nm:.1f} % > "
        f"{EXPLAINS_LITTLE_NMSE:g} %{what}): do not compensate with it before checking; "
        + (
            "; ".join(tips)
            if tips
            else "a load or gravity term, more excitation or a sensor problem is missing"
        )
    )
    return {"explains_little": True, "text": text, "suggestions": tips, "nmse_percent": nm}


def verdict_label(res) -> tuple[str, float | None]:
    """(verdict, validation NMSE % of the recommended model or None) of a FitResult: ``ok``
    (compensate with it), ``explains little`` (NMSE > :data:`EXPLAINS_LITTLE_NMSE`) or ``explains
    nothing`` (NMSE >= :data:`~.metrics.NO_SIGNAL_NMSE`, no better than a constant); the label of
    friction-fit's per-joint index and of the fleet table."""
    rec = res.models.get(res.recommended) if res.recommended else None
    nmse = rec.metrics.get("nmse_percent") if rec is not None else None
    nmse = float(nmse) if nmse is not None and math.isfinite(float(nmse)) else None
    if not (res.options.get("verdict") or {}).get("explains_little"):
        return "ok", nmse
    nothing = nmse is None or nmse >= metrics.NO_SIGNAL_NMSE
    return ("explains nothing" if nothing else "explains little"), nmse
