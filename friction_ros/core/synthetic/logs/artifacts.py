"""Logs whose trouble is the measurement or the run, not the machine: creep under dither (LuGre),
a coarse encoder, jittered and missing samples, a drive at its torque limit.

The creep, encoder and saturation runs use the project's plant
(:class:`~friction_ros.core.plant.servo.GearheadServoPlant`, exact stick logic and LuGre update);
the jittered log is the exact inverse dynamics sampled at irregular instants.
"""

from __future__ import annotations

import math

import numpy as np

from friction_ros.core.friction import make_model
from friction_ros.core.synthetic.logs.tables import GauntletLog, multisine, scaled_sines, sines, track

JOINT_UNITS = {"time": "s", "position": "rad", "velocity": "rad/s", "effort": "N*m"}
JOINT_COLUMNS = ("time", "position", "velocity", "effort")


def _plant(J: float, friction, seed: int, **plant):
    from friction_ros.core.plant.params import PlantParams

    return PlantParams(
        motor_inertia=J,
        actuation="torque",
        torque_constant=1.0,
        friction_motor=friction.to_config(),
        seed=seed,
        **plant,
    )


def _joint_log(name, description, t, run, effort_key, truth) -> GauntletLog:
    cols = {"time": t, "position": run["position"], "velocity": run["velocity"], "effort": run[effort_key]}
    return GauntletLog(name, description, cols, dict(JOINT_UNITS), truth)


