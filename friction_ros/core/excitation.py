"""Excitation programs of the identification experiment runner (pure core: numpy/scipy, no rclpy).

A program drives a joint directly with a joint torque [N*m], one call per control period::

    prog = make_program({"program": "sequence", "profile": "quick"})
    torque, events = prog.update(t, position, velocity)      # t [s], position [rad], velocity [rad/s]
    prog.done, prog.progress, prog.total_duration, prog.aborted

Programs (``PROGRAM_NAMES``), each a list of segments planned upfront (``total_duration`` is known
before the run; a breakaway ramp counts with its longest possible duration):

``plateaus``   seed 004 B.3 exp. 2: constant-velocity plateaus at ``count`` log-spaced speeds in
               [v_min, v_max], both directions (+v then -v at each speed, so the joint returns), each
               ``settle`` (transient, discarded: seed 004 0.2 s) + ``hold`` s, ``repeats`` times
               (seed 004: 5). Tracked by the internal velocity PI (``velocity_loop``, with the
               feed-forward ``inertia a + damping v + coulomb sgn(v)`` of the reference). A plateau at
               speed ``v`` settles at least ``settle_travel / v`` and holds at least ``hold_travel / v``
               seconds (default 0: fixed times), so slow plateaus cover a distance: enough encoder
               counts, and several stick-slip cycles below the Stribeck velocity.
``breakaway``  seed 004 B.3 exp. 1: open-loop torque ramp, first a preload to ``start`` (ramped over 60 % of
               ``preload_time``, held for the rest so the joint comes to rest), then steps of ``step`` N*m every ``step_time`` s until the joint moves
               ``counts`` encoder counts (``resolution`` rad per count) within one step, then release
               (``release`` s: the torque is ramped to zero over the first
               half, a step would set the joint ringing on its presliding stiffness). Motion is counted per step, from the position when the
               step was applied: the elastic presliding deflection caused by one small step (GMS/LuGre
               bristles) stays below a count, gross sliding does not. Both directions, ``repeats`` times.
               END event: ``target`` = breakaway torque; ABORT when ``max`` is reached without motion.
               ``detection_lag`` [N*m] (0: unknown): how far above the true breakaway the detection
               may read (one step plus the excess torque that moves ``counts`` counts within one
               step); stated in the START note as ``lag=`` so a fit can judge the reading.
``random``     seed 003 A.3: band-limited random velocity (Butterworth ``bandwidth`` Hz, seeded) under
               the envelope made of the first three non-zero Fourier terms of a rectangle of period
               ``envelope_period`` (levels ``low_level`` and 1) times ``amplitude`` (rad/s, RMS at the
               high level), ``duration`` s (seed 003: 50 s), tracked by the velocity PI.
``chirp``      seed 001 sec. 4.1: torque chirp, linear frequency sweep ``f0`` -> ``f1`` Hz (low to
               high) with an amplitude decreasing linearly from ``amplitude`` to ``final_amplitude``
               N*m (motion stops near the end because the amplitude falls below breakaway).
``presliding`` small-amplitude torque cycles (sine, ``frequency`` Hz, ``cycles`` per amplitude) below
               the breakaway torque: presliding hysteresis (virgin curve, Masing loops).
``sequence``   the programs named in ``sequence``, separated by ``gap`` s of zero torque.

Events: :class:`Event` (time, program, segment label, index within the program, START/END/ABORT,
target, note), the fields of ``friction_msgs/ExperimentEvent``. A plateau START note carries
``settle=<s>`` so readers discard the same transient.

``bias`` [N*m] is added to every torque the program commands, rests and the end included (not
after an abort): the torque that holds a constant load such as gravity, so the ramps and cycles
are centred on it (``friction_ros.core.joint_sizing`` sets it to minus the load).

Safety (``limits``): travel from the position at the program start (``max_travel`` rad), speed
(``max_velocity`` rad/s) and torque (``max_torque`` N*m: commands beyond it abort). A violation
aborts the segment (ABORT event naming the reason, zero torque); ``on_limit: stop`` (default) then
ends the program (zero torque until the end), ``skip`` waits ``gap`` s at zero torque and goes on
with the next segment. A non-finite position/velocity aborts likewise. After the end, the torque is 0.

Motion check (``motion_check``): an experiment that does not excite the joint (a faulted drive,
a stuck joint, a torque limit too low for the friction) ends with ABORT and a reason instead of a
record without motion. Each segment that must move the joint is checked when it ends: a plateau's
mean speed over its hold and the random program's RMS speed must reach ``fraction`` of their
targets (the share of time the velocity loop spent at its torque limit is named), a breakaway
ramp must break away; the open-loop chirp and presliding cycles are not checked on their own (a
chirp above breakaway may still move less than a count of a coarse encoder, presliding stays below
a count by design). A failed segment ends with ABORT instead of END; ``max_failures`` failed segments in a row
(0: never) stop the program. At the end, a program with moving segments must have moved the
joint ``travel_counts`` counts (of ``breakaway.resolution``) and reversed ``reversals`` times (a
reversal: ``travel_counts`` counts back from the last extreme); a program with checked segments
none of which moved the joint is not excited either. ``not_excited`` then holds the reason (None when excited).

Profiles (``PROFILES``): ``default`` (~115 s simulated, scaled for the ABB M19-S preset: static
friction 0.95 N*m, J = 0.0012 kg m^2) and ``quick`` (~27 s, tests/demo). Config keys given next to
``profile`` override the profile's values section by section.
"""

