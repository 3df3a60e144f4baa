"""Machines the project never saw: a ball-screw axis in metres and newtons, a hobby servo at
centi-newton-metres, one joint of a coupled two-link arm.

Friction comes from the project's models (:mod:`friction_ros.core.friction`); the hobby servo runs
on the project's plant (:func:`~friction_ros.core.synthetic.logs.tables.track`); the axis and the arm
follow their reference exactly (a stiff position loop), so their effort is the inverse dynamics.
"""

from __future__ import annotations

import math

import numpy as np

from friction_ros.core.friction import make_model
from friction_ros.core.synthetic.logs.tables import GauntletLog, quantize, scaled_sines, track

G = 9.81


# ------------------------------------------------------------------------------------ ball-screw axis
def _min_jerk_moves(rng, n: int, dt: float, lo: float, hi: float, vmax: float):
    """Point-to-point moves between random targets in [lo, hi] m, minimum-jerk profiles
    s(u) = 10u^3 - 15u^4 + 6u^5 (peak speed 1.875 D / T <= vmax), 0.2-0.6 s dwell between moves."""
    q = np.empty(n)
    v = np.zeros(n)
    a = np.zeros(n)
    k, x = 0, 0.5 * (lo + hi)
    while k < n:
        dwell = int(rng.uniform(0.2, 0.6) / dt)
        q[k : k + dwell] = x
        k += dwell
        if k >= n:
            break
        target = rng.uniform(lo, hi)
        d = target - x
        T = max(1.875 * abs(d) / (vmax * rng.uniform(0.4, 1.0)), 0.1)
        m = int(round(T / dt))
        u = np.arange(1, m + 1) / m
        seg = slice(k, min(k + m, n))
        u = u[: seg.stop - seg.start]
        q[seg] = x + d * (10 * u**3 - 15 * u**4 + 6 * u**5)
        v[seg] = d / T * (30 * u**2 - 60 * u**3 + 30 * u**4)
        a[seg] = d / T**2 * (60 * u - 180 * u**2 + 120 * u**3)
        k, x = seg.stop, target
    return q[:n], v[:n], a[:n]


def prismatic_ballscrew(seed: int = 0, seconds: float = 30.0, validation_seconds: float | None = None):
    """Ball-screw linear axis at N scale (1 kHz), estimation run + validation run:

    F = M a + Fv v + Fc sgn(v) + F0   [N],  M = 15 kg, Fv = 200 N*s/m, Fc = 20 N, F0 = 15 N
    (inclined axis plus cable drag), |F| up to ~100 N. Estimation: a multisine of 0.05-4 Hz
    (velocity amplitudes rising as sqrt(f)), |v| <= 0.2 m/s over a ~0.1 m stroke; validation: minimum-jerk point-to-point moves with dwells (another excitation).
    Measured: position on a 1 um linear scale, velocity +- 0.5 mm/s noise, force +- 1 N noise.
    """
    rng = np.random.default_rng(seed)
    dt = 1e-3
    M, fv, fc, f0 = 15.0, 200.0, 20.0, 15.0
    fric = make_model("coulomb_viscous", fc=fc, fv=fv)

    def table(q, v, a, label, excitation):
        f = M * a + fric.torque(v) + f0
        n = q.size
        cols = {
            "time": np.arange(n) * dt,
            "position": quantize(q, 1e-6),
            "velocity": v + 5e-4 * rng.standard_normal(n),
            "force": f + 1.0 * rng.standard_normal(n),
        }
        truth = {
            "mass": M,
            "fv": fv,
            "fc": fc,
            "offset": f0,
            "friction": fric.to_config(),
            "excitation": excitation,
            "force_range": [float(f.min()), float(f.max())],
            "stroke": float(np.ptp(q)),
            "speed_max": float(np.max(np.abs(v))),
        }
        return GauntletLog(
            label,
            "ball-screw linear axis, force F = M a + Fv v + Fc sgn(v) + F0",
            cols,
            {"time": "s", "position": "m", "velocity": "m/s", "force": "N"},
            truth,
            {"columns": {"time": "time", "position": "position", "velocity": "velocity", "effort": "force"}},
        )

    n = int(round(seconds / dt))
    t = np.arange(n) * dt
    q, v, a, _ = scaled_sines(rng, t, 0.05, 4.0, 0.25, 0.2, n=7, tilt=0.5)
    est = table(0.15 + q, v, a, "prismatic_ballscrew", "multisine 0.05-4 Hz")
    nv = int(round((validation_seconds or seconds) / dt))
    qv, vv, av = _min_jerk_moves(rng, nv, dt, 0.02, 0.28, 0.2)
    est.validation = table(qv, vv, av, "prismatic_ballscrew_validation", "point-to-point moves")
    return est


