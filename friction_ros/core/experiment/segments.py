"""Segments, the parts an excitation program is made of, and the state they share.

A segment returns a torque for its local time and says when it is finished; ``marked`` segments
emit START/END events, ``checked`` ones must move the joint (the motion check of
:mod:`friction_ros.core.experiment.excitation`). Rests and releases sit between the marked parts.
"""

from __future__ import annotations

import math

import numpy as np

from friction_ros.core.control.pid import Pid


# ------------------------------------------------------------------------------------------ segments
class SegmentContext:
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


def saturation_note(saturated: int, n: int, limit: float) -> str:
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

    def begin(self, ctx: SegmentContext, position: float) -> None:  # noqa: B027 - optional hook
        pass

    def step(
        self, ctx: SegmentContext, tau: float, position: float, velocity: float, dt: float
    ) -> tuple[float, bool]:
        """Torque for local time ``tau`` and whether the segment is finished (then torque unused)."""
        raise NotImplementedError

    def end_target(self) -> float:
        return self.target

    def end_note(self) -> str:
        return ""

    #: whether the segment must move the joint (see the module docstring's motion check)
    checked = False

    def motion_failure(self, ctx: SegmentContext) -> str | None:
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