from __future__ import annotations

import copy
import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, NamedTuple

import numpy as np

from friction_ros.core.control.pid import Pid
from friction_ros.core.validation import (
    ParameterError,
    check_bool,
    check_choice,
    check_int,
    check_keys,
    check_real,
)

START, END, ABORT = 0, 1, 2
EVENT_NAMES = {START: "START", END: "END", ABORT: "ABORT"}
PROGRAM_NAMES = ("plateaus", "breakaway", "random", "chirp", "presliding", "sequence")
ON_LIMIT = ("stop", "skip")
#: exit codes of the experiment node (friction-experiment reports them): a safety limit stopped the
#: program / the joint was not excited (motion check)
EXIT_ABORTED, EXIT_NOT_EXCITED = 3, 4

#: The default profile (ABB M19-S scale). Every key is documented in the module docstring.
DEFAULTS: dict[str, Any] = {
    "program": "sequence",
    "dt": 0.001,
    "sequence": ["breakaway", "plateaus", "presliding", "random", "chirp"],
    "gap": 0.5,
    "bias": 0.0,
    "limits": {"max_travel": 100.0, "max_velocity": 40.0, "max_torque": 2.5, "on_limit": "stop"},
    "velocity_loop": {
        "p": 0.5,
        "i": 20.0,
        "torque_limit": 2.0,
        "inertia": 0.0,
        "damping": 0.0,
        "coulomb": 0.0,
        "remember_integral": True,
    },
    "plateaus": {
        "v_min": 0.1,
        "v_max": 10.0,
        "count": 6,
        "settle": 0.2,
        "hold": 0.5,
        "repeats": 3,
        "settle_travel": 0.0,
        "hold_travel": 0.0,
    },
    "breakaway": {
        "start": 0.6,
        "step": 0.002,
        "step_time": 0.008,
        "max": 1.5,
        "counts": 2,
        "resolution": 2.0 * math.pi / 60000.0,
        "preload_time": 0.3,
        "release": 0.3,
        "repeats": 3,
        "detection_lag": 0.0,
    },
    "random": {
        "duration": 50.0,
        "bandwidth": 4.0,
        "amplitude": 1.0,
        "low_level": 0.1,
        "envelope_period": 10.0,
        "seed": 3,
    },
    "chirp": {"duration": 15.0, "f0": 2.0, "f1": 10.0, "amplitude": 1.2, "final_amplitude": 0.5},
    "presliding": {"amplitudes": [0.3, 0.6, 0.85], "frequency": 1.0, "cycles": 3},
    "motion_check": {"fraction": 0.5, "max_failures": 3, "travel_counts": 10, "reversals": 1},
}

