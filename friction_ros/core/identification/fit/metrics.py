"""Model comparison metrics (ABB M19-S paper Table 1) and information criteria.

* NMSE in percent, ABB M19-S paper eq. (4): ``MSE = 100 / (N sigma_y^2) sum (yhat_i - y_i)^2`` with y the
  measured joint torque (eq. 1: tau_m = J a + tau_f; the inertial part is small at these rates)
  and sigma_y^2 its variance over the same samples; yhat = mean(y) gives 100 %.
* Relative error in percent, ``100 ||y - yhat|| / ||y||`` (the figure published system
  identification benchmarks report beside NMSE; unlike NMSE it counts the mean of y as signal).
* Max. error as in Table 1's brackets: peak-to-peak error normalised by the RMS of the measured
  torque, ``(max e - min e) / rms(y)``.
* AIC = N ln(SSE/N) + 2k and BIC = N ln(SSE/N) + k ln N (Gaussian errors; k = parameter count
  including J), on the validation samples.
* Recommended model (:func:`recommend_with_rule`): lowest validation BIC; a model with fewer
  parameters replaces it when its validation NMSE is within 5 % (relative) of it, overall and at
  low velocity (ABB M19-S paper: GMS-10 is "not worth the extra 12 parameters"). Unavailable metrics (a
  subset without signal above the noise) never decide.
"""

from __future__ import annotations

import math

import numpy as np


def nmse_percent(y_hat, y) -> float:
    """ABB M19-S paper eq. (4) normalised MSE in percent."""
    y = np.asarray(y, dtype=float)
    e = np.asarray(y_hat, dtype=float) - y
    var = float(np.var(y))
    if y.size == 0 or var <= 1e-9 * float(np.mean(y**2)):  # a constant torque: NMSE undefined
        return math.nan
    return float(100.0 * np.mean(e**2) / var)


def relative_error_percent(y_hat, y) -> float:
    """The system-identification benchmarks' relative error ``100 ||y - y_hat|| / ||y||`` [%]."""
    y = np.asarray(y, dtype=float)
    n = float(np.linalg.norm(y))
    if y.size == 0 or not n > 0:
        return math.nan
    return float(100.0 * np.linalg.norm(y - np.asarray(y_hat, dtype=float)) / n)


def peak_error(y_hat, y) -> float:
    """Peak-to-peak error normalised by the RMS of y (Table 1 brackets)."""
    y = np.asarray(y, dtype=float)
    if y.size == 0:
        return math.nan
    e = np.asarray(y_hat, dtype=float) - y
    return float((e.max() - e.min()) / (np.sqrt(np.mean(y**2)) + 1e-300))


def information_criteria(y_hat, y, k: int) -> tuple[float, float]:
    y = np.asarray(y, dtype=float)
    n = y.size
    sse = float(np.sum((np.asarray(y_hat) - y) ** 2))
    ll = n * math.log(max(sse / n, 1e-300))
    return ll + 2 * k, ll + k * math.log(n)


def _subset_metric(y_hat, y, mask, noise_var: float, min_samples: int = 200) -> tuple[float, float, str]:
    """(NMSE %, peak error, note) on a subset; NaN with the reason when it carries no signal."""
    n = int(np.sum(mask))
    if n < min_samples:
        return math.nan, math.nan, f"{n} samples in this subset (need {min_samples})"
    var = float(np.var(y[mask]))
    if not var > 4.0 * noise_var:
        return (
            math.nan,
            math.nan,
            f"the measured torque varies no more than its noise there (variance {var:.3g} vs noise {noise_var:.3g})",
        )
    return nmse_percent(y_hat[mask], y[mask]), peak_error(y_hat[mask], y[mask]), ""


def torque_noise_variance(y) -> float:
    """Variance of the torque noise from first differences (robust: median absolute difference)."""
    y = np.asarray(y, dtype=float)
    if y.size < 3:
        return 0.0
    s = float(np.median(np.abs(np.diff(y)))) / (math.sqrt(2.0) * 0.6745)
    return s * s


