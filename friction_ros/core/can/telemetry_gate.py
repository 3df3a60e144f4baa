"""Plausibility gate of one drive's decoded telemetry (pure, protocol-independent, joint side).

A drive's encoder and effort reports reach ``joint_states`` only through this gate, the CAN
counterpart of :class:`~friction_ros.core.input_gate.JointInputGate` (same reasons, same
rate-limited :class:`~friction_ros.core.input_gate.RejectionLog`). It sees decoded values already
converted to the joint (rad or m, rad/s or m/s, N*m or N), never frame bytes. Per report, in order:

``not_finite``    NaN/inf position, velocity or effort
``out_of_range``  ``|position| > max_position``, ``|velocity| > max_velocity``,
                  ``|effort| > max_effort``
``jump``          ``|q - q_ref| > max_velocity * (max(t - t_ref, T) + T) + resolution``: farther
                  than the largest plausible speed covers since the last accepted position
                  (q_ref, received at t_ref), with one telemetry period T of margin for frames
                  that arrive in a burst; ``resolution`` is the protocol's position quantum plus
                  two float32 steps of the position (2^-22 |q|)
``undecodable``   a frame for this drive that its protocol decoder rejected (wrong length, NaN)

The bounds derive from the axis's configured limits (:meth:`AxisConfig.plausibility`):
``max_velocity = limit_factor * velocity_limit`` and ``max_effort = limit_factor * current_limit *
k_t * ratio`` (the drive cannot produce more than its current limit), ``max_position`` from the
protocol's position range. A rejected report changes nothing (the axis keeps the last accepted
values and their receive time, so no sample is made from it). Reports come on two channels, motion
(position, velocity) and effort; ``reject_run`` consecutive rejections on one channel are the
*implausible telemetry* condition (:attr:`TelemetryGate.implausible`), which lasts until that
channel accepts a report again. :meth:`TelemetryGate.reset` forgets the reference position
(the next plausible report is adopted as is): the axis calls it on an explicit enable, so a genuine
re-homing is adopted only by an operator. Cost per report: a few comparisons.
"""

from __future__ import annotations

import math
from typing import NamedTuple

from friction_ros.core.input_gate import GATE_DEFAULTS, RejectionLog

REASONS = ("not_finite", "out_of_range", "jump", "undecodable")
MOTION, EFFORT = 0, 1  # report channels
FLOAT32_STEPS = 2.0**-22  # two float32 steps relative to the value (23-bit mantissa)


class TelemetryLimits(NamedTuple):
    """Joint-side bounds of plausible telemetry (see the module docstring)."""

    max_position: float  # [rad or m]
    max_velocity: float  # [rad/s or m/s]
    max_effort: float  # [N*m or N]
    period: float  # telemetry period T [s]
    resolution: float = 0.0  # position quantum of the protocol [rad or m]
    reject_run: int = 5  # consecutive rejections on one channel that make the condition