PROFILES: dict[str, dict[str, Any]] = {
    "default": {},
    "quick": {
        "gap": 0.3,
        "plateaus": {"v_min": 0.2, "v_max": 5.0, "count": 4, "repeats": 1},
        "breakaway": {"repeats": 1},
        "random": {"duration": 10.0},
        "chirp": {"duration": 4.0},
        "presliding": {"amplitudes": [0.4, 0.8], "cycles": 2},
    },
}
SECTIONS = (
    "limits",
    "velocity_loop",
    "plateaus",
    "breakaway",
    "random",
    "chirp",
    "presliding",
    "motion_check",
)


class Event(NamedTuple):
    """A segment marker (fields of friction_msgs/ExperimentEvent; ``time`` in program seconds)."""

    time: float
    program: str
    segment: str
    index: int
    event: int
    target: float = math.nan
    note: str = ""


# ------------------------------------------------------------------------------------------ config
def _merge(base: dict, over: Mapping) -> dict:
    out = copy.deepcopy(base)
    for k, v in over.items():
        if isinstance(v, Mapping) and isinstance(out.get(k), dict):
            out[k] = _merge(out[k], v)
        else:
            out[k] = copy.deepcopy(v)
    return out


def profile_defaults(profile: str = "default") -> dict[str, Any]:
    """The complete default config of ``profile`` (not yet merged with user values)."""
    return _merge(DEFAULTS, PROFILES[check_choice("profile", profile, PROFILES)])


def resolve_config(config: Mapping[str, Any] | None = None) -> dict[str, Any]:
    """Profile defaults merged with ``config`` (``profile`` key, default ``default``), validated.

    Returns the complete config (every key, checked ranges); raises ParameterError naming the key.
    """
    config = dict(config or {})
    profile = check_choice("profile", config.pop("profile", "default"), PROFILES)
    check_keys("excitation", config, list(DEFAULTS))
    for s in SECTIONS:
        if s in config:
            if not isinstance(config[s], Mapping):
                raise ParameterError(f"{s} = {config[s]!r} must be a mapping of {s} parameters")
            check_keys(s, config[s], DEFAULTS[s])
    cfg = _merge(_merge(DEFAULTS, PROFILES[profile]), config)
    cfg["profile"] = profile
    _validate(cfg)
    return cfg


