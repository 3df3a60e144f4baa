"""Scalar friction kernels shared by the models, the batch simulator and the plant.

Every kernel is plain Python on floats and float64 arrays so that it runs unchanged either compiled by
numba (``@njit(cache=True)``, the default when numba is importable) or interpreted (set the environment
variable ``FRICTION_ROS_NO_NUMBA=1``; slow but bit-for-bit the same algorithm). The model classes also
carry independent vectorised numpy implementations; the tests check both paths agree.

Parameter vectors (``p``) are laid out per model kind; ``o`` is the offset of the model's first
parameter inside ``p`` (used by the asymmetric wrapper, which stores a positive and a negative set).
All velocities in rad/s (or m/s), torques in N*m (or N).
"""

from __future__ import annotations

import math
import os

_DISABLE = os.environ.get("FRICTION_ROS_NO_NUMBA", "").lower() in ("1", "true", "yes")

try:  # pragma: no cover - exercised implicitly
    if _DISABLE:
        raise ImportError
    import numba

    HAVE_NUMBA = True

    def jit(fn):
        return numba.njit(cache=True, nogil=True)(fn)

except ImportError:  # pragma: no cover
    HAVE_NUMBA = False

    def jit(fn):
        return fn


# ---- model kinds (stable integers, used only inside the core) -------------------------------------
K_NONE = 0
K_COULOMB = 1
K_VISCOUS = 2
K_COULOMB_VISCOUS = 3
K_STRIBECK = 4  # also tustin (delta=1) and gaussian (delta=2)
K_LORENTZIAN = 5
K_STRIBECK_EPS = 6
K_GA_EXPONENTIAL = 7
K_GA_TUSTIN = 8
K_GA_NONLINEAR = 9
K_GA_DUPONT = 10
K_GA_SEVEN = 11
K_POLYNOMIAL = 12
K_LOAD_DEPENDENT = 13
K_KARNOPP = 14
K_GKF = 15
K_TABLE = 16  # a static map given as a table (models without a kernel of their own)
K_ASYMMETRIC = 20
K_DAHL = 30
K_LUGRE = 31
K_GMS = 32


@jit
def sgn(v):
    """sgn(v) with sgn(0) = 0 (AI friction chapter eq. (6))."""
    if v > 0.0:
        return 1.0
    if v < 0.0:
        return -1.0
    return 0.0


@jit
def stribeck_s(av, fc, fs, vs, delta):
    """Stribeck magnitude s(|v|) = Fc + (Fs - Fc) exp(-(|v|/vs)^delta) (AI friction chapter eq. (5))."""
    return fc + (fs - fc) * math.exp(-((av / vs) ** delta))


@jit
def static_torque(kind, p, o, v, load):
    """Friction torque of a static (memoryless) model at velocity ``v``; ``load`` = transmitted torque."""
    if kind == K_NONE:
        return 0.0
    av = abs(v)
    s = sgn(v)
    if kind == K_COULOMB:
        return p[o] * s
    if kind == K_VISCOUS:
        return p[o] * v
    if kind == K_COULOMB_VISCOUS:
        return p[o] * s + p[o + 1] * v
    if kind == K_STRIBECK or kind == K_KARNOPP or kind == K_GKF:
        return stribeck_s(av, p[o], p[o + 1], p[o + 2], p[o + 3]) * s + p[o + 4] * v
    if kind == K_LORENTZIAN:
        r = v / p[o + 2]
        return (p[o] + (p[o + 1] - p[o]) / (1.0 + r * r)) * s + p[o + 3] * v
    if kind == K_STRIBECK_EPS:
        eps = p[o + 5]
        g = stribeck_s(av, p[o], p[o + 1], p[o + 2], p[o + 3])
        if av > eps:
            return g * s + p[o + 4] * v
        return (v / eps) * g + p[o + 4] * v
    if kind == K_GA_EXPONENTIAL:
        # p = fs, gamma, delta, fc, sigma
        return (p[o + 3] + (p[o] - p[o + 3]) * math.exp(-((p[o + 1] * av) ** p[o + 2])) + p[o + 4] * av) * s
    if kind == K_GA_TUSTIN:
        # p = ff0, ffc, vc, x, sigma
        return (p[o] - p[o + 1] * (1.0 - math.exp(-((av / p[o + 2]) ** p[o + 3]))) + p[o + 4] * av) * s
    if kind == K_GA_NONLINEAR:
        # p = alpha0, alpha1, alpha2, beta1, beta2
        return (p[o] + p[o + 1] * math.exp(-p[o + 3] * av) + p[o + 2] * (1.0 - math.exp(-p[o + 4] * av))) * s
    if kind == K_GA_DUPONT:
        # p = c0, c1, c2, c3, c4
        return (p[o] + p[o + 1] * av + p[o + 2] * math.exp(-((av / p[o + 3]) ** p[o + 4]))) * s
    if kind == K_GA_SEVEN:
        # p = fc, fv, fs, vs
        r = v / p[o + 3]
        return (p[o] + p[o + 1] * av + p[o + 2] / (1.0 + r * r)) * s
    if kind == K_POLYNOMIAL:
        n = int(p[o])
        base = o + 1 if v >= 0.0 else o + 1 + n
        acc = 0.0
        for j in range(n - 1, -1, -1):
            acc = acc * av + p[base + j]
        return acc * s
    if kind == K_TABLE:
        return table_torque(p, o, v)
    if kind == K_LOAD_DEPENDENT:
        # p = fc, fl, fv, veps
        veps = p[o + 3]
        mag = p[o] + p[o + 1] * abs(load)
        if veps > 0.0:
            return v / (veps + av) * mag + p[o + 2] * v
        return mag * s + p[o + 2] * v
    return math.nan