class TelemetryGate:
    """Gate of one axis; :meth:`motion`/:meth:`effort`/:meth:`reading` return True to accept.

    ``lines`` collects the lines to log, ``(accepted, text)``, rate-limited (the caller takes and
    clears them); ``total`` and ``log.counts`` count the rejections per reason.
    """

    def __init__(self, limits: TelemetryLimits, what: str = "telemetry"):
        self.limits = limits
        self.log = RejectionLog(what, GATE_DEFAULTS["log_period"], REASONS)
        self.runs = [0, 0]  # consecutive rejections per channel
        self.lines: list[tuple[bool, str]] = []
        self.last_detail = ""
        self.reset()

    @property
    def limits(self) -> TelemetryLimits:
        return self._limits

    @limits.setter
    def limits(self, lim: TelemetryLimits) -> None:
        self._limits = lim
        self._qmax, self._vmax, self._emax, self._period = (
            lim.max_position,
            lim.max_velocity,
            lim.max_effort,
            lim.period,
        )
        self._slack = lim.max_velocity * lim.period + lim.resolution  # one period's travel + quantum
        self._run_limit = lim.reject_run

    @property
    def total(self) -> int:
        return self.log.total

    @property
    def implausible(self) -> bool:
        """``reject_run`` consecutive rejections on a channel, not yet followed by an accepted report."""
        n = self._run_limit
        return self.runs[MOTION] >= n or self.runs[EFFORT] >= n

    def reason(self) -> str:
        """What makes the telemetry implausible now (the fault's start line)."""
        return (
            f"{max(self.runs)} telemetry reports in a row rejected as implausible (limit "
            f"telemetry_gate.reject_run = {self.limits.reject_run}; last: {self.last_detail})"
        )

    def reset(self) -> None:
        """Forget the reference position and the runs (the next plausible report is adopted)."""
        self._ref: float | None = None
        self._ref_t = 0.0
        self.runs[MOTION] = self.runs[EFFORT] = 0

    # -- per report ----------------------------------------------------------------------------------
    def motion(self, position: float, velocity: float, t: float) -> bool:
        """Position and velocity received at ``t`` [s]."""
        ref, vmax = self._ref, self._vmax
        if not (  # the usual case first, in a few comparisons; the full check only when it fails
            abs(position) <= self._qmax
            and abs(velocity) <= vmax
            and (
                ref is None or abs(position - ref) <= vmax * max(t - self._ref_t, self._period) + self._slack
            )
        ):
            why = self._motion_fault(position, velocity, t)
            if why:
                return self._reject((MOTION,), why[0], why[1], t)
        self._ref, self._ref_t = position, t
        if self.runs[MOTION] or self.log._streak:
            return self._accept((MOTION,))
        return True

    def effort(self, t: float, a: float, b: float = 0.0) -> bool:
        """One or two efforts (e.g. the current setpoint and measurement, as joint effort) at ``t``."""
        m = self._emax
        if not (abs(a) <= m and abs(b) <= m):
            why = self._effort_fault((a, b))
            return self._reject((EFFORT,), *why, t)
        if self.runs[EFFORT] or self.log._streak:
            return self._accept((EFFORT,))
        return True

    def reading(self, position: float, velocity: float, effort: float, t: float) -> bool:
        """One report carrying both (MIT reply): accepted whole or rejected whole."""
        why = self._motion_fault(position, velocity, t) or self._effort_fault((effort,))
        if why:
            return self._reject((MOTION, EFFORT), why[0], why[1], t)
        self._ref, self._ref_t = position, t
        return self._accept((MOTION, EFFORT))

    def undecodable(self, channel: int, detail: str, t: float) -> None:
        """A frame of this drive on ``channel`` that the protocol decoder rejected."""
        self._reject((channel,), "undecodable", detail, t)

    # -- internals -----------------------------------------------------------------------------------
    def _motion_fault(self, q: float, v: float, t: float) -> tuple[str, str] | None:
        lim = self.limits
        if not (abs(q) <= lim.max_position and abs(v) <= lim.max_velocity):
            if not (math.isfinite(q) and math.isfinite(v)):
                return "not_finite", f"position {q}, velocity {v}: must be finite"
            return "out_of_range", (
                f"position {q:g}, velocity {v:g}: must satisfy |position| <= {lim.max_position:g}, "
                f"|velocity| <= {lim.max_velocity:g}"
            )
        ref = self._ref
        if ref is not None:
            step = max(t - self._ref_t, lim.period)
            allowed = lim.max_velocity * (step + lim.period) + lim.resolution
            allowed += FLOAT32_STEPS * max(abs(q), abs(ref))
            if abs(q - ref) > allowed:
                return "jump", (
                    f"position {q:g} jumps {q - ref:.6g} from the last accepted {ref:g} in {step:.6g} s "
                    f"(allowed {allowed:.6g} = max velocity {lim.max_velocity:g} x ({step:.6g} s + one "
                    f"period {lim.period:g} s) + resolution)"
                )
        return None

    def _effort_fault(self, efforts) -> tuple[str, str] | None:
        m = self.limits.max_effort
        for e in efforts:
            if not abs(e) <= m:
                if not math.isfinite(e):
                    return "not_finite", f"effort {e}: must be finite"
                return "out_of_range", f"effort {e:g}: must satisfy |effort| <= {m:g}"
        return None

    def _accept(self, channels) -> bool:
        for c in channels:
            self.runs[c] = 0
        line = self.log.recovered() if self.log._streak else None
        if line:
            self.lines.append((True, line))
        return True

    def _reject(self, channels, reason: str, detail: str, t: float) -> bool:
        for c in channels:
            self.runs[c] += 1
        self.last_detail = f"{reason}: {detail}"
        line = self.log.reject(reason, detail, t)
        if line:
            self.lines.append((False, line))
        return False
