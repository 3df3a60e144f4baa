"""Identification experiments on an arm: one excitation program per joint (pure core, no rclpy).

Each joint has its own :class:`~friction_ros.core.experiment.excitation.ExcitationProgram` (its own
config: program, sizing, limits, ``bias``). One call per control period with every joint's state::

    arm = ArmExperiment(["j1", "j2"], [cfg_j1, cfg_j2], sequence="one_at_a_time", gap=0.5)
    torques, events = arm.update(t, positions, velocities)   # events: [(joint index, Event)]

``sequence``:

``one_at_a_time``  the joints run their programs one after another, in the order given, with
                   ``gap`` s between two joints; the joints not being excited are held by a PD hold.
``together``       every joint runs its program from the start; a joint whose program is over is
                   held until the last one ends.

PD hold (:func:`hold_gains`): ``bias + clamp(K_p (q_ref - q) - K_d v, +-limit)`` with the gains of
the joint's velocity loop, which is the tracking design's PD law on the velocity error's integral
(:mod:`~friction_ros.core.experiment.tracking_design`: the loop's ``p`` is the PD's ``K_d``, its
``i`` the PD's ``K_p``), unless ``hold_p`` / ``hold_d`` are given; ``limit`` is the velocity loop's
``torque_limit`` within ``limits.max_torque - |bias|``. ``q_ref``: the joint's position at the start
of the experiment (a joint that waits for its turn) or where its own program ended (a joint that
is done). A held joint is checked against its limits every period: travel from its position at the
start of the experiment (``limits.max_travel``), speed (``limits.max_velocity``), finite state.

Safety: a held joint leaving its limits, a joint whose program a safety limit stopped
(``limits.on_limit: stop``) or a joint that was not excited (motion check) stops the whole
experiment: every running program ends with an ABORT for its open segment, every joint gets zero
torque from then on, ``abort_reasons[-1]`` names the joint first (``joint j2: position limit:
...``; ``not_excited``: ``joint not excited: joint j2: ...``). A held joint's ABORT event is ``program`` ``arm``, segment
``hold``. Every ABORT a joint's program emits has its reason prefixed with the joint; the limits in
a reason are named by the program's ``names`` (``limits.j2.max_travel`` for a joint's own value).
After a completed experiment every joint is held
(the end tail).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

from friction_ros.core.experiment.events import ABORT, Event
from friction_ros.core.experiment.excitation import ExcitationProgram, Status
from friction_ros.core.validation import ParameterError

SEQUENCES = ("one_at_a_time", "together")
#: ``program`` of the events the arm itself emits (a held joint left its limits)
ARM_PROGRAM = "arm"
NOT_EXCITED = "joint not excited: "


@dataclass(frozen=True)
class Hold:
    """PD hold of one joint: ``bias + clamp(p (q_ref - q) - d v, +-limit)`` [N*m]."""

    p: float
    d: float
    limit: float
    bias: float

    def torque(self, ref: float, position: float, velocity: float) -> float:
        u = self.p * (ref - position) - self.d * (velocity if math.isfinite(velocity) else 0.0)
        return self.bias + min(max(u, -self.limit), self.limit)


def hold_gains(config: Mapping[str, Any], p: float = 0.0, d: float = 0.0) -> Hold:
    """The PD hold of a joint with program ``config`` (resolved): ``p``/``d`` when > 0, else the
    velocity loop's ``i``/``p`` (module docstring)."""
    vl, lim = config["velocity_loop"], config["limits"]
    bias = float(config["bias"])
    limit = max(0.0, min(float(vl["torque_limit"]), float(lim["max_torque"]) - abs(bias)))
    return Hold(float(p) if p > 0 else float(vl["i"]), float(d) if d > 0 else float(vl["p"]), limit, bias)


def _describe(joint: str, text: str) -> str:
    return f"joint {joint}: {text}"


