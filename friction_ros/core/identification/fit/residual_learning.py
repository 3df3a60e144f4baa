"""Training of the learned residual on top of a physics friction model (scikit-learn, offline).

Target: the physics model's residual ``r = tau_measured - tau_physics``; inputs: the causal features
of :mod:`friction_ros.core.friction.learned_residual` (one recursion shared with the run-time
``step``: :func:`residual_features` runs :class:`~friction_ros.core.friction.learned_residual.FeatureState`).
Several runs are given as lists of arrays; the history recursion restarts with every run.

Candidates (all on standardised features and target, seeded):

* ``mlp``: ``MLPRegressor`` (tanh, hidden (24, 24), adam, L2 1e-4, early stopping on a 10 %
  shuffled hold-out), exported as flat weights and evaluated by hand in numpy;
* ``rff``: random Fourier features + ridge (``RBFSampler`` with 200 components, ``Ridge``; kernel
  width and ridge penalty chosen on the last 20 % of the training part), exported as a ``cos`` layer;
* ``hgb`` (comparison only, ``compare=("hgb",)``): ``HistGradientBoostingRegressor``; trees are not
  exported (its one-sample predict costs ~100x the 20 us budget).

Choice (``kind="auto"``): the exported candidate with the lowest validation NMSE of the residual;
a cheaper one (fewer multiply-adds) replaces it when within 5 % (relative); None when none beats
r = 0. ``rff`` is fitted first (under a second on 10,000 samples); when it does not beat r = 0 the
MLP (5-11 s of training, most of it on residuals that hold nothing to learn: the realistic and arm
joints of ``bench/_long_logs.py``) is not trained (``report["skipped"]`` says so). Timing is
reported, not used (it would make the choice machine-dependent). Measured by
``bench/learned_residual.py`` (2-core machine shared with other jobs, Python 3.11; validation = last
40 % of every run; torque NMSE %, physics alone -> physics + residual; step() median us/sample):

=====================================  ==============  ==============  ===========  =============
data                                   mlp             rff             hgb (trees)  chosen
=====================================  ==============  ==============  ===========  =============
hysteresis joint (40 s, 1 ms)          13.5 -> 0.70    13.5 -> 2.3     13.5 -> 1.4  mlp, 10-16 us
realistic_joint (3 x 40 s, 2 ms)       1.22 -> 0.25    1.22 -> 1.02    1.22 -> 0.26 mlp, 9.6 us
DFKI pendulum (3 real runs, pooled)    77.9 -> 217     77.9 -> 55.9    77.9 -> 123  rff, 9-16 us
DFKI pendulum, with the command input  77.9 -> 43.0    (mlp only)                   (leaks, below)
=====================================  ==============  ==============  ===========  =============

The MLP is the model the data favour where the runs are consistent (it matches or beats the
boosted trees at ~10 us per step, the trees cost ~10 ms per single-sample predict); RFF + ridge is
the robust fallback: on the real pendulum, whose three runs disagree with each other (the
authors' own model scores 54-465 % NMSE on them; a per-run fit 0.1-247 %), the MLP extrapolates
badly to each run's tail and RFF is chosen. The ``use_command`` variant is better there because
the logged torque is the controller's command, so the input partly contains the target; in a
compensating controller that closes a loop of gain ~1 (see the run-time module): off by default.
"""

from __future__ import annotations

import time
import warnings
from collections.abc import Mapping, Sequence

import numpy as np

from friction_ros.core.friction.learned_residual import (
    FeatureState,
    LearnedResidual,
    feature_names,
    feature_settings,
)
from friction_ros.core.identification.fit import metrics
from friction_ros.core.identification.fit.fit_results import ModelResult
from friction_ros.core.validation import ParameterError

EXPORTED = ("mlp", "rff")
COMPARED = ("hgb",)
TOLERANCE = 0.05  # relative validation-NMSE margin within which the cheaper model is preferred


