"""Reference trajectory from waypoints (the core of the controller's trajectory_msgs input).

A trajectory is a list of waypoints ``(t_i, q_i, qd_i, qdd_i)``. Between waypoints the position is a
cubic Hermite spline through (q_i, qd_i) when velocities are given, linear interpolation otherwise;
before the first waypoint the first point holds, after the last one the last position holds with
zero velocity and acceleration (the joint comes to rest).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from friction_ros.core.validation import ParameterError


class TrajectoryReference:
    """Piecewise cubic Hermite reference through waypoints, sampled at arbitrary times."""

    def __init__(
        self,
        times: Sequence[float],
        positions: Sequence[float],
        velocities: Sequence[float] | None = None,
        start_time: float = 0.0,
    ):
        t = np.asarray(times, dtype=float)
        q = np.asarray(positions, dtype=float)
        if t.ndim != 1 or t.size == 0:
            raise ParameterError("trajectory: needs at least one point with a time_from_start")
        if q.shape != t.shape:
            raise ParameterError(
                f"trajectory: {q.size} positions for {t.size} points: each point needs one position"
            )
        has_vel = velocities is not None and len(velocities) > 0
        qd = np.asarray(velocities, dtype=float) if has_vel else np.zeros_like(q)
        if has_vel and qd.shape != t.shape:
            raise ParameterError(
                f"trajectory: {qd.size} velocities for {t.size} points: give one per point or none"
            )
        for name, arr in (("time_from_start", t), ("positions", q), ("velocities", qd)):
            if not np.all(np.isfinite(arr)):
                raise ParameterError(f"trajectory: {name} contains NaN or inf: every value must be finite")
        if not math.isfinite(start_time):
            raise ParameterError("trajectory: start time must be finite")
        if np.any(np.diff(t) <= 0):
            raise ParameterError("trajectory: time_from_start must be strictly increasing")
        self.t = t + start_time
        self.q = q
        self.qd = qd
        self.cubic = has_vel

    def sample(self, time: float) -> tuple[float, float, float]:
        """Return (position, velocity, acceleration) of the reference at ``time``."""
        t, q, qd = self.t, self.q, self.qd
        if time <= t[0]:
            return float(q[0]), 0.0, 0.0
        if time >= t[-1]:
            return float(q[-1]), 0.0, 0.0
        k = int(np.searchsorted(t, time, side="right") - 1)
        h = t[k + 1] - t[k]
        s = (time - t[k]) / h
        if not self.cubic:
            v = (q[k + 1] - q[k]) / h
            return float(q[k] + s * (q[k + 1] - q[k])), float(v), 0.0
        p0, p1, m0, m1 = q[k], q[k + 1], qd[k] * h, qd[k + 1] * h
        s2, s3 = s * s, s * s * s
        pos = (2 * s3 - 3 * s2 + 1) * p0 + (s3 - 2 * s2 + s) * m0 + (-2 * s3 + 3 * s2) * p1 + (s3 - s2) * m1
        dpos = (
            (6 * s2 - 6 * s) * p0 + (3 * s2 - 4 * s + 1) * m0 + (-6 * s2 + 6 * s) * p1 + (3 * s2 - 2 * s) * m1
        )
        ddpos = (12 * s - 6) * p0 + (6 * s - 4) * m0 + (-12 * s + 6) * p1 + (6 * s - 2) * m1
        return float(pos), float(dpos / h), float(ddpos / (h * h))

    @property
    def end_time(self) -> float:
        return float(self.t[-1])
