"""Temperature (and load) dependence of a joint's friction coefficients, and normalisation to a
reference temperature with propagated uncertainty.

Friction in a geared robot joint falls as the gearbox warms up: the lubricant's viscosity drops
roughly exponentially with temperature (Andrade/Reynolds law, mu(T) = mu_ref exp(-b (T - T_ref)))
and the viscous term follows it, while the low-speed (Coulomb, boundary-lubrication) level changes
less and about linearly over the operating range. This is what Carlson-Bittencourt and Gunnarsson
measured on an ABB IRB joint ("Static friction in a robot joint: modeling and identification of
load and temperature effects", J. Dyn. Sys., Meas., Control 134(5), 2012) and what their wear
studies build on (Bittencourt, Axelsson, Jung, Brogardh, "Modeling and experiment design for
identification of wear in a robot joint under load and temperature uncertainties based on friction
data", IEEE/ASME Trans. Mechatronics 19(5), 2014): a wear change of a few per cent is smaller than
the temperature effect and is seen only once the coefficients are normalised to one temperature.
The project's sources name the same dependence (GA friction thesis 2002, section 2: friction "varies with material
properties, temperature, wear"; its compensation chapter: "component wear, lubricant temperature and
aging"), without a law. The laws used here, per coefficient c of one joint:

    viscous (fv, sigma1, sigma2, c1):   c(T, L) = c_ref exp(-k_v (T - T_ref) + b_L (L - L_ref))
    every other level (fc, fs, ...):    c(T, L) = c_ref (1 + a_c (T - T_ref) + a_L (L - L_ref))

T the run's mean temperature [degC], L its load (RMS effort, the joint's unit). The load column
enters only when the baseline's load varies (interquartile range > :data:`LOAD_SPREAD` of its
median); otherwise ``a_L = b_L = 0``. The coefficients are fitted per joint by least squares on its
baseline runs (log c for the exponential law), one pass dropping residuals beyond 4 robust standard
deviations; a baseline whose temperatures span less than :data:`MIN_SPAN_K` gives no temperature
term (k_v = a_c = 0).

Normalisation: c_n = c / g(T, L) with g = c(T, L) / c_ref, and by first-order propagation

    var(c_n) = (se_c / g)^2 + grad_beta(c_n) Cov(beta) grad_beta(c_n)^T

(beta the law's fitted coefficients), so a run far from T_ref or a law fitted on few runs carries a
larger uncertainty.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

#: coefficients that scale with lubricant viscosity (exponential law); all others: linear law
VISCOUS = ("fv", "sigma1", "sigma2", "c1")
#: baseline temperature span [K] below which no temperature term is fitted
MIN_SPAN_K = 3.0
#: relative spread (IQR / median) of the baseline's load above which the load enters the law
LOAD_SPREAD = 0.10
#: residuals beyond this many robust standard deviations are dropped once (bad fits)
OUTLIER_SIGMAS = 4.0


def robust_sigma(x) -> float:
    """1.4826 x median absolute deviation of the finite values of ``x`` (sigma of a normal)."""
    x = np.asarray(x, float)
    x = x[np.isfinite(x)]
    if x.size == 0:
        return math.nan
    return float(1.4826 * np.median(np.abs(x - np.median(x))))


@dataclass(frozen=True)
class TemperatureLaw:
    """One coefficient's law (module docstring): ``form`` ``"exponential"`` or ``"linear"``,
    ``beta`` = (b0, b_T, b_L) and its covariance; ``t_ref`` [degC], ``l_ref`` [effort unit]."""

    name: str
    form: str
    t_ref: float
    l_ref: float
    beta: tuple[float, float, float]
    cov: tuple[tuple[float, ...], ...]
    runs: int

    @property
    def c_ref(self) -> float:
        """The coefficient at T_ref, L_ref."""
        return math.exp(self.beta[0]) if self.form == "exponential" else self.beta[0]

    @property
    def slope_per_k(self) -> float:
        """Relative change per kelvin at T_ref: -k_v (exponential) or a_c (linear) [1/K]."""
        return self.beta[1] if self.form == "exponential" else self.beta[1] / self.beta[0]

    def _design(self, temperature, load) -> np.ndarray:
        t = np.asarray(temperature, float) - self.t_ref
        ld = np.asarray(load, float) - self.l_ref if self.beta[2] != 0.0 else np.zeros_like(t)
        t = np.where(np.isfinite(t) | (self.beta[1] == 0.0), np.nan_to_num(t), np.nan)
        return np.column_stack([np.ones_like(t), t, np.nan_to_num(ld)])

    def factor(self, temperature, load=None) -> np.ndarray:
        """g(T, L) = c(T, L) / c_ref (NaN where T is missing and the law has a temperature term)."""
        x = self._design(temperature, np.zeros(np.size(temperature)) if load is None else load)
        b = np.asarray(self.beta)
        if self.form == "exponential":
            return np.exp(x[:, 1:] @ b[1:])
        return (x @ b) / b[0]

    def normalise(self, values, stderr, temperature, load=None) -> tuple[np.ndarray, np.ndarray]:
        """(c_n, se_n): ``values`` at their runs' T, L brought to T_ref, L_ref (module docstring)."""
        c = np.asarray(values, float)
        se = np.asarray(stderr, float)
        x = self._design(temperature, np.zeros(c.size) if load is None else load)
        b = np.asarray(self.beta)
        cov = np.asarray(self.cov)
        if self.form == "exponential":
            g = np.exp(x[:, 1:] @ b[1:])
            cn = c / g
            grad = -cn[:, None] * x
            grad[:, 0] = 0.0
        else:
            p = x @ b
            g = p / b[0]
            cn = c / g
            # c_n = c b0 / (x.b): d/db = c (e0 (x.b) - b0 x) / (x.b)^2
            grad = c[:, None] * (np.eye(3)[0][None, :] * p[:, None] - b[0] * x) / (p**2)[:, None]
        var = (np.nan_to_num(se, nan=0.0) / g) ** 2 + np.einsum("ij,jk,ik->i", grad, cov, grad)
        return cn, np.sqrt(var)