def _runs(x, name: str) -> list[np.ndarray]:
    if x is None:
        return []
    if isinstance(x, (list, tuple)) and len(x) and np.ndim(x[0]) == 1:
        return [np.asarray(r, dtype=float).ravel() for r in x]
    return [np.asarray(x, dtype=float).ravel()]


def _as_runs(q, v, command, residual=None):
    qs, vs = _runs(q, "q"), _runs(v, "v")
    cs = _runs(command, "command") if command is not None else [np.zeros_like(a) for a in qs]
    rs = _runs(residual, "residual") if residual is not None else [np.zeros_like(a) for a in qs]
    if not (len(qs) == len(vs) == len(cs) == len(rs)):
        raise ParameterError(
            f"q, v, command, residual have different numbers of runs ({len(qs)}, {len(vs)}, {len(cs)}, {len(rs)})"
        )
    for i, (a, b, c, d) in enumerate(zip(qs, vs, cs, rs)):
        if not (a.size == b.size == c.size == d.size):
            raise ParameterError(f"run {i}: q, v, command, residual have different lengths")
        for n, arr in (("q", a), ("v", b), ("command", c), ("residual", d)):
            if not np.all(np.isfinite(arr)):
                raise ParameterError(f"run {i}: {n} holds non-finite values")
    return qs, vs, cs, rs


def residual_features(q, v, command, dt: float, settings: Mapping | None = None) -> np.ndarray:
    """The run-time features (shape (N, n)) of one run or of several runs (lists; concatenated, the
    history restarting with each run): the same recursion as ``LearnedResidual.step``."""
    s = feature_settings({**(settings or {}), "dt": float(dt)})
    qs, vs, cs, _ = _as_runs(q, v, command)
    return np.concatenate([FeatureState(s).batch(a, b, c) for a, b, c in zip(qs, vs, cs)], axis=0)


def _nmse(pred, y) -> float:
    return float(100.0 * np.mean((pred - y) ** 2) / np.var(y)) if np.var(y) > 0 else float("nan")


def _export(kind, layers, settings, mu, sd, ym, ys, xt, yt, fade) -> LearnedResidual:
    """A LearnedResidual from layers [(W (out, in), b)] fitted on ``(x - mu) / sd`` to
    ``(r - ym) / ys``; feature and clip ranges from all training samples ``xt``, ``yt``."""
    sizes = [layers[0][0].shape[1]] + [w.shape[0] for w, _ in layers]
    cfg = {
        "kind": kind,
        **settings,
        "feature_mean": mu.tolist(),
        "feature_scale": sd.tolist(),
        "feature_low": xt.min(axis=0).tolist(),
        "feature_high": xt.max(axis=0).tolist(),
        "fade": float(fade),
        "layer_sizes": sizes,
        "weights": np.concatenate([w.ravel() for w, _ in layers]).tolist(),
        "biases": np.concatenate([b.ravel() for _, b in layers]).tolist(),
        "output_mean": float(ym),
        "output_scale": float(ys),
        "clip_low": float(yt.min()),
        "clip_high": float(yt.max()),
    }
    return LearnedResidual(cfg)


def _scale(x) -> np.ndarray:
    s = x.std(axis=0)
    return np.where(s > 1e-12, s, 1.0)


def _fit_mlp(xs, ys, seed, hidden):
    from sklearn.exceptions import ConvergenceWarning
    from sklearn.neural_network import MLPRegressor

    m = MLPRegressor(
        hidden_layer_sizes=tuple(hidden),
        activation="tanh",
        solver="adam",
        alpha=1e-4,
        batch_size=256,
        learning_rate_init=1e-3,
        max_iter=300,
        early_stopping=True,
        validation_fraction=0.1,
        n_iter_no_change=15,
        random_state=seed,
    )
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", ConvergenceWarning)
        m.fit(xs, ys)
    converged = not any(issubclass(w.category, ConvergenceWarning) for w in caught)
    layers = [(w.T.copy(), b.copy()) for w, b in zip(m.coefs_, m.intercepts_)]
    return layers, {"epochs": int(m.n_iter_), "converged": converged}