@jit
def table_torque(p, o, v):
    """A static map tabulated at speeds 0 < w_1 < ... < w_n (see ``StaticModel.table_speeds``):
    p = n, w_1..w_n, F(+w_1)..F(+w_n), F(-w_1)..F(-w_n), F(0+), F(0-). Linear in |v| between
    the nodes (from F(0+-) at 0), extended with the last segment's slope; F(0) = 0."""
    if v == 0.0:
        return 0.0
    n = int(p[o])
    av = abs(v)
    w = o + 1
    f = o + 1 + n if v > 0.0 else o + 1 + 2 * n
    if av <= p[w]:
        f0 = p[o + 1 + 3 * n] if v > 0.0 else p[o + 2 + 3 * n]
        return f0 + (p[f] - f0) * av / p[w]
    lo, hi = 0, n - 1
    if av >= p[w + hi]:
        lo = n - 2
    else:
        while hi - lo > 1:  # bisection: p[w + lo] < av <= p[w + hi]
            mid = (lo + hi) // 2
            if p[w + mid] < av:
                lo = mid
            else:
                hi = mid
    hi = lo + 1
    u = (av - p[w + lo]) / (p[w + hi] - p[w + lo])
    return p[f + lo] + (p[f + hi] - p[f + lo]) * u


@jit
def lugre_update(p, o, z, v, h):
    """Exact LuGre bristle update for velocity held constant over ``h``; returns (z_new, torque).

    dz/dt = v - sigma0 |v| z / g(v) is linear in z for constant v, so
    z(h) = z_ss + (z - z_ss) exp(-a h), a = sigma0 |v| / g(v), z_ss = g(v) sgn(v) / sigma0
    (unconditionally stable for any sigma0 and h). Torque F = sigma0 z + sigma1(v) dz/dt + fv v at the
    end of the step (AI friction chapter eqs. (10)-(11), Canudas de Wit 1995).
    p = sigma0, sigma1, fv, fc, fs, vs, delta, vd
    """
    sigma0 = p[o]
    av = abs(v)
    g = stribeck_s(av, p[o + 3], p[o + 4], p[o + 5], p[o + 6])
    a = sigma0 * av / g
    ah = a * h
    if ah < 1e-9:
        zn = z + (v - a * z) * h
    else:
        zss = v / a
        zn = zss + (z - zss) * math.exp(-ah)
    zdot = v - a * zn
    s1 = p[o + 1]
    vd = p[o + 7]
    if vd > 0.0:
        s1 = s1 * math.exp(-((v / vd) ** 2))
    return zn, sigma0 * zn + s1 * zdot + p[o + 2] * v


@jit
def dahl_update(p, o, f, v, h):
    """Exact Dahl update over the displacement dx = v h; returns the new friction torque.

    dF/dx = sigma |1 - F sgn(v)/Fc|^alpha sgn(1 - F sgn(v)/Fc) (AI friction chapter eq. (9)); with
    y = 1 - F sgn(v)/Fc this is dy/d|x| = -(sigma/Fc) |y|^alpha sgn(y), solved in closed form.
    p = sigma, fc, alpha
    """
    if v == 0.0:
        return f
    sigma = p[o]
    fc = p[o + 1]
    alpha = p[o + 2]
    sv = sgn(v)
    y = 1.0 - f * sv / fc
    ay = abs(y)
    if ay == 0.0:
        return f
    d = sigma * abs(v) * h / fc
    if alpha == 1.0:
        ayn = ay * math.exp(-d)
    elif alpha < 1.0:
        q = ay ** (1.0 - alpha) - (1.0 - alpha) * d
        ayn = q ** (1.0 / (1.0 - alpha)) if q > 0.0 else 0.0
    else:
        ayn = (ay ** (1.0 - alpha) + (alpha - 1.0) * d) ** (-1.0 / (alpha - 1.0))
    yn = ayn if y > 0.0 else -ayn
    return fc * sv * (1.0 - yn)