def fit_law(name, values, temperature, load=None, t_ref: float = 25.0) -> TemperatureLaw:
    """Fit the law of coefficient ``name`` on baseline runs (module docstring). ``values`` must be
    positive for a viscous coefficient (non-positive runs are left out); NaN entries are left out."""
    form = "exponential" if name in VISCOUS else "linear"
    c = np.asarray(values, float)
    t = np.asarray(temperature, float)
    ld = np.full(c.size, np.nan) if load is None else np.asarray(load, float)
    ok = np.isfinite(c) & (c > 0 if form == "exponential" else True)
    use_t = bool(np.sum(ok & np.isfinite(t)) >= 4 and np.ptp(t[ok & np.isfinite(t)]) >= MIN_SPAN_K)
    if use_t:
        ok &= np.isfinite(t)
    finite_load = ld[ok & np.isfinite(ld)]
    l_ref = float(np.median(finite_load)) if finite_load.size else 0.0
    spread = np.subtract(*np.percentile(finite_load, [75, 25])) if finite_load.size >= 6 else 0.0
    use_l = bool(l_ref > 0 and spread > LOAD_SPREAD * abs(l_ref))
    if use_l:
        ok &= np.isfinite(ld)
    cols = [np.ones(int(ok.sum()))]
    cols.append(t[ok] - t_ref if use_t else np.zeros(int(ok.sum())))
    cols.append(ld[ok] - l_ref if use_l else np.zeros(int(ok.sum())))
    x = np.column_stack(cols)
    y = np.log(c[ok]) if form == "exponential" else c[ok]
    active = [0] + ([1] if use_t else []) + ([2] if use_l else [])
    beta, cov = _robust_lstsq(x[:, active], y)
    full_b = np.zeros(3)
    full_cov = np.zeros((3, 3))
    full_b[active] = beta
    full_cov[np.ix_(active, active)] = cov
    return TemperatureLaw(
        name=name,
        form=form,
        t_ref=float(t_ref),
        l_ref=l_ref,
        beta=tuple(float(v) for v in full_b),
        cov=tuple(tuple(float(v) for v in row) for row in full_cov),
        runs=int(ok.sum()),
    )


def _robust_lstsq(x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Least squares of y on x, refitted once without residuals beyond :data:`OUTLIER_SIGMAS`
    robust sigmas; returns (beta, s^2 (X^T X)^-1)."""
    if y.size == 0:
        return np.full(x.shape[1], np.nan), np.full((x.shape[1], x.shape[1]), np.nan)
    keep = np.ones(y.size, bool)
    for _ in range(2):
        beta, *_ = np.linalg.lstsq(x[keep], y[keep], rcond=None)
        r = y - x @ beta
        s = robust_sigma(r[keep])
        if not s > 0:
            break
        new = np.abs(r) <= OUTLIER_SIGMAS * s
        if new.sum() <= x.shape[1] or np.array_equal(new, keep):
            break
        keep = new
    dof = max(int(keep.sum()) - x.shape[1], 1)
    r = (y - x @ beta)[keep]
    s2 = float(r @ r) / dof
    cov = s2 * np.linalg.pinv(x[keep].T @ x[keep])
    return beta, cov
