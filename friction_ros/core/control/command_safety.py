"""What keeps a joint command finite and inside the joint's limits, whatever comes in.

Three parts, used by :class:`~friction_ros.core.control.controller.CompensatingController` and the
compensating_controller node:

* :class:`JointLimits`: the joint's torque (or force) limit ``effort_limit`` and its position,
  velocity and acceleration limits (REP-103 units of the joint: rad, rad/s, rad/s^2, N*m; m, m/s,
  m/s^2, N). The command is clamped to ``[-effort_limit, effort_limit]`` (and to ``u_clamp_min/max``
  when they are tighter).
* :func:`check_reference_sample` / :func:`check_trajectory`: references are checked at the door: a
  sample that is not finite or lies beyond a limit is refused (a trajectory as a whole, with the
  first offending sample named); velocities implied by a trajectory's positions count too.
* :class:`TermGuard`: a non-finite intermediate (reference, friction feedforward or feedback,
  observer, load term, feedback law) is dropped for that period, the state that produced it is
  reset by the caller, and the event is recorded once per term with its first value, so that the
  node logs it once when it starts and once when it clears and diagnostics report ERROR meanwhile.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field

from friction_ros.core.input_gate import PLAUSIBLE_EFFORT
from friction_ros.core.validation import ParameterError

#: the largest gain (N*m/rad, N/m, ... per unit of error) or limit a run-time parameter may take:
#: beyond any physical joint, and far enough below float overflow that ``gain * error`` stays finite
PLAUSIBLE_GAIN = 1.0e12


@dataclass(frozen=True)
class JointLimits:
    """A joint's limits; ``inf`` = no limit (the effort limit must be finite on a running node)."""

    effort_limit: float = math.inf
    position_min: float = -math.inf
    position_max: float = math.inf
    velocity_limit: float = math.inf
    acceleration_limit: float = math.inf

    def __post_init__(self) -> None:
        for name in ("effort_limit", "velocity_limit", "acceleration_limit"):
            x = getattr(self, name)
            if not (x > 0.0):  # also refuses nan
                raise ParameterError(f"{name} = {x!r} is out of range: must be > 0")
        if math.isfinite(self.effort_limit) and self.effort_limit > PLAUSIBLE_EFFORT:
            raise ParameterError(
                f"effort_limit = {self.effort_limit:g} is out of range: must be in (0, {PLAUSIBLE_EFFORT:g}] "
                "(the joint's torque or force limit)"
            )
        if not (self.position_min < self.position_max):
            raise ParameterError(
                f"position_min = {self.position_min!r} is out of range: must be < position_max "
                f"({self.position_max!r})"
            )

    def command_bounds(self, u_min: float, u_max: float) -> tuple[float, float]:
        """The command interval: ``[max(u_min, -effort_limit), min(u_max, effort_limit)]``."""
        return max(u_min, -self.effort_limit), min(u_max, self.effort_limit)


def check_reference_sample(limits: JointLimits, pos: float, vel: float, acc: float) -> str:
    """'' when the reference sample is finite and inside the limits, else the reason."""
    for name, x in (("position", pos), ("velocity", vel), ("acceleration", acc)):
        if not math.isfinite(x):
            return f"reference {name} {x!r} is not finite"
    if not limits.position_min <= pos <= limits.position_max:
        return (
            f"reference position {pos:.6g} is outside the joint's limits "
            f"[{limits.position_min:g}, {limits.position_max:g}]"
        )
    if abs(vel) > limits.velocity_limit:
        return f"reference velocity {vel:.6g} exceeds the joint's velocity limit {limits.velocity_limit:g}"
    if abs(acc) > limits.acceleration_limit:
        return (
            f"reference acceleration {acc:.6g} exceeds the joint's acceleration limit "
            f"{limits.acceleration_limit:g}"
        )
    return ""


def check_trajectory(
    limits: JointLimits,
    times: Sequence[float],
    positions: Sequence[float],
    velocities: Sequence[float] | None = None,
    accelerations: Sequence[float] | None = None,
) -> None:
    """Refuse a trajectory as a whole (ParameterError naming the first bad sample) when a sample is
    not finite, beyond a limit, or when the velocity implied between two samples,
    ``(q[k+1] - q[k]) / (t[k+1] - t[k])``, exceeds the velocity limit."""
    n = len(positions)
    for k in range(n):
        t = times[k] if k < len(times) else math.nan
        if not math.isfinite(t):
            raise ParameterError(f"point {k}: time_from_start {t!r} is not finite")
        vel = velocities[k] if velocities is not None else 0.0
        acc = accelerations[k] if accelerations is not None else 0.0
        why = check_reference_sample(limits, positions[k], vel, acc)
        if why:
            raise ParameterError(f"point {k} (t = {t:g} s): {why}")
    if math.isfinite(limits.velocity_limit):
        for k in range(n - 1):
            dt = times[k + 1] - times[k]
            if dt > 0.0:
                v = (positions[k + 1] - positions[k]) / dt
                if abs(v) > limits.velocity_limit:
                    raise ParameterError(
                        f"points {k}-{k + 1}: moving {positions[k + 1] - positions[k]:.6g} in {dt:g} s "
                        f"needs {abs(v):.6g}, beyond the joint's velocity limit {limits.velocity_limit:g}"
                    )


@dataclass
class TermGuard:
    """Records the terms a controller dropped (per term: count and the first reason).

    ``active``: terms non-finite in the current stretch (cleared by :meth:`clear_quiet`);
    ``counts``: total events per term; ``new``: terms that went non-finite since the last
    :meth:`take_new` (for a log line when a fault starts)."""

    counts: dict[str, int] = field(default_factory=dict)
    active: dict[str, str] = field(default_factory=dict)
    new: list[str] = field(default_factory=list)
    last_event: float = -math.inf

    def record(self, name: str, reason: str, t: float) -> None:
        """Record that term ``name`` was dropped at time ``t`` for ``reason``."""
        self.counts[name] = self.counts.get(name, 0) + 1
        self.last_event = t
        if name not in self.active:
            self.active[name] = reason
            self.new.append(name)

    @property
    def total(self) -> int:
        return sum(self.counts.values())

    def take_new(self) -> list[str]:
        """The reasons of terms that went non-finite since the last call (each once)."""
        out = [self.active[n] for n in self.new if n in self.active]
        self.new.clear()
        return out

    def clear_quiet(self, t: float, quiet: float) -> list[str]:
        """Clear the active terms once ``quiet`` seconds passed without an event; returns the names."""
        if self.active and t - self.last_event >= quiet:
            names = list(self.active)
            self.active.clear()
            return names
        return []
