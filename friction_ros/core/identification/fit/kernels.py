"""Compiled (numba) simulation kernels for output-error fitting, vectorised over a population.

Each dynamic friction model is simulated in a *normalised* form in which the coefficients that
enter linearly are factored out (variable projection, Golub & Pereyra 1973). The kernels return,
per candidate, the Gram matrix ``X^T X`` of the regressor columns ``[phi_1 .. phi_m, v, a, (load
terms), tau]``
so the linear coefficients (static level, element weights, micro-damping, viscous coefficient,
inertia J) are solved exactly by (non-negative) least squares outside the kernel. This keeps the
global search low-dimensional and removes the scale ambiguities between them.

Normalised model forms (derivations from the standard equations, see models.py). The coefficient
names are the friction library's (``fc, fs, vs, delta, fv, sigma, sigma0, sigma1, attraction, k,
alpha``, see docs/coefficients.md); ``F_C = fc``, ``F_S = fs``, ``C = attraction``:

* Stribeck shape (AI friction chapter eq. 5, ABB M19-S paper A.2.2): ``s~(v) = r + (1 - r) exp(-|v/vs|^delta)``,
  ``r = fc / fs``, so ``s(v) = fs s~(v)``.
* Dahl (AI friction chapter eq. 9, alpha = 1): ``G = F/fc``, ``dG/dx = sigma_n (1 - G sgn v)``,
  ``sigma_n = sigma / fc``; exact update for piecewise-constant v:
  ``G+ = sgn v + (G - sgn v) exp(-sigma_n |v| dt)``.
* LuGre (AI friction chapter eqs. 10-11): ``w = sigma0 z / fs``, ``dw/dt = sigma0_n v - sigma0_n |v| w / s~(v)``
  with ``sigma0_n = sigma0 / fs``; exact exponential update with rate ``a = sigma0_n |v| / s~``;
  ``dz/dt = (v - |v| w / s~)``; ``F = fs w + sigma1 dz/dt + fv v``.
* GMS-N (ABB M19-S paper A.2.4, sign-corrected eq. 3): element ``i`` force ``F_i = fs alpha_i G_i``;
  stick ``dG_i/dt = v / x_i`` (``x_i = alpha_i fs / k_i`` is the element's breakaway
  displacement), slip ``dG_i/dt = attraction_n (sgn v - G_i / s~(v))`` with
  ``attraction_n = attraction / fs`` (exact exponential update), stick -> slip when
  ``|G_i| >= s~`` in the direction of motion, slip -> stick on a velocity reversal or v = 0.
  ``F = sum_i beta_i G_i + fv v`` with ``beta_i = fs alpha_i``. Optional presliding damping
  (library GMS ``sigma1``, stiffness-proportional): ``F = sum_i beta_i (G_i + s dG_i/dt) + fv v``
  with one more nonlinear coefficient, the time constant ``s = sigma1 / sum_j k_j``.

The Gram kernels use ``prange`` over the population (both cores) when it is large enough, a
serial compilation of the same code otherwise (:func:`_two_versions`); all use ``cache=True``.
"""

from __future__ import annotations

import math
import os
import types

# Threads waiting for the next parallel batch sleep instead of spinning: the cores are shared (other
# fits, other users), and a spinning OpenMP worker takes CPU from the thread that does the work
# (GNU OpenMP reads this when numba first loads it; a value set by the user is kept).
os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")

import numba  # noqa: E402
import numpy as np  # noqa: E402
from numba import njit, prange  # noqa: E402


@njit(cache=True, inline="always")
def _sgn(x):
    if x > 0.0:
        return 1.0
    if x < 0.0:
        return -1.0
    return 0.0


@njit(cache=True, inline="always")
def _shape(v, r, vs, delta):
    """Normalised Stribeck curve s~(v) = r + (1-r) exp(-|v/vs|^delta), in (r, 1]."""
    av = abs(v) / vs
    if av == 0.0:
        return 1.0
    return r + (1.0 - r) * math.exp(-math.pow(av, delta))


@njit(cache=True, inline="always")
def _accumulate(gram, feats, nphi, m):
    """Upper triangle of the rows 0..nphi-1 (the parameter-dependent regressors) of the Gram."""
    for i in range(nphi):
        fi = feats[i]
        for j in range(i, m):
            gram[i, j] += fi * feats[j]


@njit(cache=True, inline="always")
def _filter_feats(feats, nf, sos, zf):
    """Filter the first ``nf`` entries of ``feats`` in place through the second-order sections
    ``sos`` (scipy layout b0 b1 b2 a0 a1 a2, a0 = 1; transposed direct form II, states ``zf``
    of shape (nf, n_sections, 2)). No sections: no filtering."""
    ns = sos.shape[0]
    for i in range(nf):
        x = feats[i]
        for s in range(ns):
            y = sos[s, 0] * x + zf[i, s, 0]
            zf[i, s, 0] = sos[s, 1] * x - sos[s, 4] * y + zf[i, s, 1]
            zf[i, s, 1] = sos[s, 2] * x - sos[s, 5] * y
            x = y
        feats[i] = x


