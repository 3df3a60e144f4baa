"""Compiled inner loop of the plant: the parameter-vector layout and the numba integration kernels.

:func:`pack_params` turns :class:`~friction_ros.core.plant.params.PlantParams` into the flat vector
``P`` (indices ``P_*``); the state vector ``x`` has the indices ``X_*``. :func:`run_control_periods`
advances both for a sequence of control periods of ``n_sub`` semi-implicit Euler sub-steps each,
with the equations of :mod:`friction_ros.core.plant.servo` (rigid or compliant transmission, current
lag or armature circuit, static friction with stick logic, dynamic friction states).

The friction comes from :func:`~friction_ros.core.friction._kernels.friction_eval` (every model kind,
tabulated static maps included). numba's on-disk cache keys a compiled function on its own file
only: a change of the friction kernels must touch this file too, or a stale plant loop stays cached.
"""

from __future__ import annotations

import math

import numpy as np

from friction_ros.core.friction._kernels import friction_eval, jit
from friction_ros.core.plant.params import PlantParams

(
    P_JM,
    P_JL,
    P_R,
    P_ETA,
    P_BM,
    P_BL,
    P_KL,
    P_GRAV,
    P_TLOAD,
    P_BACKLASH,
    P_KC,
    P_CC,
    P_KT,
    P_MODE,
    P_TAUI,
    P_RES,
    P_IND,
    P_KE,
    P_IMAX,
    P_UMAX,
    P_BAND_M,
    P_BAND_L,
    P_STICK,
    P_COMPLIANT,
    P_GRAV_AMP,
    P_GRAV_PHASE,
    P_SIZE,
) = range(27)
X_THM, X_WM, X_Q, X_WL, X_I, X_SIZE = range(6)


def pack_params(p: PlantParams) -> np.ndarray:
    """The parameter vector ``P`` of :func:`run_control_periods` for the validated parameters ``p``."""
    P = np.zeros(P_SIZE)
    P[P_JM] = p.motor_inertia + p.transmission_inertia
    P[P_JL] = p.load_inertia
    P[P_R] = p.ratio
    P[P_ETA] = p.gear_efficiency
    P[P_BM] = p.motor_damping
    P[P_BL] = p.load_damping
    P[P_KL] = p.load_stiffness
    P[P_GRAV] = p.gravity_force
    P[P_TLOAD] = p.load_torque
    P[P_BACKLASH] = p.backlash
    P[P_KC] = p.coupling_stiffness
    P[P_CC] = p.coupling_damping
    P[P_KT] = p.torque_constant
    P[P_MODE] = 1.0 if p.actuation == "voltage" else 0.0
    P[P_TAUI] = p.current_time_constant
    P[P_RES] = p.resistance
    P[P_IND] = p.inductance
    P[P_KE] = p.back_emf_constant
    P[P_IMAX] = p.current_limit
    P[P_UMAX] = p.voltage_limit
    fm, fl = p.friction_motor, p.friction_load
    P[P_BAND_M] = fm.coefficients.get("dv", 0.0) if fm.name == "karnopp" else 0.0
    P[P_BAND_L] = fl.coefficients.get("dv", 0.0) if fl.name == "karnopp" else 0.0
    P[P_STICK] = 1.0 if p.stick_logic else 0.0
    P[P_COMPLIANT] = 1.0 if p.compliant else 0.0
    P[P_GRAV_AMP] = p.gravity
    P[P_GRAV_PHASE] = p.gravity_phase
    return P


@jit
def static_pair(km, pm, sm, kl, pl, sl, w, r, scale_l, load_m, load_l):
    """Static friction of both sides at motor velocity ``w`` (load side reflected by ``scale_l``)."""
    f = 0.0
    if km >= 0:
        f += friction_eval(km, pm, sm, w, 0.0, load_m)
    if kl >= 0:
        f += scale_l * friction_eval(kl, pl, sl, w / r, 0.0, load_l)
    return f


@jit
def body_step(w, ta, J, h, km, pm, sm, kl, pl, sl, r, scale_l, load_m, load_l, band, stick):
    """Advance one body's velocity with static friction (GKF/Karnopp stick logic); returns (w, F)."""
    if km < 0 and kl < 0:
        return w + h * ta / J, 0.0
    if not stick:
        f = static_pair(km, pm, sm, kl, pl, sl, w, r, scale_l, load_m, load_l)
        return w + h * (ta - f) / J, f
    if w == 0.0 or abs(w) < band:
        d = 1.0 if ta >= 0.0 else -1.0
        brk = abs(static_pair(km, pm, sm, kl, pl, sl, d * 1e-12, r, scale_l, load_m, load_l))
        if abs(ta) <= brk:
            return 0.0, ta
        f = d * brk
        return w + h * (ta - f) / J, f
    f = static_pair(km, pm, sm, kl, pl, sl, w, r, scale_l, load_m, load_l)
    wn = w + h * (ta - f) / J
    if wn * w < 0.0:
        wn = 0.0
    return wn, f