class ArmExperiment:
    """Excitation programs of several joints, sequenced; see the module docstring."""

    def __init__(
        self,
        joints: Sequence[str],
        programs: Sequence[ExcitationProgram],
        sequence: str = "one_at_a_time",
        gap: float = 0.5,
        holds: Sequence[Hold] | None = None,
    ):
        if sequence not in SEQUENCES:
            raise ParameterError(
                f"joint_sequence = {sequence!r} is not allowed: must be one of {', '.join(SEQUENCES)}"
            )
        if len(programs) != len(joints) or not joints:
            raise ParameterError(f"{len(programs)} programs for {len(joints)} joints")
        self.joints = list(joints)
        self.programs = list(programs)
        self.sequence = sequence
        self.gap = float(gap)
        self.holds = list(holds) if holds is not None else [hold_gains(p.config) for p in self.programs]
        n = len(self.joints)
        durations = [p.total_duration for p in self.programs]
        if sequence == "one_at_a_time":
            self.total_duration = float(sum(durations) + self.gap * (n - 1))
        else:
            self.total_duration = float(max(durations))
        self.marked_count = sum(p.marked_count for p in self.programs)
        self.name = "+".join(dict.fromkeys(p.name for p in self.programs))
        self._t0: float | None = None
        self._t_prev: float | None = None
        self.t = 0.0
        self._pos0 = [0.0] * n
        self._ref = [0.0] * n
        self._running: list[int] = []
        self._next = 0  # one_at_a_time: the next joint to start
        self._next_start = 0.0  # ... and when (experiment time)
        self._started = [False] * n
        self._finished = [False] * n
        self._last = [0.0] * n
        self.done = False
        self.aborted = False
        self.stopped = False  # done by a safety limit or the motion check: zero torque
        self.abort_reasons: list[str] = []
        self.not_excited: str | None = None
        self.failed_joint: str | None = None
        self.on_limit = "stop"  # the arm stops on any joint's safety limit (node compatibility)

    # ------------------------------------------------------------------------------ status
    @property
    def running(self) -> list[str]:
        return [self.joints[i] for i in self._running]

    @property
    def progress(self) -> float:
        if self.done:
            return 1.0
        if self.sequence == "together":
            return min(self.t / max(self.total_duration, 1e-12), 1.0)
        done = sum(p.total_duration + self.gap for p, f in zip(self.programs, self._finished) if f)
        inside = sum(p.progress * p.total_duration for i, p in enumerate(self.programs) if i in self._running)
        return min((done + inside) / max(self.total_duration, 1e-12), 1.0)

    def status(self) -> Status:
        if self._running:
            i = self._running[0]
            st = self.programs[i].status()
            program, segment = f"{self.joints[i]}:{st.program}", st.segment
        else:
            program, segment = "", "hold" if not self.done else ""
        number = sum(
            p.status().segment_number if i in self._running else (p.marked_count if self._finished[i] else 0)
            for i, p in enumerate(self.programs)
        )
        return Status(
            self.t, self.total_duration, self.progress, program, segment, number, self.marked_count,
            self.done, self.aborted,
        )  # fmt: skip

    # ------------------------------------------------------------------------------ stepping
    def _stop(
        self, reason: str, joint: int, events: list[tuple[int, Event]], not_excited: bool = False
    ) -> None:
        """Stop every joint (module docstring's safety); ``joint``: the one that caused it."""
        self.failed_joint = self.joints[joint]
        for i in self._running:
            if i != joint:
                note = f"stopped: {reason}"
                events += [(i, e._replace(time=self.t)) for e in self.programs[i].stop(note)]
        self._running = []
        self.done = self.stopped = True
        self.aborted = not not_excited
        if not_excited:
            self.not_excited = reason
        self.abort_reasons.append(reason)
        self._last = [0.0] * len(self.joints)

    def _held_violation(self, i: int, position: float, velocity: float) -> str | None:
        lim, names = self.programs[i].config["limits"], self.programs[i].names
        if not (math.isfinite(position) and math.isfinite(velocity)):
            return f"joint state not finite while held (position {position}, velocity {velocity})"
        travel = position - self._pos0[i]
        if abs(travel) > lim["max_travel"]:
            return (
                f"position limit while held: travel {travel:+.4g} rad from the start exceeds "
                f"{names('limits.max_travel')} = {lim['max_travel']:g} rad"
            )
        if abs(velocity) > lim["max_velocity"]:
            return (
                f"velocity limit while held: |{velocity:+.4g}| rad/s exceeds "
                f"{names('limits.max_velocity')} = {lim['max_velocity']:g} rad/s"
            )
        return None

    def update(
        self, t: float, positions: Sequence[float], velocities: Sequence[float]
    ) -> tuple[list[float], list[tuple[int, Event]]]:
        """Every joint's torque [N*m] until the next period, and the events of this period as
        ``(joint index, event)`` (event times in experiment seconds)."""
        events: list[tuple[int, Event]] = []
        t = float(t)
        if self._t_prev is not None and t <= self._t_prev:
            return list(self._last), events  # duplicate/stale sample: same answer
        self._t_prev = t
        n = len(self.joints)
        q = [float(x) for x in positions]
        v = [float(x) for x in velocities]
        if self._t0 is None:
            self._t0 = t
            self._pos0 = [x if math.isfinite(x) else 0.0 for x in q]
            self._ref = list(self._pos0)
            if self.sequence == "together":
                self._running = list(range(n))
                self._started = [True] * n
        self.t = t - self._t0
        if self.done:
            self._last = (
                [0.0] * n
                if self.stopped
                else [self.holds[i].torque(self._ref[i], q[i], v[i]) for i in range(n)]
            )
            return list(self._last), events
        # held joints must stay within their limits
        for i in range(n):
            if i in self._running:
                continue
            why = self._held_violation(i, q[i], v[i])
            if why is not None:
                reason = _describe(self.joints[i], why)
                events.append((i, Event(self.t, ARM_PROGRAM, "hold", 0, ABORT, math.nan, reason)))
                self._stop(reason, i, events)
                return list(self._last), events
        if (
            self.sequence == "one_at_a_time"
            and not self._running
            and self._next < n
            and self.t >= self._next_start
        ):
            self._running = [self._next]
            self._started[self._next] = True
            self._next += 1
        torques = [0.0] * n
        for i in list(self._running):
            prog = self.programs[i]
            tau, evs = prog.update(t, q[i], v[i])
            for e in evs:  # an ABORT's reason names the joint (and its per-joint parameter)
                note = _describe(self.joints[i], e.note) if e.event == ABORT and e.note else e.note
                events.append((i, e._replace(time=self.t, note=note)))
            torques[i] = tau
            if not prog.done:
                continue
            if prog.not_excited is not None:
                rest = prog.not_excited.removeprefix(NOT_EXCITED)
                reason = NOT_EXCITED + _describe(self.joints[i], rest)
                self._stop(reason, i, events, not_excited=True)
                return list(self._last), events
            if prog.aborted and prog.on_limit == "stop":
                self._stop(_describe(self.joints[i], prog.abort_reasons[-1]), i, events)
                return list(self._last), events
            self._running.remove(i)  # completed: held where it ended
            self._finished[i] = True
            self._ref[i] = q[i] if math.isfinite(q[i]) else self._ref[i]
            self._next_start = self.t + self.gap
        for i in range(n):
            if i not in self._running:
                torques[i] = self.holds[i].torque(self._ref[i], q[i], v[i])
        if all(self._finished):
            self.done = True
        self._last = torques
        return list(torques), events