@njit(cache=True)
def _finish(grams, E, nphi):
    """Fill every Gram's block of the parameter-free columns ``E^T E`` (one product for the whole
    population) and mirror the upper triangle."""
    ete = E.T @ E
    m = grams.shape[1]
    for p in range(grams.shape[0]):
        for i in range(nphi, m):
            for j in range(i, m):
                grams[p, i, j] = ete[i - nphi, j - nphi]
        for i in range(m):
            for j in range(i):
                grams[p, i, j] = grams[p, j, i]
    return grams


def _two_versions(f):
    """(serial, parallel) compilations of one population kernel (``prange`` is ``range`` in the
    serial one). A parallel launch costs more than a one-candidate simulation of a few thousand
    samples (Nelder-Mead's calls), and a process that shares the cores with other fits runs
    one thread: both take the serial version (:func:`_pick`). Each version has its own cache entry."""
    ser = types.FunctionType(f.__code__, f.__globals__, f.__name__ + "_serial", f.__defaults__, f.__closure__)
    ser.__qualname__ = f.__qualname__ + "_serial"
    return njit(cache=True)(ser), njit(cache=True, parallel=True)(f)


def _pick(versions, npop: int):
    """The parallel version for a population of at least two candidates per thread, else the serial."""
    return versions[1] if npop >= 2 * numba.get_num_threads() > 2 else versions[0]


# ---------------------------------------------------------------------------------- Dahl
@njit(cache=True)
def dahl_features(theta, v, dt):
    """Regressor columns [G] of the normalised Dahl model for one parameter row [sigma_n]."""
    n = v.shape[0]
    out = np.empty((n, 1))
    st = theta[0]
    g = 0.0
    for k in range(n):
        vk = v[k]
        if vk != 0.0:
            s = _sgn(vk)
            g = s + (g - s) * math.exp(-st * abs(vk) * dt)
        out[k, 0] = g
    return out


def _dahl_gram(P, vm, E, dt, sos):
    npop = P.shape[0]
    n = E.shape[0]
    q = E.shape[1]
    m = 1 + q
    grams = np.zeros((npop, m, m))
    for p in prange(npop):
        st = P[p, 0]
        g = 0.0
        feats = np.empty(m)
        gram = np.zeros((m, m))
        zf = np.zeros((1, sos.shape[0], 2))
        for k in range(n):
            vk = vm[k]
            if vk != 0.0:
                s = _sgn(vk)
                g = s + (g - s) * math.exp(-st * abs(vk) * dt)
            feats[0] = g
            _filter_feats(feats, 1, sos, zf)
            for j in range(q):
                feats[1 + j] = E[k, j]
            _accumulate(gram, feats, 1, m)
        grams[p] = gram
    return _finish(grams, E, 1)


_DAHL = _two_versions(_dahl_gram)


def dahl_gram(P, vm, E, dt, sos):
    """Gram of [L phi(vm), E]; the states are driven by the interval-mean velocity vm.

    ``E`` (n x q): the columns that do not depend on the parameters, target last: ``[v, a, (load
    and position terms), tau]``. ``L`` = the causal filter ``sos`` (see :func:`_filter_feats`); pass
    ``E`` already filtered with the same sections so every column sees the same filter. Only the
    rows of ``phi`` are accumulated per candidate; ``E^T E`` is one product (:func:`_finish`)."""
    return _pick(_DAHL, P.shape[0])(P, vm, E, dt, sos)


# ---------------------------------------------------------------------------------- LuGre
@njit(cache=True, inline="always")
def _lugre_step(w, vk, r, vs, delta, s0, dt):
    if vk == 0.0:
        return w, 0.0
    g = _shape(vk, r, vs, delta)
    rate = s0 * abs(vk) / g
    wss = _sgn(vk) * g
    w = wss + (w - wss) * math.exp(-rate * dt)
    zdot = vk - abs(vk) * w / g
    return w, zdot


@njit(cache=True)
def lugre_features(theta, v, dt):
    """Regressor columns [w, dz/dt] of the normalised LuGre model; theta = [r, vs, delta, sigma0_n]."""
    n = v.shape[0]
    out = np.empty((n, 2))
    r, vs, delta, s0 = theta[0], theta[1], theta[2], theta[3]
    w = 0.0
    for k in range(n):
        w, zd = _lugre_step(w, v[k], r, vs, delta, s0, dt)
        out[k, 0] = w
        out[k, 1] = zd
    return out


