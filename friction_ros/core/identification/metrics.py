"""Model comparison metrics (seed 003 Table 1) and information criteria.

* NMSE in percent, seed 003 eq. (4): ``MSE = 100 / (N sigma_y^2) sum (yhat_i - y_i)^2`` with y the
  measured joint torque (eq. 1: tau_m = J a + tau_f; the inertial part is small at these rates)
  and sigma_y^2 its variance over the same samples; yhat = mean(y) gives 100 %.
* Max. error as in Table 1's brackets: peak-to-peak error normalised by the RMS of the measured
  torque, ``(max e - min e) / rms(y)``.
* AIC = N ln(SSE/N) + 2k and BIC = N ln(SSE/N) + k ln N (Gaussian errors; k = parameter count
  including J), on the validation samples.
* Recommended model: lowest BIC; among models within 2 % (relative) of the best low-velocity NMSE,
  the one with fewer parameters (seed 003: GMS-10 is "not worth the extra 12 parameters").
"""

from __future__ import annotations

import math

import numpy as np


def nmse_percent(y_hat, y) -> float:
    """Seed 003 eq. (4) normalised MSE in percent."""
    y = np.asarray(y, dtype=float)
    e = np.asarray(y_hat, dtype=float) - y
    var = float(np.var(y))
    if y.size == 0 or var <= 0:
        return math.nan
    return float(100.0 * np.mean(e**2) / var)


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


def compare(y_hat, y, high_mask, k: int) -> dict:
    """All metrics of one model on validation data."""
    y_hat = np.asarray(y_hat, dtype=float)
    y = np.asarray(y, dtype=float)
    hm = np.asarray(high_mask, bool)
    aic, bic = information_criteria(y_hat, y, k)
    return {
        "nmse_percent": nmse_percent(y_hat, y),
        "nmse_high_percent": nmse_percent(y_hat[hm], y[hm]) if hm.any() else math.nan,
        "nmse_low_percent": nmse_percent(y_hat[~hm], y[~hm]) if (~hm).any() else math.nan,
        "max_error_high": peak_error(y_hat[hm], y[hm]) if hm.any() else math.nan,
        "max_error_low": peak_error(y_hat[~hm], y[~hm]) if (~hm).any() else math.nan,
        "rmse": float(np.sqrt(np.mean((y_hat - y) ** 2))),
        "n_params": int(k),
        "aic": aic,
        "bic": bic,
        "n_samples": int(y.size),
    }


def recommend(metrics: dict[str, dict], margin: float = 0.02) -> str | None:
    """Lowest BIC; then prefer a smaller model whose low-velocity NMSE is within ``margin`` (relative)."""
    ok = {m: v for m, v in metrics.items() if v and math.isfinite(v.get("bic", math.nan))}
    if not ok:
        return None
    best = min(ok, key=lambda m: ok[m]["bic"])
    key = "nmse_low_percent" if math.isfinite(ok[best].get("nmse_low_percent", math.nan)) else "nmse_percent"
    ref = ok[best][key]
    for m in sorted(ok, key=lambda m: ok[m]["n_params"]):
        if ok[m]["n_params"] < ok[best]["n_params"] and ok[m][key] <= ref * (1 + margin) + 1e-9:
            return m
    return best
