"""AI friction chapter's learned friction maps: ANFIS and nu-SVR, one model per direction (B.4).

**ANFIS** (first-order Takagi-Sugeno, Jang 1993; AI friction chapter B.4.1), one input x = v, two Gaussian
membership functions, two rules:

    mu_j(x) = exp(-(x - c_j)^2 / (2 s_j^2)),  wbar_j = mu_j / (mu_1 + mu_2),
    F(x) = wbar_1 (p_1 x + r_1) + wbar_2 (p_2 x + r_2)

Initialised with epsilon-completeness 0.5 (centres at the data range ends,
s = range / (2 sqrt(2 ln 2)), AI friction chapter E.1.12); **hybrid training**: each epoch solves the
consequents (p_j, r_j) by linear least squares with the premises fixed, then takes a gradient step
on the premises (c_j, s_j) with the consequents fixed (step size adapted: x1.1 after a decrease,
x0.5 after an increase); error target 1e-4 (RMS, normalised by the output RMS), 100 epochs.

**nu-SVR** (Schoelkopf & Smola; AI friction chapter B.4.2): scikit-learn ``NuSVR`` with a Gaussian (RBF)
kernel on the standardised velocity; nu, C and the kernel width are chosen by validation over a
small grid, per direction, as the paper describes ("cross-validated with testing data for both
directions").

Both are static maps (no presliding): they predict the steady friction for |v| > 0 per direction.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np

from friction_ros.core.validation import ParameterError


# ------------------------------------------------------------------------------------ ANFIS
@dataclass
class Anfis:
    c: np.ndarray
    s: np.ndarray
    p: np.ndarray
    r: np.ndarray
    epochs: int = 0
    history: list[float] = field(default_factory=list)

    @staticmethod
    def _wbar(x, c, s):
        mu = np.exp(-((x[:, None] - c[None, :]) ** 2) / (2.0 * s[None, :] ** 2))
        den = mu.sum(axis=1, keepdims=True) + 1e-300
        return mu / den, mu

    def predict(self, x) -> np.ndarray:
        x = np.asarray(x, dtype=float)
        wb, _ = self._wbar(x, self.c, self.s)
        return np.sum(wb * (self.p[None, :] * x[:, None] + self.r[None, :]), axis=1)

    def params(self) -> dict:
        return {"c": self.c.tolist(), "s": self.s.tolist(), "p": self.p.tolist(), "r": self.r.tolist()}


def _anfis_lse(x, y, c, s):
    wb, _ = Anfis._wbar(x, c, s)
    A = np.column_stack([wb[:, 0] * x, wb[:, 0], wb[:, 1] * x, wb[:, 1]])
    sol, *_ = np.linalg.lstsq(A, y, rcond=None)
    return np.array([sol[0], sol[2]]), np.array([sol[1], sol[3]])


def fit_anfis(x, y, *, epochs: int = 100, error_target: float = 1e-4, step: float = 0.05) -> Anfis:
    """Hybrid-trained 2-MF ANFIS (see module docstring)."""
    x = np.asarray(x, dtype=float)
    y = np.asarray(y, dtype=float)
    if x.size < 4:
        raise ParameterError(f"anfis: {x.size} training points, need at least 4")
    lo, hi = float(x.min()), float(x.max())
    rng_ = max(hi - lo, 1e-9)
    c = np.array([lo, hi])
    s = np.full(2, rng_ / (2.0 * math.sqrt(2.0 * math.log(2.0))))
    yscale = float(np.sqrt(np.mean(y**2))) + 1e-12
    hist = []
    prev = np.inf
    lr = step * rng_
    ep = 0
    for _ in range(epochs):
        ep += 1
        p, r = _anfis_lse(x, y, c, s)
        model = Anfis(c, s, p, r)
        e = model.predict(x) - y
        err = float(np.sqrt(np.mean(e**2))) / yscale
        hist.append(err)
        if err <= error_target:
            break
        lr = lr * 1.1 if err < prev else lr * 0.5
        prev = err
        # gradient of 0.5 mean(e^2) w.r.t. premises (analytic)
        wb, mu = Anfis._wbar(x, c, s)
        f = p[None, :] * x[:, None] + r[None, :]
        yhat = np.sum(wb * f, axis=1)
        den = mu.sum(axis=1) + 1e-300
        gc = np.zeros(2)
        gs = np.zeros(2)
        for j in range(2):
            dmu_dc = mu[:, j] * (x - c[j]) / s[j] ** 2
            dmu_ds = mu[:, j] * (x - c[j]) ** 2 / s[j] ** 3
            dy_dmu = (f[:, j] - yhat) / den
            gc[j] = np.mean(e * dy_dmu * dmu_dc)
            gs[j] = np.mean(e * dy_dmu * dmu_ds)
        g = np.concatenate([gc, gs])
        gn = float(np.linalg.norm(g)) + 1e-300
        c = c - lr * gc / gn
        s = np.maximum(s - lr * gs / gn, 1e-3 * rng_)
    p, r = _anfis_lse(x, y, c, s)
    return Anfis(c, s, p, r, ep, hist)


# ------------------------------------------------------------------------------------ nu-SVR
@dataclass
class SvrMap:
    model: object
    x_mean: float
    x_std: float
    y_mean: float
    y_std: float
    nu: float
    C: float
    gamma: float
    n_support: int

    def predict(self, x) -> np.ndarray:
        x = (np.asarray(x, dtype=float) - self.x_mean) / self.x_std
        return self.model.predict(x[:, None]) * self.y_std + self.y_mean

    def params(self) -> dict:
        return {"nu": self.nu, "C": self.C, "gamma": self.gamma, "n_support": self.n_support}


def fit_nusvr(x, y, *, max_points: int = 1500, seed: int = 4) -> SvrMap:
    """nu-SVR with an RBF kernel; (nu, C, gamma) by hold-out validation on a 3x3x3 grid."""
    from sklearn.svm import NuSVR

    x = np.asarray(x, dtype=float)
    y = np.asarray(y, dtype=float)
    if x.size < 4:
        raise ParameterError(f"nusvr: {x.size} training points, need at least 4")
    rng = np.random.default_rng(seed)
    if x.size > max_points:
        idx = rng.choice(x.size, max_points, replace=False)
        x, y = x[idx], y[idx]
    xm, xs = float(x.mean()), float(x.std()) + 1e-12
    ym, ys = float(y.mean()), float(y.std()) + 1e-12
    X = ((x - xm) / xs)[:, None]
    Y = (y - ym) / ys
    perm = rng.permutation(x.size)
    n_val = max(int(0.4 * x.size), 1) if x.size >= 10 else 0  # AI friction chapter: 60/40 split
    tr, va = (perm[n_val:], perm[:n_val]) if n_val else (perm, perm)
    best = None
    for nu in (0.2, 0.5, 0.8):
        for C in (1.0, 10.0, 100.0):
            for gamma in (0.3, 1.0, 3.0):
                m = NuSVR(nu=nu, C=C, gamma=gamma, kernel="rbf").fit(X[tr], Y[tr])
                err = float(np.mean((m.predict(X[va]) - Y[va]) ** 2))
                if best is None or err < best[0]:
                    best = (err, nu, C, gamma)
    _, nu, C, gamma = best
    m = NuSVR(nu=nu, C=C, gamma=gamma, kernel="rbf").fit(X, Y)
    return SvrMap(m, xm, xs, ym, ys, nu, C, gamma, int(len(m.support_)))


# ------------------------------------------------------------------------------------ per direction
@dataclass
class DirectionalMap:
    """One learned map per direction; F(0) = 0."""

    kind: str
    positive: object
    negative: object
    seconds: float = 0.0

    def steady_state(self, v) -> np.ndarray:
        v = np.asarray(v, dtype=float)
        out = np.zeros_like(v)
        pos, neg = v > 0, v < 0
        if pos.any():
            out[pos] = self.positive.predict(v[pos])
        if neg.any():
            out[neg] = self.negative.predict(v[neg])
        return out

    def params(self) -> dict:
        return {"positive": self.positive.params(), "negative": self.negative.params()}


def fit_directional(kind: str, v, f) -> DirectionalMap:
    """Fit ``kind`` ('anfis' or 'nusvr') separately to v > 0 and v < 0 samples of (v, F)."""
    t0 = time.perf_counter()
    v = np.asarray(v, dtype=float)
    f = np.asarray(f, dtype=float)
    fit = fit_anfis if kind == "anfis" else fit_nusvr
    pos, neg = v > 0, v < 0
    if pos.sum() < 4 or neg.sum() < 4:
        raise ParameterError(
            f"{kind}: needs friction samples in both directions (found {pos.sum()}+/{neg.sum()}-): run the "
            "'plateaus' experiment in both directions"
        )
    return DirectionalMap(kind, fit(v[pos], f[pos]), fit(v[neg], f[neg]), time.perf_counter() - t0)