# ------------------------------------------------------------------------------------ hobby servo
def hobby_servo(seed: int = 0, seconds: float = 30.0) -> GauntletLog:
    """Hobby servo at 0.01-0.1 N*m: J = 2e-4 kg*m^2, Stribeck friction Fc = 0.02, Fs = 0.03 N*m,
    vs = 0.4 rad/s, Fv = 0.004 N*m*s/rad, on the project plant with a P-D loop (torque limit
    0.1 N*m, D on a 50 Hz filtered velocity) at 1 kHz. Logged like a microcontroller does: 100 Hz
    with 0-2 ms loop jitter, integer ``millis`` stamps, a 10-bit potentiometer over 270 deg (4.6 mrad), the current-sense torque
    estimate (+- 3 mN*m noise), no velocity column.
    """
    from friction_ros.core.plant.params import PlantParams

    rng = np.random.default_rng(seed)
    dt, J, limit = 1e-3, 2e-4, 0.1
    fric = make_model("stribeck", fc=0.02, fs=0.03, vs=0.4, delta=2.0, fv=0.004)
    cpr = int(round(1024 * 360 / 270))  # counts per revolution of the 10-bit pot over 270 deg
    params = PlantParams(
        motor_inertia=J,
        actuation="torque",
        torque_constant=1.0,
        friction_motor=fric.to_config(),
        encoder_cpr=cpr,
        encoder_location="joint",
        current_noise_std=0.003,
        velocity_filter_hz=50.0,
        seed=seed,
    )
    n = int(round(seconds / dt)) + 3
    t = np.arange(n) * dt
    q, v, _, _ = scaled_sines(rng, t, 0.1, 2.0, 2.0, 4.0, n=6)
    wn = 2 * math.pi * 8.0
    run = track(params, q, v, dt, kp=J * wn * wn, kd=2 * 0.7 * J * wn, limit=limit)
    idx = np.arange(0, n - 3, 10) + rng.integers(0, 3, size=(n - 3 + 9) // 10)
    truth = {
        "inertia": J,
        "friction": fric.to_config(),
        "torque_limit": limit,
        "encoder_step": 2 * math.pi / cpr,
        "effort_range": [float(run["effort"].min()), float(run["effort"].max())],
        "speed_max": float(np.max(np.abs(run["true_velocity"]))),
        "saturated_percent": float(100 * np.mean(np.abs(run["command"]) >= limit)),
    }
    return GauntletLog(
        "hobby_servo",
        "hobby servo, 100 Hz serial log with millis() stamps, pot angle and current-sense torque",
        {"millis": idx.astype(float), "angle": run["position"][idx], "torque_est": run["effort"][idx]},
        {"millis": "ms", "angle": "rad", "torque_est": "N*m"},
        truth,
        {"columns": {"time": "millis", "position": "angle", "effort": "torque_est"}, "time_scale": 1e-3},
    )


# ------------------------------------------------------------------------------------ two-link arm
#: planar arm in a vertical plane (angles from hanging down), sized like the DFKI double pendulum
ARM = {"m1": 0.4, "m2": 0.4, "l1": 0.3, "lc1": 0.3, "lc2": 0.2, "I1": 0.054, "I2": 0.024, "rotor": 2.2e-3}


def arm_inverse_dynamics(q1, q2, v1, v2, a1, a2, p=ARM) -> tuple[np.ndarray, np.ndarray]:
    """Joint torques [N*m] of the two-link arm without friction:

    tau = M(q) qdd + C(q, qd) + G(q),  b = m2 l1 lc2,  A = I1 + I2 + m1 lc1^2 + m2 (l1^2 + lc2^2),
    D = I2 + m2 lc2^2,  M = [[A + 2 b cos q2 + Ir, D + b cos q2], [D + b cos q2, D + Ir]],
    C = [-b sin q2 (2 v1 v2 + v2^2), b sin q2 v1^2],
    G = [(m1 lc1 + m2 l1) g sin q1 + m2 lc2 g sin(q1 + q2), m2 lc2 g sin(q1 + q2)]
    (Ir: the reflected rotor inertia of each joint's gearmotor).
    """
    b = p["m2"] * p["l1"] * p["lc2"]
    A = p["I1"] + p["I2"] + p["m1"] * p["lc1"] ** 2 + p["m2"] * (p["l1"] ** 2 + p["lc2"] ** 2)
    D = p["I2"] + p["m2"] * p["lc2"] ** 2
    c2, s2 = np.cos(q2), np.sin(q2)
    g12 = p["m2"] * p["lc2"] * G * np.sin(q1 + q2)
    tau1 = (A + 2 * b * c2 + p["rotor"]) * a1 + (D + b * c2) * a2 - b * s2 * (2 * v1 * v2 + v2**2)
    tau1 = tau1 + (p["m1"] * p["lc1"] + p["m2"] * p["l1"]) * G * np.sin(q1) + g12
    tau2 = (D + b * c2) * a1 + (D + p["rotor"]) * a2 + b * s2 * v1**2 + g12
    return tau1, tau2


def coupled_arm(seed: int = 0, seconds: float = 30.0) -> GauntletLog:
    """One joint of a coupled two-link arm at 500 Hz (both joints' columns in the file; the fitter
    is given the shoulder): tau_i = [M qdd + C + G]_i + F_i(v_i) + noise, F_i Stribeck
    (shoulder Fc 0.3, Fs 0.4 N*m, vs 0.3 rad/s, Fv 0.1 N*m*s/rad; elbow 0.1, 0.15, 0.3, 0.03).
    Sensors as MIT-mode CAN reports them: 16-bit position over 25 rad, 12-bit velocity over 90 rad/s,
    torque +- 0.02 N*m noise. ``truth["friction_share_percent"]``: var(F_1) / var(tau_1).
    """
    rng = np.random.default_rng(seed)
    dt = 2e-3
    n = int(round(seconds / dt))
    t = np.arange(n) * dt
    q1, v1, a1, _ = scaled_sines(rng, t, 0.15, 2.0, 0.8, 3.0, n=6)
    q2, v2, a2, _ = scaled_sines(rng, t, 0.2, 2.5, 2.4, 8.0, n=6)
    f1 = make_model("stribeck", fc=0.3, fs=0.4, vs=0.3, delta=2.0, fv=0.1)
    f2 = make_model("stribeck", fc=0.1, fs=0.15, vs=0.3, delta=2.0, fv=0.03)
    r1, r2 = arm_inverse_dynamics(q1, q2, v1, v2, a1, a2)
    tau1, tau2 = r1 + f1.torque(v1), r2 + f2.torque(v2)
    pos_step, vel_step = 25.0 / 2**16, 90.0 / 2**12
    cols = {"time": t}
    for name, q, v, tau in (("shoulder", q1, v1, tau1), ("elbow", q2, v2, tau2)):
        cols[f"{name}_position"] = np.round(q / pos_step) * pos_step
        cols[f"{name}_velocity"] = np.round(v / vel_step) * vel_step
        cols[f"{name}_effort"] = tau + 0.02 * rng.standard_normal(n)
    units = {k: "s" if k == "time" else k.split("_")[1] for k in cols}
    units = {
        k: {"s": "s", "position": "rad", "velocity": "rad/s", "effort": "N*m"}[u] for k, u in units.items()
    }
    truth = {
        "arm": dict(ARM),
        "friction": {"shoulder": f1.to_config(), "elbow": f2.to_config()},
        "friction_share_percent": float(100 * np.var(f1.torque(v1)) / np.var(tau1)),
        "effort_range": [float(tau1.min()), float(tau1.max())],
    }
    return GauntletLog(
        "coupled_arm",
        "two-link arm, both joints logged; each joint torque carries the other link's gravity and inertia",
        cols,
        units,
        truth,
        {"joint": "shoulder"},
    )
