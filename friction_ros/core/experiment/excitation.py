"""Excitation programs of the identification experiment runner (pure core: numpy/scipy, no rclpy).

A program drives a joint directly with a joint torque [N*m], one call per control period::

    prog = make_program({"program": "sequence", "profile": "quick"})
    torque, events = prog.update(t, position, velocity)      # t [s], position [rad], velocity [rad/s]
    prog.done, prog.progress, prog.total_duration, prog.aborted

Programs (``excitation_config.PROGRAM_NAMES``), each a list of segments planned upfront (``total_duration`` is known
before the run; a breakaway ramp counts with its longest possible duration):

``plateaus``   AI friction chapter B.3 exp. 2: constant-velocity plateaus at ``count`` log-spaced speeds in
               [v_min, v_max], both directions (+v then -v at each speed, so the joint returns), each
               ``settle`` (transient, discarded: AI friction chapter 0.2 s) + ``hold`` s, ``repeats`` times
               (AI friction chapter: 5). Tracked by the internal velocity PI (``velocity_loop``, with the
               feed-forward ``inertia a + damping v + coulomb sgn(v)`` of the reference). A plateau at
               speed ``v`` settles at least ``settle_travel / v`` and holds at least ``hold_travel / v``
               seconds (default 0: fixed times), so slow plateaus cover a distance: enough encoder
               counts, and several stick-slip cycles below the Stribeck velocity.
``breakaway``  AI friction chapter B.3 exp. 1: open-loop torque ramp, first a preload to ``start`` (ramped over 60 % of
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
``random``     ABB M19-S paper A.3: band-limited random velocity (Butterworth ``bandwidth`` Hz, seeded) under
               the envelope made of the first three non-zero Fourier terms of a rectangle of period
               ``envelope_period`` (levels ``low_level`` and 1) times ``amplitude`` (rad/s, RMS at the
               high level), ``duration`` s (ABB M19-S paper: 50 s), tracked by the velocity PI.
``chirp``      GA friction thesis 2002 sec. 4.1: torque chirp, linear frequency sweep ``f0`` -> ``f1`` Hz (low to
               high) with an amplitude decreasing linearly from ``amplitude`` to ``final_amplitude``
               N*m (motion stops near the end because the amplitude falls below breakaway).
``presliding`` small-amplitude torque cycles (sine, ``frequency`` Hz, ``cycles`` per amplitude) below
               the breakaway torque: presliding hysteresis (virgin curve, Masing loops).
``sequence``   the programs named in ``sequence``, separated by ``gap`` s of zero torque.

Events: :class:`~friction_ros.core.experiment.events.Event` (time, program, segment label, index within the program, START/END/ABORT,
target, note), the fields of ``friction_msgs/ExperimentEvent``. A plateau START note carries
``settle=<s>`` so readers discard the same transient.

``bias`` [N*m] is added to every torque the program commands, rests and the end included (not
after an abort): the torque that holds a constant load such as gravity, so the ramps and cycles
are centred on it (``friction_ros.core.experiment.experiment_sizing`` sets it to minus the load).

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

Profiles (``excitation_config.PROFILES``): ``default`` (~115 s simulated, scaled for the ABB M19-S preset: static
friction 0.95 N*m, J = 0.0012 kg m^2) and ``quick`` (~27 s, tests/demo). Config keys given next to
``profile`` override the profile's values section by section.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from friction_ros.core.config import Names
from friction_ros.core.experiment.events import ABORT, END, START, Event
from friction_ros.core.experiment.excitation_config import NAMES, resolve_config
from friction_ros.core.experiment.segments import Rest, Segment, SegmentContext
from friction_ros.core.experiment.torque_programs import (
    BreakawayRamp,
    breakaway_segments,
    chirp_segments,
    presliding_segments,
)
from friction_ros.core.experiment.velocity_programs import plateau_segments, random_segments

#: exit codes of the experiment node (friction-experiment reports them): a safety limit stopped the
#: program / the joint was not excited (motion check)
EXIT_ABORTED, EXIT_NOT_EXCITED = 3, 4

_BUILDERS = {
    "plateaus": plateau_segments,
    "breakaway": breakaway_segments,
    "random": random_segments,
    "chirp": chirp_segments,
    "presliding": presliding_segments,
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

    def __init__(self, config: Mapping[str, Any] | None = None, names: Names = NAMES):
        #: the parameter names in messages (``names("limits.max_travel")``; a joint's on an arm)
        self.names = names
        self.config = resolve_config(config, names)
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
        self.ctx = SegmentContext(self.config)
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

    def stop(self, reason: str) -> list[Event]:
        """End the program from outside (on an arm: another joint left its limits): an ABORT event
        for the segment under way, naming ``reason``; the program is done and, like a program a
        safety limit stopped, commands zero torque from now on."""
        events: list[Event] = []
        if self.done:
            return events
        seg = self.current
        self.aborted = True
        self.abort_reasons.append(reason)
        if seg is not None and seg.marked and self._seg_t0 is not None:
            events.append(Event(self.t, seg.program, seg.label, seg.index, ABORT, seg.target, reason))
        self.ctx.pid.reset(0.0)
        self.on_limit = "stop"
        self._done_planned = self.total_duration
        self._i = len(self.segments)
        self.done = True
        self._last_torque = self.ctx.last_torque = 0.0
        return events

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
                f"{self.names('limits.max_travel')} = {self.max_travel:g} rad"
            )
        if abs(velocity) > self.max_velocity:
            return (
                f"velocity limit: |{velocity:+.4g}| rad/s exceeds "
                f"{self.names('limits.max_velocity')} = {self.max_velocity:g} rad/s"
            )
        return None

    def update(self, t: float, position: float, velocity: float) -> tuple[float, list[Event]]:
        """Torque [N*m] to apply until the next period and the events of this period."""
        events: list[Event] = []
        t = float(t)
        if self._t_prev is not None and t <= self._t_prev:
            return self._last_torque, events  # duplicate/stale sample: same answer, no recompute
        dt = self.config["control_period"] if self._t_prev is None else t - self._t_prev
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
                f"torque limit: command {torque + bias:+.4g} N*m exceeds "
                f"{self.names('limits.max_torque')} = {self.max_torque:g} N*m",
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