def compare(y_hat, y, high_mask, k: int, low_mask=None, noise_var: float | None = None, scored=None) -> dict:
    """All metrics of one model on validation data.

    ``high_mask``/``low_mask``: the high- and low-velocity *moving* samples (default low = not
    high). A subset with fewer than 200 samples or whose measured torque does not vary more than
    its noise has NaN metrics and a ``*_note`` saying why, never a huge number. ``scored``: the
    samples every metric (NMSE, AIC/BIC too) is computed on, default all; the pipeline leaves out
    long standstills (:func:`~friction_ros.core.identification.data.velocity_regimes.standstill_mask`), where the
    friction is whatever torque holds the joint and no model can be scored
    (``n_rest_excluded`` counts them).
    """
    y_hat = np.asarray(y_hat, dtype=float)
    y = np.asarray(y, dtype=float)
    hm = np.asarray(high_mask, bool)
    lm = ~hm if low_mask is None else np.asarray(low_mask, bool)
    sc = np.ones(y.shape, bool) if scored is None else np.asarray(scored, bool)
    n_rest = int(np.sum(~sc))
    y_hat, y, hm, lm = y_hat[sc], y[sc], hm[sc], lm[sc]
    nv = torque_noise_variance(y) if noise_var is None else float(noise_var)
    aic, bic = information_criteria(y_hat, y, k)
    nh, mh, note_h = _subset_metric(y_hat, y, hm, nv)
    nl, ml, note_l = _subset_metric(y_hat, y, lm, nv)
    out = {
        "nmse_percent": nmse_percent(y_hat, y),
        "rel_error_percent": relative_error_percent(y_hat, y),
        "nmse_high_percent": nh,
        "nmse_low_percent": nl,
        "max_error_high": mh,
        "max_error_low": ml,
        "rmse": float(np.sqrt(np.mean((y_hat - y) ** 2))),
        "n_params": int(k),
        "aic": aic,
        "bic": bic,
        "n_samples": int(y.size),
        "n_high": int(np.sum(hm)),
        "n_low": int(np.sum(lm)),
        "n_rest_excluded": n_rest,
    }
    if note_h:
        out["nmse_high_note"] = note_h
    if note_l:
        out["nmse_low_note"] = note_l
    return out


#: a smaller model is preferred when its validation NMSE is within this relative tolerance of the best
RECOMMEND_TOLERANCE = 0.05


def recommend_with_rule(metrics: dict[str, dict], tolerance: float = RECOMMEND_TOLERANCE) -> dict:
    """The recommended model and the rule that decided.

    Rule (out-of-sample error with a complexity penalty): the model with the lowest BIC on the
    validation samples (``N ln(SSE/N) + k ln N``) is the reference; a model with fewer parameters
    replaces it only if its validation NMSE over all samples is within ``tolerance`` (relative) of
    the reference's AND, when both have it, its low-velocity NMSE is within ``tolerance`` too. A
    metric that is not available never decides.
    """
    ok = {m: v for m, v in metrics.items() if v and math.isfinite(v.get("bic", math.nan))}
    if not ok:
        return {"model": None, "rule": "no model has a finite validation BIC", "reason": ""}
    best = min(ok, key=lambda m: ok[m]["bic"])
    rule = (
        f"lowest validation BIC (N ln(SSE/N) + k ln N); a model with fewer parameters is preferred when its "
        f"validation NMSE is within {100 * tolerance:g} % (relative) of it, overall and at low velocity"
    )
    ref = ok[best]

    def close(m: str, key: str) -> bool:
        a, b = ok[m].get(key, math.nan), ref.get(key, math.nan)
        if not (math.isfinite(a) and math.isfinite(b)):
            return key != "nmse_percent"  # an unavailable subset metric neither helps nor blocks
        return a <= b * (1.0 + tolerance) + 1e-12

    for m in sorted(ok, key=lambda m: (ok[m]["n_params"], ok[m]["bic"])):
        if ok[m]["n_params"] < ref["n_params"] and close(m, "nmse_percent") and close(m, "nmse_low_percent"):
            return {
                "model": m,
                "rule": rule,
                "reason": f"{m} ({ok[m]['n_params']} parameters) is within {100 * tolerance:g} % of {best} "
                f"({ref['n_params']} parameters, lowest BIC)",
            }
    return {"model": best, "rule": rule, "reason": f"{best} has the lowest validation BIC"}


#: validation NMSE [%] at or above which the torque record discriminates nothing (the mean does as well)
NO_SIGNAL_NMSE = 100.0


def recommend_by_plateaus(models: dict[str, tuple], plateaus) -> dict:
    """The recommendation when no model explains the validation torque (every NMSE >= 100 %: the
    mean predicts it as well, e.g. sub-count motion of a coarse encoder): lowest BIC of the
    steady-state map on the constant-velocity plateau means, ``N ln(SSE/N) + k ln N`` over the
    N plateaus. ``models``: name -> (steady_state, k)."""
    v = np.array([p.velocity for p in plateaus], dtype=float)
    f = np.array([p.torque for p in plateaus], dtype=float)
    scores = {}
    for name, (ss, k) in models.items():
        e = np.asarray(ss(v), dtype=float) - f
        sse = max(float(e @ e), 1e-300 * max(len(v), 1))
        scores[name] = len(v) * math.log(sse / len(v)) + k * math.log(len(v))
    best = min(scores, key=scores.get)
    return {
        "model": best,
        "rule": (
            f"every model's validation NMSE is >= {NO_SIGNAL_NMSE:g} % (the torque record discriminates nothing): "
            f"lowest BIC of the steady-state map on the {len(v)} plateau means (N ln(SSE/N) + k ln N)"
        ),
        "reason": f"{best} has the lowest plateau BIC",
    }


def recommend(metrics: dict[str, dict], margin: float = RECOMMEND_TOLERANCE) -> str | None:
    """The recommended model's name (:func:`recommend_with_rule`)."""
    return recommend_with_rule(metrics, margin)["model"]