@jit
def gms_update(p, o, st, v, h):
    """GMS update (ABB M19-S paper eqs. (2)-(3), sign fixed per ABB M19-S paper A.2.4), exact for constant ``v``.

    State ``st`` = [F_1..F_N, stuck_1..stuck_N] (stuck as 1.0/0.0), updated in place.
    Stick: dF_i/dt = k_i v (exact: F_i += k_i v h); an element breaks away when
    |F_i| >= alpha_i s(v) in the direction of motion and is then held at alpha_i s(v) sgn(v).
    Slip: dF_i/dt = C (alpha_i sgn(v) - F_i / s(v)), C = ``attraction``, solved exactly (relaxation
    rate C/s).
    A slipping element sticks again on reversal (F_i v < 0) or at v = 0.
    Presliding micro-damping (Lampaert et al.: F = sum_i (k_i z_i + sigma_i dz_i/dt) + fv v)
    with stiffness-proportional sigma_i = sigma1 k_i / sum_j k_j, i.e. with dz_i/dt = (dF_i/dt) / k_i
    the damping force is (sigma1 / sum_j k_j) sum_i dF_i/dt, evaluated over the step as
    sum_i (F_i(t+h) - F_i(t)) / h (= sigma1 v while every element sticks).
    p = n, fc, fs, vs, delta, attraction, fv, k_1..k_n, alpha_1..alpha_n, sigma1 (GMS.sigma1, default 0)
    """
    n = int(p[o])
    s = stribeck_s(abs(v), p[o + 1], p[o + 2], p[o + 3], p[o + 4])
    attraction = p[o + 5]
    sv = sgn(v)
    decay = math.exp(-attraction * h / s)
    sig = p[o + 7 + 2 * n]
    total = 0.0
    dsum = 0.0
    ksum = 0.0
    for i in range(n):
        k = p[o + 7 + i]
        lim = p[o + 7 + n + i] * s
        f = st[i]
        stuck = st[n + i] != 0.0
        if v == 0.0:
            stuck = True
        else:
            if not stuck and f * v < 0.0:
                stuck = True
            if stuck:
                f = f + k * v * h
                if f * sv >= lim:
                    f = lim * sv
                    stuck = False
            else:
                tgt = lim * sv
                f = tgt + (f - tgt) * decay
        dsum += f - st[i]
        ksum += k
        st[i] = f
        st[n + i] = 1.0 if stuck else 0.0
        total += f
    if sig > 0.0 and h > 0.0:
        total += sig / ksum * dsum / h
    return total + p[o + 6] * v


@jit
def friction_eval(kind, p, st, v, h, load):
    """Advance a model of any kind by ``h`` at velocity ``v`` and return its friction torque."""
    o = 0
    if kind == K_ASYMMETRIC:
        m = int(p[1])
        o = 2 if v >= 0.0 else 2 + m
        kind = int(p[0])
    if kind == K_LUGRE:
        zn, f = lugre_update(p, o, st[0], v, h)
        st[0] = zn
        return f
    if kind == K_DAHL:
        f = dahl_update(p, o, st[0], v, h)
        st[0] = f
        return f
    if kind == K_GMS:
        return gms_update(p, o, st, v, h)
    return static_torque(kind, p, o, v, load)


@jit
def simulate_batch_kernel(kind, pmat, st0, v, h, out):
    """Simulate one model kind for every parameter row of ``pmat`` over the velocity trajectory ``v``.

    ``st0`` (rows x state) is the initial state per row (copied); ``out`` (rows x len(v)) receives the
    torque after each step.
    """
    rows = pmat.shape[0]
    nt = v.shape[0]
    for r in range(rows):
        p = pmat[r]
        st = st0[r].copy()
        for t in range(nt):
            out[r, t] = friction_eval(kind, p, st, v[t], h, 0.0)


@jit
def simulate_kernel(kind, p, st, v, h, out):
    """Simulate one parameter set over ``v`` (state ``st`` updated in place)."""
    for t in range(v.shape[0]):
        out[t] = friction_eval(kind, p, st, v[t], h, 0.0)