def _fit_rff(xs, ys, seed, components):
    from sklearn.kernel_approximation import RBFSampler
    from sklearn.linear_model import Ridge

    n_in = xs.shape[1]
    cut = int(0.8 * len(xs))  # in-training hold-out (the tail) for the kernel width and the penalty
    best = None
    for gamma in (0.02, 0.1, 0.5):
        f = RBFSampler(gamma=gamma, n_components=components, random_state=seed).fit(xs[:cut])
        zt, zh = f.transform(xs[:cut]), f.transform(xs[cut:])
        for alpha in (1e-3, 1e-1, 10.0):
            mse = float(np.mean((Ridge(alpha=alpha).fit(zt, ys[:cut]).predict(zh) - ys[cut:]) ** 2))
            if best is None or mse < best[0]:
                best = (mse, gamma, alpha)
    _, gamma, alpha = best
    f = RBFSampler(gamma=gamma, n_components=components, random_state=seed).fit(xs)
    ridge = Ridge(alpha=alpha).fit(f.transform(xs), ys)
    w1 = np.asarray(f.random_weights_, dtype=float).T.reshape(components, n_in)
    b1 = np.asarray(f.random_offset_, dtype=float).ravel()
    w2 = (np.sqrt(2.0 / components) * ridge.coef_).reshape(1, components)
    return [(w1, b1), (w2, np.array([float(ridge.intercept_)]))], {"gamma": gamma, "ridge_alpha": alpha}


def _fit_hgb(xs, ys, seed):
    from sklearn.ensemble import HistGradientBoostingRegressor

    m = HistGradientBoostingRegressor(max_iter=300, learning_rate=0.1, early_stopping=True, random_state=seed)
    return m.fit(xs, ys)


def _step_us(model: LearnedResidual, q, v, c, n: int = 2000) -> float:
    """Median per-sample time of step() [us] (information only: not used for the choice)."""
    model.reset()
    qs, vs, cs = q[:n].tolist(), v[:n].tolist(), c[:n].tolist()
    times = []
    step, clock = model.step, time.perf_counter
    for a, b, d in zip(qs, vs, cs):
        t0 = clock()
        step(a, b, d)
        times.append(clock() - t0)
    model.reset()
    return float(np.median(times) * 1e6)


