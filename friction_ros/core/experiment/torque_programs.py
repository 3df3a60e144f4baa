"""Open-loop torque programs: breakaway ramps, the chirp and the presliding cycles."""

from __future__ import annotations

import math

from friction_ros.core.experiment.segments import Release, Rest, Segment


class TorqueProfile(Segment):
    """Open-loop torque ``fn(tau)``; with ``expect_motion`` it must move the joint ``travel_counts``."""

    def __init__(
        self, program: str, label: str, index: int, duration: float, fn, target: float, expect_motion=False
    ):
        super().__init__(program, label, index, duration, target)
        self.fn = fn
        self.checked = expect_motion
        self._lo = math.inf
        self._hi = -math.inf

    def begin(self, ctx, position):
        self._lo = self._hi = position

    def motion_failure(self, ctx):
        moved = self._hi - self._lo
        if not self.checked or moved >= ctx.min_travel:
            return None
        return (
            f"{self.program}: the joint moved {moved:.4g} rad under torques up to {abs(self.target):g} N*m "
            f"(< motion_check.travel_counts = {ctx.min_travel:.4g} rad)"
        )

    def step(self, ctx, tau, position, velocity, dt):
        if tau >= self.planned:
            return 0.0, True
        self._lo = min(self._lo, position)
        self._hi = max(self._hi, position)
        return float(self.fn(tau)), False


class BreakawayRamp(Segment):
    """Preload, then small steps until ``counts`` encoder counts of motion within one step."""

    checked = True

    def motion_failure(self, ctx):
        return f"no breakaway up to breakaway.max = {self.b['max']:g} N*m" if self.failed else None

    def __init__(self, index: int, direction: int, b: dict):
        self.dir = 1 if direction > 0 else -1
        self.b = b
        n_steps = int(math.ceil((b["max"] - b["start"]) / b["step"] - 1e-9)) + 1
        self.n_steps = n_steps
        planned = b["preload_time"] + n_steps * b["step_time"]
        super().__init__(
            "breakaway", f"breakaway{'+' if self.dir > 0 else '-'}", index, planned, self.dir * b["max"]
        )
        self.threshold = b["counts"] * b["resolution"] * 0.999
        self.start_note = f"counts={b['counts']} resolution={b['resolution']:.6g}"
        if b["detection_lag"] > 0:
            self.start_note += f" lag={b['detection_lag']:.6g}"
        self.torque = math.nan
        self._step = -1
        self._ref = 0.0
        self.failed = False

    def step(self, ctx, tau, position, velocity, dt):
        b = self.b
        if tau < b["preload_time"]:  # ramp to `start` over 60 %, hold 40 % so the joint comes to rest
            return self.dir * b["start"] * min(1.0, (tau + dt) / max(0.6 * b["preload_time"], dt)), False
        k = int((tau - b["preload_time"]) / b["step_time"] + 1e-9)
        if k >= self.n_steps:
            self.failed = True
            return 0.0, True
        if k != self._step:
            self._step = k
            self._ref = position  # motion counted from where the joint was when this step began
        elif abs(position - self._ref) >= self.threshold:
            self.torque = self.dir * min(b["start"] + k * b["step"], b["max"])
            return self.torque, True
        return self.dir * min(b["start"] + k * b["step"], b["max"]), False

    def end_target(self) -> float:
        return self.torque

    def end_note(self) -> str:
        return f"breakaway torque {self.torque:+.4f} N*m"


def breakaway_segments(c: dict) -> list[Segment]:
    b = c["breakaway"]
    segs: list[Segment] = []
    i = 0
    for _ in range(b["repeats"]):
        for d in (1, -1):
            segs.append(BreakawayRamp(i, d, b))
            segs.append(Release(b["release"]))
            i += 1
    return segs


def chirp_segments(c: dict) -> list[Segment]:
    ch = c["chirp"]
    T, f0, f1, a0, a1 = ch["duration"], ch["f0"], ch["f1"], ch["amplitude"], ch["final_amplitude"]

    def fn(t: float) -> float:
        amp = a0 + (a1 - a0) * t / T
        return amp * math.sin(2 * math.pi * (f0 * t + 0.5 * (f1 - f0) / T * t * t))

    return [TorqueProfile("chirp", "chirp", 0, T, fn, a0)]


def presliding_segments(c: dict) -> list[Segment]:
    ps = c["presliding"]
    f, n = ps["frequency"], ps["cycles"]
    segs: list[Segment] = []
    for i, a in enumerate(ps["amplitudes"]):
        segs.append(
            TorqueProfile(
                "presliding",
                f"presliding{a:.3g}",
                i,
                n / f,
                lambda t, a=a: a * math.sin(2 * math.pi * f * t),
                a,
            )
        )
        segs.append(Rest(min(c["gap"], 0.2)))
    return segs
