"""Each model family's fit turned into a :class:`~friction_ros.core.identification.fit.fit_results.ModelResult`:
static curves from plateaus (with breakaway levels and per-direction levels), dynamic models from a
time-domain fit, and the data the learned models train on.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from friction_ros.core.identification.data.data_scale import velocity_scale
from friction_ros.core.identification.data.records import concat_records
from friction_ros.core.identification.fit import identifiability
from friction_ros.core.identification.fit.dynamic_fit import DynamicFit
from friction_ros.core.identification.fit.fit_registry import fit_model, library_config
from friction_ros.core.identification.fit.fit_results import ModelResult
from friction_ros.core.identification.fit.static_fit import StaticFit, fit_plateaus, stribeck_map
from friction_ros.core.validation import ParameterError


def static_predictor(ss, J):
    return lambda r: J * r.acceleration + ss(r.velocity)


def learning_data(plateaus, train, J, eps):
    pos = [p for p in plateaus if p.velocity > 0]
    neg = [p for p in plateaus if p.velocity < 0]
    if len(pos) >= 6 and len(neg) >= 6:
        return (
            np.array([p.velocity for p in plateaus]),
            np.array([p.torque for p in plateaus]),
            "plateau means",
        )
    r = concat_records(train)
    slide = max(20 * eps, 0.02 * velocity_scale(train[0]))
    m = np.abs(r.velocity) > slide
    return (
        r.velocity[m],
        (r.torque - J * r.acceleration)[m],
        f"sliding samples (|v| > {slide:.3g})",
    )


#: a breakaway reading is used only when the ramp's stated detection lag (an upper bound: one step
#: plus the excess torque that moves 2 counts within a step, no Stribeck drop assumed) is below
#: this share of it; sized ramps state 0.6-1 % (abb_m19s, seed001_harmonic_drive, seed004_dc_motor),
#: 8-28 % (seed002_x/y/z, whose readings were within 0.3 % of the truth) and 250 % (seed000_gearhead's
#: 60-count encoder behind a damped voltage drive: readings 2.7 times the friction level)
BREAKAWAY_LAG_SHARE = 0.5


def breakaway_levels(breakaways) -> dict[int, float]:
    """Median breakaway torque magnitude per direction (the static friction level), from the
    experiment's breakaway ramps only (``source == "events"``): a breakaway detected in an arbitrary
    log (a plateau start, a reversal) is not a slow ramp from rest and would mislead the fit. A
    ramp whose detection lag (START note) exceeds BREAKAWAY_LAG_SHARE of its reading is left out
    (:func:`imprecise_breakaways`)."""
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


def imprecise_breakaways(breakaways) -> str:
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


def fit_static_plateaus(name, plateaus, train, eps, breakaways=()) -> ModelResult:
    levels = breakaway_levels(breakaways)
    shape = fit_model(name).plateau_shape
    sf: StaticFit = fit_plateaus(plateaus, shape, breakaway=levels or None)
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
    cfg = library_config(name, coefs, eps=0.0, per_direction=per)
    _validate_config(cfg)
    notes = [f"fitted to {sf.n_points} plateau means (robust soft-L1 least squares), rms {sf.rms:.3g} N*m"]
    if levels and shape == "stribeck":
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
    m = ModelResult(name, "plateaus", coefs, cfg, {}, ident, sf.seconds, ss, static_predictor(ss, J), notes)
    m.extra["train_mse"] = float(np.mean((J * a + ss(r.velocity) - r.torque) ** 2))
    if per:
        m.extra["per_direction"] = {"positive": per["positive"], "negative": per["negative"]}
    return m


def direction_part(per: dict, joint: dict) -> Callable[[np.ndarray], np.ndarray]:
    """``d(v) = F_dir(v) - F_joint(v)``: what the direction-dependent steady state adds to the
    symmetric one (both Stribeck maps of the plateau fit)."""

    def d(v):
        v = np.asarray(v, dtype=float)
        f = np.where(v >= 0, stribeck_map(v, per["positive"]), stribeck_map(v, per["negative"]))
        return f - stribeck_map(v, joint)

    return d


def with_direction_levels(m: ModelResult, per: dict, joint: dict) -> ModelResult:
    """A symmetric dynamic fit made direction-dependent (an asymmetric joint, AI friction chapter B.3): the
    time-domain fit saw the torque less ``d(v)`` (:func:`direction_part`); prediction and steady
    state add it back, and the exported config is the library's ``asymmetric`` wrapper with the
    presliding coefficients shared and each direction's ``fc, fs, vs, delta, fv`` from the plateaus."""
    d = direction_part(per, joint)
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


def wrap_dynamic(name, fit: DynamicFit, eps, grid, ident_check, train) -> ModelResult:
    coefs = fit.coefficients
    cfg = library_config(name, coefs, eps=eps)
    notes = []
    try:
        _validate_config(cfg)
    except ParameterError as exc:
        notes.append(f"library config rejected: {exc}")
        cfg = None
    spec = fit.spec

    def ss(v, c=coefs):
        return spec.model.steady_state(c, np.asarray(v, dtype=float), eps)

    ident = {}
    if ident_check:
        try:
            jac, res, names, values = identifiability.time_domain_jacobian(fit, train)
            ident = identifiability.analyse(jac, res, names, values)
        except (np.linalg.LinAlgError, ValueError) as exc:
            notes.append(f"identifiability analysis failed: {exc}")
    if held := held_coefficients(spec):  # pinned by the two-stage fit: a time-domain interval says nothing
        for n in held:
            ident.get("ci95", {}).pop(n, None)
            ident.get("stderr", {}).pop(n, None)
        ident["held"] = held
        ident["useless_ci"] = [n for n in ident.get("useless_ci", []) if n not in held]
        notes.append(
            f"{', '.join(held)} held at the plateau fit's values (two-stage identification): their "
            "uncertainty is the plateau fit's (see the static model's intervals), not a time-domain interval"
        )
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


def held_coefficients(spec) -> list[str]:
    """The coefficients a two-stage fit held at the plateau fit's values (FitSpec.fix_steady_state):
    nonlinear ones with bounds pinned to +-0.1 %, linear ones fixed by a constraint."""
    held = [n for n, lo, hi in zip(spec.nonlinear, spec.lower, spec.upper) if lo > 0 and hi <= lo * 1.0021]
    names = spec.linear_all
    for c, _ in spec.linear_constraints:
        held += [names[i] for i in np.nonzero(np.asarray(c) != 0)[0] if names[i] not in held]
    if "r" in held:  # r = fc / fs held: fc is held too
        held.append("fc")
    return held