def fit_residual(
    q,
    v,
    command,
    residual,
    dt: float,
    *,
    kind: str = "auto",
    seed: int = 0,
    validation: float | Sequence = 0.4,
    settings: Mapping | None = None,
    hidden: Sequence[int] = (24, 24),
    rff_components: int = 200,
    fade: float = 0.1,
    max_train: int = 40000,
    compare: Sequence[str] = (),
) -> tuple[LearnedResidual | None, dict]:
    """Fit the residual map r(x) and return ``(model, report)``.

    ``q, v, command, residual``: arrays of one run or lists of runs (SI; ``command`` may be None).
    ``validation``: a fraction (the last part of every run is held out; its features continue the
    run's history) or a tuple ``(q, v, command, residual)`` of separate runs. ``kind``: ``auto``
    (``mlp`` and ``rff``, chosen by validation NMSE, see the module docstring), ``mlp`` or ``rff``.
    ``compare``: candidates fitted for the report only (``hgb``). At most ``max_train`` training
    samples are used (an even stride). The model is None when no candidate beats r = 0 on
    validation. The report: settings, feature names, per candidate validation/training NMSE of the
    residual [%] and MSE [N^2 m^2], fit time [s], step() time [us], parameter count; ``chosen``;
    ``models`` (the exported LearnedResidual objects) and ``validation_prediction`` (arrays).
    """
    if kind not in ("auto", *EXPORTED):
        raise ParameterError(f"kind = {kind!r} must be one of auto, {', '.join(EXPORTED)}")
    for c in compare:
        if c not in COMPARED + EXPORTED:
            raise ParameterError(f"compare: {c!r} must be one of {', '.join(COMPARED + EXPORTED)}")
    s = feature_settings({**(settings or {}), "dt": float(dt)})
    qs, vs, cs, rs = _as_runs(q, v, command, residual)
    feats = [FeatureState(s).batch(a, b, c) for a, b, c in zip(qs, vs, cs)]
    if isinstance(validation, (int, float)):
        if not 0.0 < float(validation) < 1.0:
            raise ParameterError(
                f"validation = {validation} must be a fraction in (0, 1) or (q, v, command, residual)"
            )
        cuts = [int(round(len(r) * (1.0 - float(validation)))) for r in rs]
        xt = np.concatenate([f[:k] for f, k in zip(feats, cuts)])
        yt = np.concatenate([r[:k] for r, k in zip(rs, cuts)])
        xv = np.concatenate([f[k:] for f, k in zip(feats, cuts)])
        yv = np.concatenate([r[k:] for r, k in zip(rs, cuts)])
    else:
        vq, vv, vc, vr = _as_runs(*validation)
        xt, yt = np.concatenate(feats), np.concatenate(rs)
        xv = np.concatenate([FeatureState(s).batch(a, b, c) for a, b, c in zip(vq, vv, vc)])
        yv = np.concatenate(vr)
    if len(yt) < 50 or len(yv) < 10:
        raise ParameterError(f"too few samples: {len(yt)} training, {len(yv)} validation")
    stride = max(1, int(np.ceil(len(yt) / max_train)))
    xf, yf = xt[::stride], yt[::stride]
    mu, sd = xf.mean(axis=0), _scale(xf)
    ym, ys = float(yf.mean()), float(_scale(yf[:, None])[0])
    xs, yss = (xf - mu) / sd, (yf - ym) / ys
    xvs = (xv - mu) / sd

    report: dict = {
        "settings": dict(s),
        "features": feature_names(s),
        "n_train": int(len(yt)),
        "n_fit": int(len(yf)),
        "n_validation": int(len(yv)),
        "seed": int(seed),
        "validation_zero_mse": float(np.mean(yv**2)),
        "candidates": {},
        "models": {},
        "validation_prediction": {},
    }
    names = [k for k in (EXPORTED if kind == "auto" else (kind,))] + [
        c for c in compare if c not in EXPORTED or kind != "auto"
    ]
    names = list(dict.fromkeys(names))
    if kind == "auto":  # the cheap candidate first: it decides whether the MLP is worth training
        names.sort(key=lambda n: n != "rff")
    report["skipped"] = {}
    qcat, vcat, ccat = np.concatenate(qs), np.concatenate(vs), np.concatenate(cs)
    for name in names:
        rff = report["candidates"].get("rff")
        if (
            name == "mlp"
            and kind == "auto"
            and rff
            and rff["validation_mse"] >= report["validation_zero_mse"]
        ):
            report["skipped"]["mlp"] = (
                "not trained: the random-feature model on the same features did not beat r = 0 on validation "
                "(the residual holds nothing these features can learn)"
            )
            continue
        t0 = time.perf_counter()
        info: dict = {}
        if name == "hgb":
            m = _fit_hgb(xs, yss, seed)
            fit_s = time.perf_counter() - t0
            pred = m.predict(xvs) * ys + ym
            one = xvs[:1]
            tt = []
            for _ in range(200):
                t1 = time.perf_counter()
                m.predict(one)
                tt.append(time.perf_counter() - t1)
            info.update(
                exported=False,
                step_us=float(np.median(tt) * 1e6),
                n_params=int(sum(p.get_n_leaf_nodes() for ps in m._predictors for p in ps)),
            )
            info["iterations"] = int(m.n_iter_)
        else:
            if name == "mlp":
                layers, extra = _fit_mlp(xs, yss, seed, hidden)
            else:
                layers, extra = _fit_rff(xs, yss, seed, rff_components)
            model = _export(name, layers, s, mu, sd, ym, ys, xt, yt, fade)
            fit_s = time.perf_counter() - t0
            pred = model.predict_features(xv)
            info.update(extra)
            info.update(
                exported=True,
                step_us=_step_us(model, qcat, vcat, ccat),
                n_params=int(sum(w.size + b.size for w, b in layers)),
                multiply_adds=int(sum(w.size for w, _ in layers)),
            )
            report["models"][name] = model
        info.update(
            fit_s=float(fit_s),
            validation_mse=float(np.mean((pred - yv) ** 2)),
            validation_nmse_percent=_nmse(pred, yv),
        )
        report["candidates"][name] = info
        report["validation_prediction"][name] = pred
    report["validation_residual"] = yv
    exported = [n for n in report["models"] if n in (EXPORTED if kind == "auto" else (kind,))]
    best = min(exported, key=lambda n: report["candidates"][n]["validation_mse"])
    bm = report["candidates"][best]["validation_mse"]
    for n in sorted(exported, key=lambda n: report["candidates"][n]["multiply_adds"]):
        if report["candidates"][n]["validation_mse"] <= bm * (1.0 + TOLERANCE):
            best = n
            break
    if report["candidates"][best]["validation_mse"] >= report["validation_zero_mse"]:
        report["chosen"] = "none"
        report["reason"] = "no candidate beats r = 0 on validation"
        return None, report
    report["chosen"] = best
    return report["models"][best], report