def lugre_creep(seed: int = 0, seconds: float = 20.0) -> GauntletLog:
    """A joint creeping under dither (1 kHz): LuGre friction (sigma0 = 2000 N*m/rad, sigma1 = 1.4
    N*m*s/rad, Fc = 0.2, Fs = 0.3 N*m, vs = 0.02 rad/s, Fv = 0.02 N*m*s/rad), J = 1e-3 kg*m^2,
    open-loop torque tau = s(t) b(t) Fs + 0.2 Fs sin(2 pi 25 t): a bias b = 0.4-0.6 of breakaway
    whose sign s flips every 1.5-3 s (smoothed over 0.2 s) plus a small dither; the peaks reach
    0.6-0.8 Fs, just above Fc. The joint sticks, slips a little every dither cycle and creeps
    (mean |v| ~ 0.03 rad/s); encoder 2^20 counts/rev, torque +- 3 mN*m noise.
    """
    rng = np.random.default_rng(seed)
    dt, J, fs = 1e-3, 1e-3, 0.3
    fric = make_model("lugre", sigma0=2000.0, sigma1=1.4, fv=0.02, fc=0.2, fs=fs, vs=0.02, delta=2.0)
    n = int(round(seconds / dt))
    t = np.arange(n) * dt
    sign, bias = np.empty(n), np.empty(n)
    k, s = 0, 1.0
    while k < n:
        m = int(rng.uniform(1.5, 3.0) / dt)
        sign[k : k + m], bias[k : k + m] = s, rng.uniform(0.4, 0.6)
        k, s = k + m, -s
    w = int(0.2 / dt)
    kernel = np.ones(w) / w
    sb = np.convolve(np.pad(sign * bias, (w // 2, w - 1 - w // 2), mode="edge"), kernel, "valid")
    ff = sb * fs + 0.2 * fs * np.sin(2 * math.pi * 25.0 * t)
    params = _plant(J, fric, seed, encoder_cpr=2**20, encoder_location="joint", current_noise_std=0.003)
    run = track(params, np.zeros(n), np.zeros(n), dt, kp=0.0, kd=0.0, limit=10.0, ff=ff)
    truth = {
        "inertia": J,
        "friction": fric.to_config(),
        "dither": {"amplitude": 0.2 * fs, "hz": 25.0},
        "travel": float(np.ptp(run["true_position"])),
        "speed_max": float(np.max(np.abs(run["true_velocity"]))),
        "speed_mean_abs": float(np.mean(np.abs(run["true_velocity"]))),
    }
    return _joint_log(
        "lugre_creep", "LuGre joint creeping under a dithered torque near breakaway", t, run, "effort", truth
    )


def coarse_encoder(seed: int = 0, seconds: float = 20.0, cpr: int = 2**10) -> GauntletLog:
    """A joint read by a coarse encoder (``cpr`` counts per revolution at the joint, 6.1 mrad for
    2^10) at 1 kHz: J = 5e-3 kg*m^2, Stribeck Fc = 0.15, Fs = 0.25 N*m, vs = 0.1 rad/s, Fv = 0.05
    N*m*s/rad; a P-D loop (limit 3 N*m) on the quantised position and the drive's 100 Hz filtered
    difference velocity tracks a 0.1-1.5 Hz multisine (|v| <= 3 rad/s); torque +- 5 mN*m noise.
    """
    rng = np.random.default_rng(seed)
    dt, J = 1e-3, 5e-3
    fric = make_model("stribeck", fc=0.15, fs=0.25, vs=0.1, delta=2.0, fv=0.05)
    n = int(round(seconds / dt))
    t = np.arange(n) * dt
    q, v, _, _ = scaled_sines(rng, t, 0.1, 1.5, 3.0, 3.0, n=6)
    params = _plant(
        J,
        fric,
        seed,
        encoder_cpr=cpr,
        encoder_location="joint",
        velocity_filter_hz=100.0,
        current_noise_std=0.005,
    )
    wn = 2 * math.pi * 6.0
    run = track(params, q, v, dt, kp=J * wn * wn, kd=2 * 0.7 * J * wn, limit=3.0)
    truth = {
        "inertia": J,
        "friction": fric.to_config(),
        "counts_per_rev": cpr,
        "encoder_step": 2 * math.pi / cpr,
        "speed_max": float(np.max(np.abs(run["true_velocity"]))),
    }
    return _joint_log("coarse_encoder", f"joint with a {cpr}-count encoder, 1 kHz", t, run, "effort", truth)


def jitter_gaps(seed: int = 0, seconds: float = 30.0) -> GauntletLog:
    """A joint logged by a non-real-time PC (nominal 500 Hz): sample intervals 2 ms + exponential
    delays (mean 0.3 ms, 1 % up to 10 ms), 3 % of rows dropped, three gaps of 0.05-0.4 s, 0.5 % empty
    velocity and effort cells, stamps as ROS epoch seconds. The values are exact at each instant:
    tau = J a + Fc sgn(v) + Fv v + offset (J = 0.02 kg*m^2, Fc = 0.3 N*m, Fv = 0.1 N*m*s/rad, offset
    0.05 N*m) + 0.01 N*m noise.
    """
    rng = np.random.default_rng(seed)
    J, fc, fv, off = 0.02, 0.3, 0.1, 0.05
    fric = make_model("coulomb_viscous", fc=fc, fv=fv)
    steps = 2e-3 + rng.exponential(3e-4, int(seconds / 2e-3) + 10)
    late = rng.random(steps.size) < 0.01
    steps[late] += rng.uniform(2e-3, 1e-2, int(late.sum()))
    t = np.cumsum(steps) - steps[0]
    t = t[t <= seconds]
    keep = rng.random(t.size) >= 0.03
    for start in rng.uniform(0.1, 0.9, 3) * seconds:
        keep &= ~((t >= start) & (t < start + rng.uniform(0.05, 0.4)))
    t = t[keep]
    a_, w_, p_ = multisine(rng, 0.1, 2.0, 6)
    q, v, _ = sines(np.linspace(0, seconds, 20001), a_, w_, p_)
    c = min(2.5 / np.ptp(q), 2.5 / np.max(np.abs(v)))
    q, v, a = sines(t, a_ * c, w_, p_)
    tau = J * a + fric.torque(v) + off + 0.01 * rng.standard_normal(t.size)
    vel = v + 0.01 * rng.standard_normal(t.size)
    vel[rng.random(t.size) < 0.005] = np.nan
    tau[rng.random(t.size) < 0.005] = np.nan
    epoch = 1_700_000_000.0
    cols = {"stamp": epoch + np.round(t * 1e6) / 1e6, "position": q, "velocity": vel, "effort": tau}
    truth = {
        "inertia": J,
        "fc": fc,
        "fv": fv,
        "offset": off,
        "friction": fric.to_config(),
        "nominal_dt": 2e-3,
        "rows_kept_percent": float(100 * keep.mean()),
        "max_gap": float(np.max(np.diff(t))),
    }
    units = dict(JOINT_UNITS, stamp="s (epoch)")
    del units["time"]
    return GauntletLog("jitter_gaps", "jittered 500 Hz stamps, dropped rows and gaps", cols, units, truth)


def saturation(seed: int = 0, seconds: float = 20.0) -> GauntletLog:
    """A drive at its torque limit for part of the run (1 kHz): J = 0.01 kg*m^2, Stribeck Fc = 0.3,
    Fs = 0.45 N*m, vs = 0.2 rad/s, Fv = 0.08 N*m*s/rad, a P-D loop with a 0.5 ms current loop. The
    reference is gentle for the first half (|v| <= 2 rad/s, 0.1-1 Hz) and too fast for the drive in
    the second (|v| <= 6 rad/s, to 3 Hz); the limit is 0.6 x the peak torque the fast half needs
    (J a_ref + F(v_ref)), rounded to 0.05 N*m, and at least 1.2 x what the gentle half needs. The
    effort column is the limiter's output (the drive's torque set-point): flat at the limit while
    clipped.
    """
    rng = np.random.default_rng(seed)
    dt, J = 1e-3, 0.01
    fric = make_model("stribeck", fc=0.3, fs=0.45, vs=0.2, delta=2.0, fv=0.08)
    n = int(round(seconds / dt))
    t = np.arange(n) * dt
    q1, v1, a1, _ = scaled_sines(rng, t, 0.1, 1.0, 2.0, 2.0, n=5)
    q2, v2, a2, _ = scaled_sines(rng, t, 0.3, 3.0, 2.0, 6.0, n=5, tilt=0.5)
    ramp = np.clip((t - 0.45 * seconds) / (0.1 * seconds), 0.0, 1.0)
    q, v = (1 - ramp) * q1 + ramp * q2, (1 - ramp) * v1 + ramp * v2 + (q2 - q1) * np.gradient(ramp, dt)
    need1 = np.max(np.abs(J * a1 + fric.torque(v1)))
    need2 = np.max(np.abs(J * a2 + fric.torque(v2)))
    limit = round(max(round(0.6 * need2 / 0.05) * 0.05, 1.2 * need1), 3)
    params = _plant(J, fric, seed, encoder_cpr=2**16, encoder_location="joint", current_time_constant=5e-4)
    wn = 2 * math.pi * 10.0
    run = track(params, q, v, dt, kp=J * wn * wn, kd=2 * 0.7 * J * wn, limit=limit)
    clipped = np.abs(run["command"]) >= limit
    truth = {
        "inertia": J,
        "friction": fric.to_config(),
        "torque_limit": limit,
        "saturated_percent": float(100 * clipped.mean()),
        "saturated_percent_second_half": float(100 * clipped[n // 2 :].mean()),
        "speed_max": float(np.max(np.abs(run["true_velocity"]))),
    }
    return _joint_log(
        "saturation",
        f"drive clipped at its {limit:.3g} N*m limit in the second half",
        t,
        run,
        "command",
        truth,
    )


def one_direction(seed: int = 0, seconds: float = 20.0) -> GauntletLog:
    """A joint that only turns one way (a conveyor roller, a wheel, a spindle) at 1 kHz: speed
    0.5-4 rad/s, never reversing; tau = J a + Fc sgn(v) + Fv v (J = 0.05 kg*m^2, Fc = 0.4 N*m,
    Fv = 0.15 N*m*s/rad) + 0.01 N*m noise. Fc and Fv of the positive direction are identifiable;
    the negative direction is not in the log.
    """
    rng = np.random.default_rng(seed)
    dt, J, fc, fv = 1e-3, 0.05, 0.4, 0.15
    fric = make_model("coulomb_viscous", fc=fc, fv=fv)
    n = int(round(seconds / dt))
    t = np.arange(n) * dt
    _, s, ds, _ = scaled_sines(rng, t, 0.05, 1.0, 1.0, 1.0, n=5)  # the speed follows a multisine
    lo, hi = float(s.min()), float(s.max())
    v = 0.5 + 3.5 * (s - lo) / (hi - lo)
    a = 3.5 * ds / (hi - lo)
    q = np.concatenate([[0.0], np.cumsum(0.5 * (v[1:] + v[:-1]) * dt)])
    tau = J * a + fric.torque(v) + 0.01 * rng.standard_normal(n)
    cols = {"time": t, "position": q, "velocity": v + 0.005 * rng.standard_normal(n), "effort": tau}
    truth = {"inertia": J, "fc": fc, "fv": fv, "friction": fric.to_config(), "speed_range": [0.5, 4.0]}
    return GauntletLog(
        "one_direction", "joint turning one way only (conveyor, wheel)", cols, dict(JOINT_UNITS), truth
    )