def _validate(c: dict) -> None:
    check_choice("program", c["program"], PROGRAM_NAMES)
    check_real("dt", c["dt"], 1e-5, 0.1, unit="s")
    seq = c["sequence"]
    if isinstance(seq, str):
        seq = [s.strip() for s in seq.split(",") if s.strip()]
    if not isinstance(seq, (list, tuple)) or not seq:
        raise ParameterError(f"sequence = {seq!r} must be a non-empty list of programs")
    for i, name in enumerate(seq):
        check_choice(f"sequence[{i}]", name, [p for p in PROGRAM_NAMES if p != "sequence"])
    c["sequence"] = list(seq)
    check_real("gap", c["gap"], 0.0, 60.0, unit="s")
    lim = c["limits"]
    check_real(
        "bias", c["bias"], -lim["max_torque"], lim["max_torque"], hi_open=True, lo_open=True, unit="N*m"
    )
    check_real("limits.max_travel", lim["max_travel"], 0.0, lo_open=True, unit="rad", allow_inf=True)
    check_real("limits.max_velocity", lim["max_velocity"], 0.0, lo_open=True, unit="rad/s", allow_inf=True)
    check_real("limits.max_torque", lim["max_torque"], 0.0, lo_open=True, unit="N*m")
    check_choice("limits.on_limit", lim["on_limit"], ON_LIMIT)
    vl = c["velocity_loop"]
    check_real("velocity_loop.p", vl["p"], 0.0, unit="N*m*s/rad")
    check_real("velocity_loop.i", vl["i"], 0.0, unit="N*m/rad")
    check_real(
        "velocity_loop.torque_limit", vl["torque_limit"], 0.0, lim["max_torque"], lo_open=True, unit="N*m"
    )
    check_real("velocity_loop.inertia", vl["inertia"], 0.0, unit="kg*m^2")
    check_real("velocity_loop.damping", vl["damping"], 0.0, unit="N*m*s/rad")
    check_real("velocity_loop.coulomb", vl["coulomb"], 0.0, unit="N*m")
    check_bool("velocity_loop.remember_integral", vl["remember_integral"])
    p = c["plateaus"]
    check_real("plateaus.v_min", p["v_min"], 0.0, lo_open=True, unit="rad/s")
    check_real("plateaus.v_max", p["v_max"], p["v_min"], unit="rad/s")
    check_int("plateaus.count", p["count"], 1, 1000)
    check_real("plateaus.settle", p["settle"], 0.0, 60.0, unit="s")
    check_real("plateaus.hold", p["hold"], 0.0, 600.0, lo_open=True, unit="s")
    check_int("plateaus.repeats", p["repeats"], 1, 1000)
    check_real("plateaus.settle_travel", p["settle_travel"], 0.0, unit="rad")
    check_real("plateaus.hold_travel", p["hold_travel"], 0.0, unit="rad")
    if p["v_max"] >= lim["max_velocity"]:
        raise ParameterError(
            f"plateaus.v_max = {p['v_max']:g} is out of range: must be < limits.max_velocity "
            f"= {lim['max_velocity']:g} [rad/s]"
        )
    b = c["breakaway"]
    check_real("breakaway.max", b["max"], 0.0, lim["max_torque"], lo_open=True, unit="N*m")
    check_real("breakaway.start", b["start"], 0.0, b["max"], hi_open=True, unit="N*m")
    check_real("breakaway.step", b["step"], 0.0, b["max"], lo_open=True, unit="N*m")
    check_real("breakaway.step_time", b["step_time"], c["dt"], 60.0, unit="s")
    check_int("breakaway.counts", b["counts"], 1, 10000)
    check_real("breakaway.resolution", b["resolution"], 0.0, 1.0, lo_open=True, unit="rad")
    check_real("breakaway.preload_time", b["preload_time"], 0.0, 60.0, unit="s")
    check_real("breakaway.release", b["release"], 0.0, 60.0, unit="s")
    check_real("breakaway.detection_lag", b["detection_lag"], 0.0, unit="N*m")
    check_int("breakaway.repeats", b["repeats"], 1, 1000)
    r = c["random"]
    check_real("random.duration", r["duration"], 0.0, 3600.0, lo_open=True, unit="s")
    check_real("random.bandwidth", r["bandwidth"], 0.0, 0.45 / c["dt"], lo_open=True, unit="Hz")
    check_real("random.amplitude", r["amplitude"], 0.0, lim["max_velocity"], lo_open=True, unit="rad/s")
    check_real("random.low_level", r["low_level"], 0.0, 1.0)
    check_real("random.envelope_period", r["envelope_period"], 0.0, 3600.0, lo_open=True, unit="s")
    check_int("random.seed", r["seed"], 0, 2**32 - 1)
    ch = c["chirp"]
    check_real("chirp.duration", ch["duration"], 0.0, 3600.0, lo_open=True, unit="s")
    check_real("chirp.f0", ch["f0"], 0.0, 0.45 / c["dt"], lo_open=True, unit="Hz")
    check_real("chirp.f1", ch["f1"], ch["f0"], 0.45 / c["dt"], unit="Hz")
    check_real("chirp.amplitude", ch["amplitude"], 0.0, lim["max_torque"], lo_open=True, unit="N*m")
    check_real("chirp.final_amplitude", ch["final_amplitude"], 0.0, ch["amplitude"], unit="N*m")
    ps = c["presliding"]
    amps = ps["amplitudes"]
    if not isinstance(amps, (list, tuple)) or not amps:
        raise ParameterError(f"presliding.amplitudes = {amps!r} must be a non-empty list of torques [N*m]")
    ps["amplitudes"] = [
        check_real(f"presliding.amplitudes[{i}]", a, 0.0, lim["max_torque"], lo_open=True, unit="N*m")
        for i, a in enumerate(amps)
    ]
    check_real("presliding.frequency", ps["frequency"], 0.0, 0.45 / c["dt"], lo_open=True, unit="Hz")
    check_int("presliding.cycles", ps["cycles"], 1, 10000)
    mc = c["motion_check"]
    check_real("motion_check.fraction", mc["fraction"], 0.0, 1.0)
    check_int("motion_check.max_failures", mc["max_failures"], 0, 1000)
    check_int("motion_check.travel_counts", mc["travel_counts"], 0, 1_000_000)
    check_int("motion_check.reversals", mc["reversals"], 0, 1000)


