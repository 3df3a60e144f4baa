"""Which fitted models may be shown and recommended: failures, divergence, the baseline bar and
identifiability.

* a model whose fit raised is ``not fitted`` (with the reason); the others proceed;
* a model whose validation prediction is not finite, whose validation error exceeds
  ``DIVERGED_NMSE`` percent of the torque's variance, or which does worse than a constant and
  ``BASELINE_FACTOR`` times worse than the baseline (a simulation that ran away or a fit that does
  not transfer), is ``diverged``: its figures and coefficients are withheld, never printed;
* a model is recommended only when it beats the inverse-dynamics baseline
  (:mod:`~friction_ros.core.identification.fit.baseline`) on validation;
* a recommended model with a coefficient whose standard error exceeds its value is
  unidentifiable from the log: the next simpler candidate wins (down to the baseline).
"""

from __future__ import annotations

import math

import numpy as np

from friction_ros.core.identification.fit.fit_results import ModelResult
from friction_ros.core.identification.fit.metrics import nmse_percent, relative_error_percent

#: validation NMSE [%] above which a model's prediction is called diverged (twice the variance of
#: the measured torque: farther from the measurement than a constant is, by a wide margin)
DIVERGED_NMSE = 200.0
#: ... or worse than a constant and this many times the inverse-dynamics baseline's validation NMSE
BASELINE_FACTOR = 1.5
#: relative error [%] (100 ||y - y_hat|| / ||y||) beyond which a plateau map's prediction ran away
RUNAWAY_PERCENT = 300.0


def failed_model(name: str, status: str, reason: str) -> ModelResult:
    """A placeholder result without figures: ``status`` "not fitted" or "diverged"."""
    reason = " ".join(str(reason).split())[:300]
    return ModelResult(
        name, status, {}, None, {}, {}, 0.0, _no_map, _no_prediction, [reason], {}, status, reason
    )


def _no_map(v):
    return np.full(np.shape(v), np.nan)


def _no_prediction(r):
    return np.full(r.n, np.nan)


def judge_divergence(res: ModelResult, measured: np.ndarray, baseline: ModelResult | None = None) -> None:
    """Mark ``res`` diverged (in place: figures, coefficients and config withheld) when its
    validation prediction is not finite, its NMSE exceeds :data:`DIVERGED_NMSE`, or it is worse
    than a constant (NMSE > 100 %) and :data:`BASELINE_FACTOR` times the baseline's NMSE; in both
    cases only when its error is also larger than the torque itself (relative error > 100 %: a
    torque without variance makes any NMSE large). A static map fitted to constant-velocity
    plateaus is judged on the plateaus, not on the time-domain torque (which also holds the load
    between them): it diverged only when its prediction is not finite or its error exceeds
    :data:`RUNAWAY_PERCENT` of the torque itself."""
    yhat = np.asarray(res.extra.get("validation_prediction", []), dtype=float)
    y = np.asarray(measured, dtype=float)
    why = ""
    if yhat.shape != y.shape or not np.all(np.isfinite(yhat)):
        why = "its prediction on the validation data is not finite"
    else:
        nm = nmse_percent(yhat, y)
        rel = relative_error_percent(yhat, y)
        if res.method == "plateaus":  # judged on its plateaus (docstring): only a runaway counts
            nm = math.nan
            if rel > RUNAWAY_PERCENT:
                why = f"its error on the validation data is more than {RUNAWAY_PERCENT / 100:g} times the torque itself"
        if not rel > 100.0:
            nm = math.nan  # nearer the measurement than zero is: not diverged (a torque without variance)
        nb = (
            float(baseline.metrics.get("nmse_percent", math.nan))
            if baseline and baseline.fitted
            else math.nan
        )
        cause = (
            "the fit does not carry over to the validation data (a simulation that ran away, or "
            "coefficients the training data do not determine)"
        )
        if why:
            pass
        elif math.isfinite(nm) and nm > DIVERGED_NMSE:
            why = f"its validation error is more than {DIVERGED_NMSE / 100:g} times the variance of the measured torque: {cause}"
        elif math.isfinite(nm) and math.isfinite(nb) and nm > 100.0 and nm > BASELINE_FACTOR * nb:
            why = (
                f"its validation error is larger than the variance of the measured torque and {BASELINE_FACTOR:g} "
                f"times the baseline's: {cause}"
            )
    if not why:
        return
    k = res.metrics.get("n_params")
    res.status, res.reason = "diverged", why
    res.metrics = {"n_params": k} if k is not None else {}
    res.coefficients, res.config, res.identifiability = {}, None, {}
    res.notes = [why]
    res.steady_state, res.predict = _no_map, _no_prediction
    res.extra = {}


def unidentifiable(res: ModelResult) -> list[str]:
    """Coefficients of ``res`` whose standard error exceeds their value (or flagged not identifiable)."""
    idf = res.identifiability or {}
    out = [n for n in idf.get("not_identifiable", []) if _friction_coefficient(n)]
    for name, iv in (idf.get("ci95") or {}).items():
        if not _friction_coefficient(name) or name in out:
            continue
        if iv is None or not all(math.isfinite(x) for x in iv):
            out.append(name)
            continue
        value, se = 0.5 * (iv[0] + iv[1]), (iv[1] - iv[0]) / 3.92  # the interval is value +- 1.96 se
        if se > abs(value):
            out.append(name)
    return out


def _friction_coefficient(name: str) -> bool:
    """A coefficient of the friction model (not the inertia or a load term, which may be 0)."""
    load = ("gravity", "offset", "spring", "ripple", "load_friction")
    return name != "J" and not name.startswith(load)


def beats_baseline(res: ModelResult, baseline: ModelResult | None) -> bool:
    """Lower validation NMSE than the baseline (True when there is no usable baseline)."""
    if baseline is None or not baseline.fitted:
        return True
    a = float(res.metrics.get("nmse_percent", math.nan))
    b = float(baseline.metrics.get("nmse_percent", math.nan))
    if not math.isfinite(b):
        return True
    return math.isfinite(a) and a < b