def with_residual(
    base: ModelResult, train, val, vall, kind, seed, hm, lm, scored, warnings
) -> ModelResult | None:
    """``<base>+residual``: a learned map of what ``base`` leaves (fit_residual), or None."""
    t0 = time.perf_counter()
    dt = float(train[0].dt)
    rt = [r.torque - base.predict(r) for r in train]
    yv = np.asarray(base.extra["validation_prediction"])
    rv, i = [], 0
    for r in val:
        rv.append(r.torque - yv[i : i + r.n])
        i += r.n
    try:
        model, rep = fit_residual(
            [r.position for r in train],
            [r.velocity for r in train],
            None,
            rt,
            dt,
            kind=kind,
            seed=seed,
            validation=([r.position for r in val], [r.velocity for r in val], None, rv),
        )
    except ParameterError as exc:
        warnings.append(f"learned residual not fitted: {exc}")
        return None
    if model is None:
        warnings.append(
            f"learned residual: no candidate beat the {base.name} residual on validation; not used"
            + (
                ""
                if not rep.get("skipped")
                else " (the random-feature model found nothing to learn: mlp not trained)"
            )
        )
        return None
    extra = np.concatenate([model.predict_batch(r.position, r.velocity) for r in val])
    yhat = yv + extra
    chosen = rep.get("chosen")
    k = int(base.metrics.get("n_params", 1)) + int(rep["candidates"][chosen].get("n_params", 0))
    res = ModelResult(
        f"{base.name}+residual",
        f"{base.method} + learned residual ({chosen})",
        dict(base.coefficients),
        base.config,
        metrics.compare(yhat, vall.torque, hm, k, low_mask=lm, scored=scored),
        {},
        time.perf_counter() - t0,
        base.steady_state,
        lambda r, b=base.predict, m=model: b(r) + m.predict_batch(r.position, r.velocity),
        notes=[
            f"learned residual ({chosen}, {rep['candidates'][chosen].get('n_params', 0)} parameters, "
            f"step {rep['candidates'][chosen].get('step_us', float('nan')):.1f} us) on the {base.name} residual; "
            f"features: {', '.join(rep['features'])}"
        ],
    )
    res.extra.update(
        {
            k: v
            for k, v in base.extra.items()
            if k in ("load", "load_coefficients", "load_part", "per_direction")
        }
    )
    res.extra["residual"] = model.to_config()
    res.extra["residual_report"] = {
        c: {k: v for k, v in info.items() if isinstance(v, (int, float, str, bool))}
        for c, info in rep["candidates"].items()
    }
    res.extra["validation_prediction"] = yhat
    return res