# ------------------------------------------------------------------------------------------ segments
class _Ctx:
    """State shared by the segments of one program run: velocity loop, limits, start position."""

    def __init__(self, cfg: dict):
        vl = cfg["velocity_loop"]
        self.pid = Pid(
            p=vl["p"],
            i=vl["i"],
            u_clamp_max=vl["torque_limit"],
            u_clamp_min=-vl["torque_limit"],
            antiwindup_strategy="conditional_integration",
            prefix="velocity_loop",
        )
        self.inertia = vl["inertia"]
        self.damping = vl["damping"]
        self.coulomb = vl["coulomb"]
        self.remember = vl["remember_integral"]
        self.memory: dict[int, float] = {}
        self.last_torque = 0.0
        self.torque_limit = vl["torque_limit"]
        self.saturated = False  # the last velocity-loop command was at its torque limit
        mc = cfg["motion_check"]
        self.fraction = mc["fraction"]
        self.min_travel = mc["travel_counts"] * cfg["breakaway"]["resolution"]

    def velocity_control(self, v_ref: float, a_ref: float, velocity: float, dt: float) -> float:
        ff = self.inertia * a_ref + self.damping * v_ref + self.coulomb * float(np.sign(v_ref))
        out = self.pid.update(v_ref - velocity, dt, error_dot=0.0, offset=ff)
        self.saturated = abs(out.command) >= 0.999 * self.torque_limit
        return out.command


def _saturation_note(saturated: int, n: int, limit: float) -> str:
    if n and saturated >= 0.5 * n:
        return f"; the velocity loop was at its torque limit {limit:g} N*m for {100.0 * saturated / n:.0f} % of it"
    return ""


class Segment:
    """One part of a program. ``marked`` segments emit START/END events; rests do not."""

    marked = True

    def __init__(self, program: str, label: str, index: int, planned: float, target: float = math.nan):
        self.program, self.label, self.index = program, label, index
        self.planned = float(planned)
        self.target = float(target)
        self.start_note = ""

    def begin(self, ctx: _Ctx, position: float) -> None:  # noqa: B027 - optional hook
        pass

    def step(self, ctx: _Ctx, tau: float, position: float, velocity: float, dt: float) -> tuple[float, bool]:
        """Torque for local time ``tau`` and whether the segment is finished (then torque unused)."""
        raise NotImplementedError

    def end_target(self) -> float:
        return self.target

    def end_note(self) -> str:
        return ""

    #: whether the segment must move the joint (see the module docstring's motion check)
    checked = False

    def motion_failure(self, ctx: _Ctx) -> str | None:
        """Why the segment did not move the joint as it must (None: it did, or it is not checked)."""
        return None


class Rest(Segment):
    marked = False

    def __init__(self, duration: float):
        super().__init__("rest", "rest", 0, duration)

    def step(self, ctx, tau, position, velocity, dt):
        return 0.0, tau >= self.planned


class Release(Segment):
    """Torque ramped linearly from its last value to zero over the first half, then zero: a step
    release would set the joint ringing on its (nearly undamped) presliding stiffness and the
    oscillation would fake motion counts in the next ramp."""

    marked = False

    def __init__(self, duration: float):
        super().__init__("rest", "release", 0, duration)
        self._from = 0.0

    def begin(self, ctx, position):
        self._from = ctx.last_torque

    def step(self, ctx, tau, position, velocity, dt):
        if tau >= self.planned:
            return 0.0, True
        half = 0.5 * self.planned
        return (self._from * (1.0 - tau / half) if tau < half else 0.0), False


class Plateau(Segment):
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
            + _saturation_note(self._sat, self._n, ctx.torque_limit)
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
            + _saturation_note(self._sat, self._n, ctx.torque_limit)
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


