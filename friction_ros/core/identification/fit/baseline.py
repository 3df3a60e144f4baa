"""The classical inverse-dynamics baseline that every recommended model must beat.

The textbook identification of a joint (and the "physical model" row of the published system
identification benchmarks) is one ordinary least-squares solve of the inverse dynamics::

    tau = J a + F_v v + F_c sgn_eps(v) + offset [+ the load terms the log calls for]

(the offset is left to gravity's sin/cos columns when the log calls for gravity)

with ``sgn_eps(v) = clip(v / eps, -1, 1)`` and ``eps`` three standard deviations of the velocity
noise (the load terms' linear zone), with ``J, F_v, F_c >= 0`` (bounded least squares; the load
terms are free). It has no search, cannot diverge, and its figures are the bar
a richer model must clear on validation before the fitter recommends it. The standard error of
each coefficient is ``sqrt(diag(s^2 (X'X)^-1))`` with ``s^2 = SSE / (N - p)``.
"""

from __future__ import annotations

import dataclasses
import time

import numpy as np
from scipy.optimize import lsq_linear

from friction_ros.core.friction import model_from_config
from friction_ros.core.identification.data.records import JointData
from friction_ros.core.identification.fit import metrics
from friction_ros.core.identification.fit.fit_registry import library_config
from friction_ros.core.identification.fit.fit_results import ModelResult
from friction_ros.core.identification.fit.load_terms import LoadTerms
from friction_ros.core.identification.fit.model_status import failed_model, judge_divergence
from friction_ros.core.validation import ParameterError

NAME = "baseline"


def _terms(terms: LoadTerms, both_ways: bool) -> LoadTerms:
    # an offset unless gravity's sin/cos columns are in (over a short stroke cos q is nearly
    # constant: both would trade against each other and extrapolate wildly) or the joint moved one
    # way only (sgn(v) is then a constant too); the transmitted torque needs a load model the
    # baseline does not have
    offset = (terms.offset or not terms.gravity) and both_ways
    return dataclasses.replace(terms, offset=offset, load_friction=False)


def _design(terms: LoadTerms, r: JointData) -> np.ndarray:
    v = np.asarray(r.velocity, dtype=float)
    sg = np.clip(v / terms.eps, -1.0, 1.0)
    return np.column_stack([r.acceleration, v, sg, terms.columns(r.position, v, None)])


def fit_baseline(train: list[JointData], terms: LoadTerms) -> ModelResult:
    """The baseline fitted to the training records (metrics are filled in by the caller)."""
    t0 = time.perf_counter()
    v = np.concatenate([r.velocity for r in train])
    lt = _terms(terms, bool(np.any(v > terms.eps) and np.any(v < -terms.eps)))
    names = ["J", "fv", "fc", *lt.names]
    X = np.vstack([_design(lt, r) for r in train])
    y = np.concatenate([r.torque for r in train])
    ok = np.all(np.isfinite(X), axis=1) & np.isfinite(y)
    X, y = X[ok], y[ok]
    scale = np.sqrt(np.maximum(np.sum(X**2, axis=0), 1e-300))
    # J, fv, fc >= 0 (a friction that pushes the joint, or a negative inertia, is no baseline: on
    # coupled arm data an unbounded fit trades them against the other link's torque); load terms free
    lo = np.array([0.0, 0.0, 0.0] + [-np.inf] * len(lt.names))
    coef_s = lsq_linear(X / scale, y, bounds=(lo, np.inf), method="bvls").x
    coef = coef_s / scale
    resid = y - X @ coef
    dof = max(y.size - len(names), 1)
    s2 = float(resid @ resid / dof)
    cov_s = s2 * np.linalg.pinv((X / scale).T @ (X / scale))
    se = np.sqrt(np.maximum(np.diag(cov_s), 0.0)) / scale
    c = dict(zip(names, coef.tolist()))
    stderr = dict(zip(names, se.tolist()))
    load_c = {n: c[n] for n in lt.names}
    coefs = {"fc": c["fc"], "fv": c["fv"], "J": c["J"]}
    notes = [
        "ordinary least squares of tau = J a + fv v + fc sgn(v) + "
        + (lt.describe() if not lt.empty else "offset")
        + f" on {y.size} training samples (sgn linear zone {lt.eps:.3g})"
    ]
    cfg = library_config("coulomb_viscous", {"fc": c["fc"], "fv": c["fv"]}, eps=lt.eps)
    try:
        model_from_config(cfg)
    except ParameterError as exc:
        notes.append(f"not exportable: {exc}")
        cfg = None
    useless = [n for n in ("fc", "fv", "J") if not abs(c[n]) > stderr[n]]
    if useless:
        notes.append("standard error larger than the value (not identifiable): " + ", ".join(useless))

    def predict(r: JointData, coef=coef) -> np.ndarray:
        return _design(lt, r) @ coef

    def steady_state(v, fc=c["fc"], fv=c["fv"], eps=lt.eps):
        v = np.asarray(v, dtype=float)
        return fc * np.clip(v / eps, -1.0, 1.0) + fv * v

    ident = {
        "stderr": stderr,
        "ci95": {n: [c[n] - 1.96 * stderr[n], c[n] + 1.96 * stderr[n]] for n in names},
        "not_identifiable": [],
        "useless_ci": useless,
    }
    m = ModelResult(
        NAME,
        "inverse-dynamics least squares",
        coefs,
        cfg,
        {},
        ident,
        time.perf_counter() - t0,
        steady_state,
        predict,
        notes,
    )
    m.extra["train_mse"] = float(np.mean(resid**2))
    m.extra["load"] = lt.joint_load(load_c).to_config()
    m.extra["load_coefficients"] = load_c
    b_load = np.array([c[n] for n in lt.names])

    def load_part(r: JointData) -> np.ndarray:
        return terms_columns(lt, r) @ b_load if lt.names else np.zeros(r.n)

    m.extra["load_part"] = load_part
    return m


def terms_columns(lt: LoadTerms, r: JointData) -> np.ndarray:
    """The load-term columns of a record for the baseline's terms."""
    return lt.columns(r.position, r.velocity, None)


def validated_baseline(train, terms, predict_val, vall, hm, lm, scored) -> ModelResult:
    """The inverse-dynamics baseline with its validation metrics (or why it could not be fitted)."""
    try:
        b = fit_baseline(train, terms)
        yb = predict_val(b)
        k = 3 + len(b.extra["load_coefficients"])
        b.metrics = metrics.compare(yb, vall.torque, hm, k, low_mask=lm, scored=scored)
        b.extra["validation_prediction"] = yb
    except Exception as exc:  # never stops the fit: the models are still compared with each other
        return failed_model(NAME, "not fitted", f"{type(exc).__name__}: {exc}")
    judge_divergence(b, vall.torque)
    return b
