"""Spur-gear dynamic-transmission-error model with sliding friction (Chatterjee et al. 2017 A.1.2).

J_e d'' + B(t) d' + K(t) d = u, with (exactly as coded in ``friction_model*.m``)
B(t) = c1 (1 + fac1 sgn) + c0 fac0, K(t) = k1 (1 + fac1 sgn) + k0 fac0,
fac_i = mu (X_pi J_g r_bp + X_gi J_p r_bg) / deno, deno = J_p r_bg^2 + J_g r_bp^2,
J_e = J_p J_g / deno, u = (T_p J_g r_bp + T_g J_p r_bg) / deno,
sgn = sign(mod(omega_p r_bp t, lambda) - Lap) (sliding direction flips at the pitch point),
integrated with explicit Euler (step h) from rest, as the report does. ``modified=True`` reproduces
``friction_model_modified.m`` (time-varying mesh stiffness/damping and moment arms, He Song eqs.
2.3, 2.6-2.8). Units are the report's (inch-pound); this is a regression model, not a plant part.
"""

from __future__ import annotations

import math

import numpy as np


def _msign(x: float) -> float:
    return 0.0 if x == 0 else math.copysign(1.0, x)


def spur_gear_dte(
    modified: bool = False, t_sim: float | None = None, h: float = 1e-3
) -> dict[str, np.ndarray]:
    """Simulate the Chatterjee et al. 2017 gear model; returns ``{"t", "delta", "delta_dot", "K", "B"}``.

    ``modified=False``: ``friction_model.m`` with all-unit parameters (15 s): d'' + d' + d = 0.5
    (Chatterjee et al. 2017 A-T1: peak 0.5817 near 3.63 s). ``modified=True``: ``friction_model_modified.m`` (0.5 s).
    """
    if not modified:
        c1 = c0 = k1 = k0 = 1.0
        xp1 = xp0 = xg1 = xg0 = 1.0
        jp = jg = 1.0
        rbg = rbp = 1.0
        omegap, lam, mu, te, lap = 1.0, 1.0, 1.0, 1.0, 1.0
        t_sim = 15.0 if t_sim is None else t_sim
        deno = jp * rbg**2 + jg * rbp**2
        je = 1.0  # as coded (placeholder, not Jp Jg / deno)
        u = te / deno
    else:
        jp, jg = 8.48e-3, 2.00e-2
        rbg, rbp = 4.117 / 2, 3.372 / 2
        lam = math.pi / 8
        omegap = 100 * math.pi / 3
        zetam, gamma, mu = 0.2, 1.43, 0.2
        tp = 2000.0
        tg = (31 / 25) * tp
        deno = jp * rbg**2 + jg * rbp**2
        je = jp * jg / deno
        te = tp * jg * rbp + tg * jp * rbg
        u = te / deno
        lap = lam * (gamma - 1) / (2 - gamma)
        kk = 20e3
        lxa = lyc = 1.0
        tc = lam / (omegap * rbp)
        t_sim = 0.5 if t_sim is None else t_sim
    n = int(round(t_sim / h))
    x1 = np.zeros(n + 1)
    x2 = np.zeros(n + 1)
    ks = np.zeros(n)
    bs = np.zeros(n)
    t = 0.0
    for i in range(n):
        if modified:
            t = h * i
            k1 = kk * math.fmod(t, tc)
            k0 = kk * (tc + math.fmod(t, tc))
            c1 = 2 * zetam * math.sqrt(k1 * je)
            c0 = 2 * zetam * math.sqrt(k0 * je)
            m = math.fmod(omegap * rbp * t, lam)
            xp1 = lxa + m
            xp0 = lxa + lam + m
            mg = math.fmod(omegap * rbg * t, lam)
            xg1 = lyc + lam - mg
            xg0 = lyc - mg
        fac0 = mu * (xp0 * jg * rbp + xg0 * jp * rbg) / deno
        fac1 = mu * (xp1 * jg * rbp + xg1 * jp * rbg) / deno
        sg = _msign(math.fmod(omegap * rbp * t, lam) - lap)
        b = c1 * (1 + fac1 * sg) + c0 * fac0
        k = k1 * (1 + fac1 * sg) + k0 * fac0
        ks[i], bs[i] = k, b
        x1[i + 1] = x1[i] + h * x2[i]
        x2[i + 1] = x2[i] + h * (-k * x1[i] / je - b * x2[i] / je + u / je)
        if not modified:
            t += h
    return {"t": np.arange(n + 1) * h, "delta": x1, "delta_dot": x2, "K": ks, "B": bs}