# ------------------------------------------------------------------------------------------ builders
def _plateau_segments(c: dict) -> list[Segment]:
    p = c["plateaus"]
    speeds = np.geomspace(p["v_max"], p["v_min"], p["count"]) if p["count"] > 1 else np.array([p["v_min"]])
    segs: list[Segment] = []
    i = 0
    for _ in range(p["repeats"]):
        for s in speeds:  # high to low: the remembered integral follows the friction curve
            settle = max(p["settle"], p["settle_travel"] / float(s))
            hold = max(p["hold"], p["hold_travel"] / float(s))
            for sgn in (1.0, -1.0):
                segs.append(Plateau(i, sgn * float(s), settle, hold))
                i += 1
    return segs


def _breakaway_segments(c: dict) -> list[Segment]:
    b = c["breakaway"]
    segs: list[Segment] = []
    i = 0
    for _ in range(b["repeats"]):
        for d in (1, -1):
            segs.append(BreakawayRamp(i, d, b))
            segs.append(Release(b["release"]))
            i += 1
    return segs


def random_velocity(c: dict) -> np.ndarray:
    """Seed 003 excitation: 4 Hz band-limited noise times the 3-term rectangular envelope [rad/s]."""
    from scipy.signal import butter, sosfiltfilt

    r, dt = c["random"], c["dt"]
    n = int(round(r["duration"] / dt))
    rng = np.random.default_rng(r["seed"])
    sos = butter(4, r["bandwidth"], fs=1.0 / dt, output="sos")
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


def _random_segments(c: dict) -> list[Segment]:
    v = random_velocity(c)
    return [VelocityProfile("random", "random", 0, v, c["dt"], c["random"]["amplitude"])]


def _chirp_segments(c: dict) -> list[Segment]:
    ch = c["chirp"]
    T, f0, f1, a0, a1 = ch["duration"], ch["f0"], ch["f1"], ch["amplitude"], ch["final_amplitude"]

    def fn(t: float) -> float:
        amp = a0 + (a1 - a0) * t / T
        return amp * math.sin(2 * math.pi * (f0 * t + 0.5 * (f1 - f0) / T * t * t))

    return [TorqueProfile("chirp", "chirp", 0, T, fn, a0)]


def _presliding_segments(c: dict) -> list[Segment]:
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


_BUILDERS = {
    "plateaus": _plateau_segments,
    "breakaway": _breakaway_segments,
    "random": _random_segments,
    "chirp": _chirp_segments,
    "presliding": _presliding_segments,
}


@dataclass
class Status:
    """Snapshot for progress displays and diagnostics."""

    time: float
    total: float
    progress: float
    program: str
    segment: str
    segment_number: int
    segments: int
    done: bool
    aborted: bool