@jit
def run_control_periods(P, x, km, pm, sm, dm, kl, pl, sl, dl, cmd, n_sub, h, out):
    """Run len(cmd) control periods of n_sub sub-steps each; out[k] = (thm, wm, q, wl, i, f_m, f_l)."""
    r = P[P_R]
    eta = P[P_ETA]
    refl = 1.0 / (r * eta)
    kt = P[P_KT]
    compliant = P[P_COMPLIANT] != 0.0
    stick = P[P_STICK] != 0.0
    jm = P[P_JM]
    jl = P[P_JL]
    jeq = jm + jl * refl / r
    decay_i = 0.0
    if P[P_MODE] == 0.0:
        if P[P_TAUI] > 0.0:
            decay_i = math.exp(-h / P[P_TAUI])
    elif P[P_IND] > 0.0:
        decay_i = math.exp(-P[P_RES] * h / P[P_IND])
    # static vs dynamic friction split
    skm = km if dm == 0 else -1
    skl = kl if dl == 0 else -1
    grav_amp = P[P_GRAV_AMP]
    thm, wm, q, wl, cur = x[X_THM], x[X_WM], x[X_Q], x[X_WL], x[X_I]
    fm_last = 0.0
    fl_last = 0.0
    for k in range(cmd.shape[0]):
        c = cmd[k]
        for _ in range(n_sub):
            # --- current ---
            if P[P_MODE] == 0.0:
                iss = c
            else:
                u = c
                if P[P_UMAX] > 0.0:
                    u = min(max(u, -P[P_UMAX]), P[P_UMAX])
                iss = (u - P[P_KE] * wm) / P[P_RES]
            cur = iss + (cur - iss) * decay_i
            if P[P_IMAX] > 0.0:
                cur = min(max(cur, -P[P_IMAX]), P[P_IMAX])
            tm = kt * cur
            # joint-side load towards -q: constant gravity_force plus, when set, the pendulum term
            # gravity sin(q + gravity_phase) (skipped at 0: the sums are bit-identical without it)
            grav = P[P_GRAV]
            if grav_amp != 0.0:
                grav = grav + grav_amp * math.sin(q + P[P_GRAV_PHASE])
            if not compliant:
                qd = wm / r
                # dynamic friction (advance states once per sub-step)
                fdyn = 0.0
                if dm != 0:
                    fm_last = friction_eval(km, pm, sm, wm, h, tm)
                    fdyn += fm_last
                if dl != 0:
                    fl_last = friction_eval(kl, pl, sl, qd, h, tm * r * eta)
                    fdyn += refl * fl_last
                ta = tm - P[P_BM] * wm - refl * (P[P_BL] * qd + P[P_KL] * q + grav - P[P_TLOAD]) - fdyn
                wn, fs = body_step(
                    wm,
                    ta,
                    jeq,
                    h,
                    skm,
                    pm,
                    sm,
                    skl,
                    pl,
                    sl,
                    r,
                    refl,
                    tm,
                    tm * r * eta,
                    max(P[P_BAND_M], P[P_BAND_L] * r),
                    stick,
                )
                if dm == 0:
                    fm_last = fs
                elif dl == 0:
                    fl_last = fs / refl
                wm = wn
                thm += h * wm
                q = thm / r
                wl = wm / r
            else:
                defl = thm / r - q
                gap = 0.5 * P[P_BACKLASH]
                if defl > gap:
                    dz = defl - gap
                elif defl < -gap:
                    dz = defl + gap
                else:
                    dz = 0.0
                tc = P[P_KC] * dz
                if dz != 0.0:
                    tc += P[P_CC] * (wm / r - wl)
                fdm = 0.0
                fdl = 0.0
                if dm != 0:
                    fdm = friction_eval(km, pm, sm, wm, h, tm)
                    fm_last = fdm
                if dl != 0:
                    fdl = friction_eval(kl, pl, sl, wl, h, tc)
                    fl_last = fdl
                tam = tm - P[P_BM] * wm - refl * tc - fdm
                tal = tc - P[P_BL] * wl - P[P_KL] * q - grav + P[P_TLOAD] - fdl
                wmn, fsm = body_step(
                    wm, tam, jm, h, skm, pm, sm, -1, pl, sl, r, 1.0, tm, 0.0, P[P_BAND_M], stick
                )
                wln, fsl = body_step(
                    wl, tal, jl, h, skl, pl, sl, -1, pl, sl, 1.0, 1.0, tc, 0.0, P[P_BAND_L], stick
                )
                if dm == 0:
                    fm_last = fsm
                if dl == 0:
                    fl_last = fsl
                wm = wmn
                wl = wln
                thm += h * wm
                q += h * wl
        out[k, 0] = thm
        out[k, 1] = wm
        out[k, 2] = q
        out[k, 3] = wl
        out[k, 4] = cur
        out[k, 5] = fm_last
        out[k, 6] = fl_last
    x[X_THM] = thm
    x[X_WM] = wm
    x[X_Q] = q
    x[X_WL] = wl
    x[X_I] = cur
