"""Velocity-tracked programs: constant-velocity plateaus and the band-limited random velocity.

Both are tracked by the velocity PI of :class:`~friction_ros.core.experiment.segments.SegmentContext`.
"""

from __future__ import annotations

import math

import numpy as np

from friction_ros.core.experiment.butterworth import butter_lowpass_sos, sosfiltfilt
from friction_ros.core.experiment.segments import Segment, saturation_note


class PlateauSegment(Segment):
    checked = True

    def __init__(self, index: int, target: float, settle: float, hold: float):
        super().__init__("plateaus", f"plateau{target:+.4g}", index, settle + hold, target)
        self.start_note = f"settle={settle:g}"
        self.settle = settle
        self._sum = 0.0
        self._n = 0
        self._sat = 0

    def motion_failure(self, ctx):
        mean = self._sum / self._n if self._n else 0.0
        if ctx.fraction <= 0 or mean / self.target >= ctx.fraction:
            return None
        return (
            f"plateau at {self.target:+.4g} rad/s held {mean:+.4g} rad/s on average "
            f"(< {100.0 * ctx.fraction:g} % of the target, motion_check.fraction)"
            + saturation_note(self._sat, self._n, ctx.torque_limit)
        )

    def begin(self, ctx, position):
        self._sum, self._n, self._sat = 0.0, 0, 0
        sgn = 1 if self.target > 0 else -1
        if ctx.remember:
            if sgn in ctx.memory:
                ctx.pid.reset(ctx.memory[sgn])
            elif -sgn in ctx.memory:
                ctx.pid.reset(-ctx.memory[-sgn])

    def step(self, ctx, tau, position, velocity, dt):
        if tau >= self.planned:
            ctx.memory[1 if self.target > 0 else -1] = ctx.pid.integral
            return 0.0, True
        torque = ctx.velocity_control(self.target, 0.0, velocity, dt)
        if tau >= self.settle:
            self._sum += velocity
            self._n += 1
            self._sat += ctx.saturated
        return torque, False


class VelocityProfile(Segment):
    checked = True

    def __init__(self, program: str, label: str, index: int, v: np.ndarray, dt: float, target: float):
        super().__init__(program, label, index, v.size * dt, target)
        self.v, self.dt = v, dt
        self.a = np.gradient(v, dt)
        self._ref2 = self._v2 = 0.0
        self._n = self._sat = 0

    def begin(self, ctx, position):
        ctx.pid.reset(0.0)
        self._ref2 = self._v2 = 0.0
        self._n = self._sat = 0

    def motion_failure(self, ctx):
        if ctx.fraction <= 0 or self._ref2 <= 0 or math.sqrt(self._v2 / self._ref2) >= ctx.fraction:
            return None
        rms_ref = math.sqrt(self._ref2 / max(self._n, 1))
        rms = math.sqrt(self._v2 / max(self._n, 1))
        return (
            f"{self.program}: RMS speed {rms:.4g} rad/s for a reference of {rms_ref:.4g} rad/s "
            f"(< {100.0 * ctx.fraction:g} %, motion_check.fraction)"
            + saturation_note(self._sat, self._n, ctx.torque_limit)
        )

    def step(self, ctx, tau, position, velocity, dt):
        if tau >= self.planned:
            return 0.0, True
        k = min(int(tau / self.dt), self.v.size - 1)
        ref = float(self.v[k])
        torque = ctx.velocity_control(ref, float(self.a[k]), velocity, dt)
        self._ref2 += ref * ref
        self._v2 += velocity * velocity
        self._n += 1
        self._sat += ctx.saturated
        return torque, False


def plateau_segments(c: dict) -> list[Segment]:
    p = c["plateaus"]
    speeds = np.geomspace(p["v_max"], p["v_min"], p["count"]) if p["count"] > 1 else np.array([p["v_min"]])
    segs: list[Segment] = []
    i = 0
    for _ in range(p["repeats"]):
        for s in speeds:  # high to low: the remembered integral follows the friction curve
            settle = max(p["settle"], p["settle_travel"] / float(s))
            hold = max(p["hold"], p["hold_travel"] / float(s))
            for sgn in (1.0, -1.0):
                segs.append(PlateauSegment(i, sgn * float(s), settle, hold))
                i += 1
    return segs


def random_velocity(c: dict) -> np.ndarray:
    """ABB M19-S paper excitation: 4 Hz band-limited noise times the 3-term rectangular envelope [rad/s]."""
    r, dt = c["random"], c["control_period"]
    n = int(round(r["duration"] / dt))
    rng = np.random.default_rng(r["seed"])
    sos = butter_lowpass_sos(4, r["bandwidth"], 1.0 / dt)
    x = sosfiltfilt(sos, rng.standard_normal(n + 2000))[1000 : 1000 + n]
    x /= np.sqrt(np.mean(x * x))
    t = np.arange(n) * dt
    w0 = 2 * math.pi / r["envelope_period"]
    hi, lo = 1.0, r["low_level"]
    env = (hi + lo) / 2 + (hi - lo) * (2 / math.pi) * (np.sin(w0 * t) + np.sin(3 * w0 * t) / 3)
    v = r["amplitude"] * np.clip(env, 0.0, None) * x
    # fade in/out over 0.1 s so the segment starts and ends at rest, and remove the drift
    ramp = np.minimum(1.0, np.minimum(t, t[-1] - t) / 0.1)
    v = v * ramp
    v -= ramp * np.sum(v) / max(np.sum(ramp), 1.0)
    return v


def random_segments(c: dict) -> list[Segment]:
    v = random_velocity(c)
    return [VelocityProfile("random", "random", 0, v, c["control_period"], c["random"]["amplitude"])]