class ExcitationProgram:
    """State machine over planned segments; see the module docstring."""

    def __init__(self, config: Mapping[str, Any] | None = None):
        self.config = resolve_config(config)
        c = self.config
        names = c["sequence"] if c["program"] == "sequence" else [c["program"]]
        segs: list[Segment] = []
        for k, name in enumerate(names):
            if k > 0 and c["gap"] > 0:
                segs.append(Rest(c["gap"]))
            segs += _BUILDERS[name](c)
        self.name = c["program"]
        self.segments = segs
        self.total_duration = float(sum(s.planned for s in segs))
        self.marked_count = sum(1 for s in segs if s.marked)
        lim = c["limits"]
        self.max_travel, self.max_velocity, self.max_torque = (
            lim["max_travel"],
            lim["max_velocity"],
            lim["max_torque"],
        )
        self.on_limit = lim["on_limit"]
        self.reset()

    def reset(self) -> None:
        self.ctx = _Ctx(self.config)
        self._i = 0
        self._seg_t0: float | None = None
        self._t0: float | None = None
        self._t_prev: float | None = None
        self._pos0 = 0.0
        self._done_planned = 0.0
        self._last_torque = 0.0
        self._skip_until: float | None = None
        self.done = False
        self.aborted = False
        self.abort_reasons: list[str] = []
        self.breakaways: list[tuple[str, float]] = []
        self.t = 0.0
        self.not_excited: str | None = None
        self._failures = 0  # checked segments in a row without their motion
        self._passed = 0  # checked segments that moved the joint as they must
        self._lo = self._hi = self._ext = math.nan  # position range and last extreme
        self._dir = 0  # direction of the current excursion (+1/-1, 0 before the first)
        self.reversals = 0

    # ------------------------------------------------------------------------------ status
    @property
    def current(self) -> Segment | None:
        return self.segments[self._i] if self._i < len(self.segments) else None

    @property
    def progress(self) -> float:
        if self.done:
            return 1.0
        seg = self.current
        inside = 0.0
        if seg is not None and self._seg_t0 is not None:
            inside = min(max(self.t - self._seg_t0, 0.0), seg.planned)
        return min((self._done_planned + inside) / max(self.total_duration, 1e-12), 1.0)

    def status(self) -> Status:
        seg = self.current
        number = sum(1 for s in self.segments[: self._i + 1] if s.marked)
        return Status(
            self.t,
            self.total_duration,
            self.progress,
            seg.program if seg is not None else "",
            seg.label if seg is not None else "",
            number,
            self.marked_count,
            self.done,
            self.aborted,
        )

    # ------------------------------------------------------------------------------ stepping
    def _finish_segment(self, t: float) -> None:
        seg = self.segments[self._i]
        self._done_planned += seg.planned
        self._i += 1
        self._seg_t0 = None
        if self._i >= len(self.segments):
            self.done = True

    def _abort(self, t: float, reason: str, events: list[Event]) -> None:
        seg = self.current
        self.aborted = True
        self.abort_reasons.append(reason)
        if seg is not None and seg.marked and self._seg_t0 is not None:
            events.append(Event(t, seg.program, seg.label, seg.index, ABORT, seg.target, reason))
        elif seg is not None:
            events.append(Event(t, self.name, seg.label, seg.index, ABORT, math.nan, reason))
        self.ctx.pid.reset(0.0)
        if self.on_limit == "stop" or seg is None:
            self._done_planned = self.total_duration
            self._i = len(self.segments)
            self.done = True
        else:
            self._finish_segment(t)
            self._skip_until = t + self.config["gap"]

    def _track_motion(self, position: float) -> None:
        """Position range and reversals (``travel_counts`` counts back from the last extreme)."""
        if not math.isfinite(position):
            return
        if math.isnan(self._lo):
            self._lo = self._hi = self._ext = position
            return
        self._lo, self._hi = min(self._lo, position), max(self._hi, position)
        thr = max(self.ctx.min_travel, 1e-12)
        d = position - self._ext
        if self._dir == 0:
            if abs(d) >= thr:
                self._dir, self._ext = (1 if d > 0 else -1), position
        elif self._dir * d > 0:
            self._ext = position
        elif -self._dir * d >= thr:
            self.reversals += 1
            self._dir, self._ext = -self._dir, position

    def _stop_not_excited(self, reason: str, events: list[Event]) -> None:
        self.not_excited = f"joint not excited: {reason}"
        events.append(Event(self.t, self.name, "program", 0, ABORT, math.nan, self.not_excited))
        self.abort_reasons.append(self.not_excited)
        self._done_planned = self.total_duration
        self._i = len(self.segments)
        self.done = True

    def _final_motion_check(self, events: list[Event]) -> None:
        """Whole-program check when the program completes (module docstring's motion check)."""
        checked = [s for s in self.segments if s.checked]
        if checked and self._passed == 0:
            self._stop_not_excited(
                f"none of the {len(checked)} segments that must move the joint did "
                f"(last: {self.abort_reasons[-1] if self.abort_reasons else 'no motion'})",
                events,
            )
            return
        travel = [s for s in checked if not isinstance(s, BreakawayRamp)]
        mc = self.config["motion_check"]
        if not travel or mc["travel_counts"] == 0:
            return
        moved = (self._hi - self._lo) if math.isfinite(self._hi - self._lo) else 0.0
        if moved < self.ctx.min_travel or self.reversals < mc["reversals"]:
            self._stop_not_excited(
                f"over the whole program the joint moved {moved:.4g} rad and reversed {self.reversals} "
                f"time(s); needed: {self.ctx.min_travel:.4g} rad (motion_check.travel_counts = "
                f"{mc['travel_counts']} counts of breakaway.resolution) and motion_check.reversals = "
                f"{mc['reversals']}",
                events,
            )

    def _check_limits(self, position: float, velocity: float) -> str | None:
        if not (math.isfinite(position) and math.isfinite(velocity)):
            return f"joint state not finite (position {position}, velocity {velocity})"
        travel = position - self._pos0
        if abs(travel) > self.max_travel:
            return (
                f"position limit: travel {travel:+.4g} rad from the start exceeds "
                f"limits.max_travel = {self.max_travel:g} rad"
            )
        if abs(velocity) > self.max_velocity:
            return f"velocity limit: |{velocity:+.4g}| rad/s exceeds limits.max_velocity = {self.max_velocity:g} rad/s"
        return None

    def update(self, t: float, position: float, velocity: float) -> tuple[float, list[Event]]:
        """Torque [N*m] to apply until the next period and the events of this period."""
        events: list[Event] = []
        t = float(t)
        if self._t_prev is not None and t <= self._t_prev:
            return self._last_torque, events  # duplicate/stale sample: same answer, no recompute
        dt = self.config["dt"] if self._t_prev is None else t - self._t_prev
        self._t_prev = t
        if self._t0 is None:
            self._t0 = t
            self._pos0 = float(position) if math.isfinite(position) else 0.0
        self.t = t - self._t0
        bias = self.config["bias"]
        if self.done:
            stopped = (self.aborted and self.on_limit == "stop") or self.not_excited is not None
            self._last_torque = 0.0 if stopped else bias
            return self._last_torque, events
        self._track_motion(float(position))
        reason = self._check_limits(float(position), float(velocity))
        if reason is not None:
            self._abort(self.t, reason, events)
            self._last_torque = 0.0
            return 0.0, events
        if self._skip_until is not None:
            if self.t < self._skip_until:
                self._last_torque = bias
                return bias, events
            self._skip_until = None
        torque = 0.0
        while not self.done:
            seg = self.segments[self._i]
            if self._seg_t0 is None:
                self._seg_t0 = self.t
                seg.begin(self.ctx, position)
                if seg.marked:
                    events.append(
                        Event(self.t, seg.program, seg.label, seg.index, START, seg.target, seg.start_note)
                    )
            torque, finished = seg.step(self.ctx, self.t - self._seg_t0, position, velocity, dt)
            if not finished:
                break
            failure = seg.motion_failure(self.ctx) if seg.checked else None
            if seg.checked:
                self._failures = self._failures + 1 if failure else 0
                self._passed += failure is None
            if seg.marked:
                if failure:
                    events.append(
                        Event(self.t, seg.program, seg.label, seg.index, ABORT, seg.target, failure)
                    )
                    self.abort_reasons.append(failure)
                else:
                    events.append(
                        Event(
                            self.t, seg.program, seg.label, seg.index, END, seg.end_target(), seg.end_note()
                        )
                    )
                    if isinstance(seg, BreakawayRamp):
                        self.breakaways.append((seg.label, seg.torque))
            self._finish_segment(self.t)
            torque = 0.0
            limit = self.config["motion_check"]["max_failures"]
            if failure and limit and self._failures >= limit:
                self._stop_not_excited(
                    f"{self._failures} segments in a row without the expected motion "
                    f"(motion_check.max_failures = {limit}; last: {failure})",
                    events,
                )
                self._last_torque = self.ctx.last_torque = 0.0
                return 0.0, events
            if self.done:
                self._final_motion_check(events)
                if self.not_excited is not None:
                    self._last_torque = self.ctx.last_torque = 0.0
                    return 0.0, events
        if not math.isfinite(torque) or abs(torque + bias) > self.max_torque:
            self._abort(
                self.t,
                f"torque limit: command {torque + bias:+.4g} N*m exceeds limits.max_torque = {self.max_torque:g} N*m",
                events,
            )
            self._last_torque = self.ctx.last_torque = 0.0
            return 0.0, events
        self.ctx.last_torque = torque
        self._last_torque = torque + bias
        return torque + bias, events


def make_program(config: Mapping[str, Any] | None = None) -> ExcitationProgram:
    """Build an :class:`ExcitationProgram` from a config dict (``program``, ``profile``, sections)."""
    return ExcitationProgram(config)