def _lugre_gram(P, vm, E, dt, sos):
    npop = P.shape[0]
    n = E.shape[0]
    q = E.shape[1]
    m = 2 + q
    grams = np.zeros((npop, m, m))
    for p in prange(npop):
        r, vs, delta, s0 = P[p, 0], P[p, 1], P[p, 2], P[p, 3]
        w = 0.0
        feats = np.empty(m)
        gram = np.zeros((m, m))
        zf = np.zeros((2, sos.shape[0], 2))
        for k in range(n):
            w, zd = _lugre_step(w, vm[k], r, vs, delta, s0, dt)
            feats[0] = w
            feats[1] = zd
            _filter_feats(feats, 2, sos, zf)
            for j in range(q):
                feats[2 + j] = E[k, j]
            _accumulate(gram, feats, 2, m)
        grams[p] = gram
    return _finish(grams, E, 2)


_LUGRE = _two_versions(_lugre_gram)


def lugre_gram(P, vm, E, dt, sos):
    """Gram of [L phi(vm), E] (see :func:`dahl_gram`)."""
    return _pick(_LUGRE, P.shape[0])(P, vm, E, dt, sos)


# ---------------------------------------------------------------------------------- GMS
@njit(cache=True, inline="always")
def _gms_step(G, stuck, vk, s, attraction_n, xs, dt):
    ne = G.shape[0]
    sv = _sgn(vk)
    decay = math.exp(-attraction_n * dt / s)
    for i in range(ne):
        if stuck[i]:
            G[i] += vk * dt / xs[i]
            if sv != 0.0 and G[i] * sv >= s:
                stuck[i] = False
                G[i] = sv * s
        else:
            if sv == 0.0 or sv != _sgn(G[i]):
                stuck[i] = True
                G[i] += vk * dt / xs[i]
            else:
                gss = sv * s
                G[i] = gss + (G[i] - gss) * decay


@njit(cache=True)
def gms_features(theta, v, dt, damped=False):
    """Regressor columns of normalised GMS-N; theta = [r, vs, delta, attraction_n, x_1..x_N] (+ [s] if
    ``damped``): G_i, or G_i + s dG_i/dt with presliding damping (see :func:`gms_gram`)."""
    n = v.shape[0]
    ne = theta.shape[0] - 4 - (1 if damped else 0)
    out = np.empty((n, ne))
    r, vs, delta, attraction_n = theta[0], theta[1], theta[2], theta[3]
    xs = theta[4 : 4 + ne].copy()
    sd = theta[4 + ne] / dt if damped else 0.0
    G = np.zeros(ne)
    Gp = np.zeros(ne)
    stuck = np.ones(ne, dtype=np.bool_)
    for k in range(n):
        vk = v[k]
        s = _shape(vk, r, vs, delta)
        _gms_step(G, stuck, vk, s, attraction_n, xs, dt)
        for i in range(ne):
            if damped:
                out[k, i] = G[i] + sd * (G[i] - Gp[i])
                Gp[i] = G[i]
            else:
                out[k, i] = G[i]
    return out


def _gms_gram(P, vm, E, dt, sos, damped=False):
    npop = P.shape[0]
    n = E.shape[0]
    q = E.shape[1]
    ne = P.shape[1] - 4 - (1 if damped else 0)
    m = ne + q
    grams = np.zeros((npop, m, m))
    for p in prange(npop):
        r, vs, delta, attraction_n = P[p, 0], P[p, 1], P[p, 2], P[p, 3]
        xs = P[p, 4 : 4 + ne].copy()
        sd = P[p, 4 + ne] / dt if damped else 0.0
        G = np.zeros(ne)
        Gp = np.zeros(ne)
        stuck = np.ones(ne, dtype=np.bool_)
        feats = np.empty(m)
        gram = np.zeros((m, m))
        zf = np.zeros((ne, sos.shape[0], 2))
        for k in range(n):
            vk = vm[k]
            s = _shape(vk, r, vs, delta)
            _gms_step(G, stuck, vk, s, attraction_n, xs, dt)
            for i in range(ne):
                if damped:
                    feats[i] = G[i] + sd * (G[i] - Gp[i])
                    Gp[i] = G[i]
                else:
                    feats[i] = G[i]
            _filter_feats(feats, ne, sos, zf)
            for j in range(q):
                feats[ne + j] = E[k, j]
            _accumulate(gram, feats, ne, m)
        grams[p] = gram
    return _finish(grams, E, ne)


_GMS = _two_versions(_gms_gram)


def gms_gram(P, vm, E, dt, sos, damped=False):
    """Gram of [L phi(vm), E] (see :func:`dahl_gram`).

    ``damped``: the last column of P is the presliding damping time constant
    ``s = sigma1 / sum_j k_j`` [s] and each regressor is ``G_i + s dG_i/dt``, with dG_i/dt the
    backward difference over the sample as in the library GMS (F_damp = (sigma1 / sum_j k_j)
    sum_i dF_i/dt, dF_i/dt = (F_i(t) - F_i(t - h)) / h): since F_i = beta_i G_i and k_i = beta_i /
    x_i, the damping force is ``sum_i beta_i s dG_i/dt`` and the element weights stay linear."""
    return _pick(_GMS, P.shape[0])(P, vm, E, dt, sos, damped)
