"""Run-time watch for over-compensation (O(1) per sample, no allocation).

A friction compensation larger than the joint's friction (a Coulomb level edited up, a gain of 2)
pushes the joint ahead of its reference; the loop's feedback then works *against* the compensation
to hold the track, and the joint hunts around the reference (seen: +-0.15 rad at 0.73 Hz, 9x the
tracking error of the fitted file). Too slow for the limit-cycle detector (:mod:`.limit_cycle`),
but visible in the torques: with exponential averages of time constant ``window``,

    R = LP(-u_fb sgn(u_c)) / LP(|u_c|)      (the fraction of the compensation the feedback cancels)
    S = LP(|u_c|) / LP(|u_fb|)              (how much of the command the compensation is)

where ``u_c`` is the friction compensation and ``u_fb`` the feedback law's output (PID terms or
the scheme's). A correct model leaves the feedback uncorrelated with the compensation (R ~ 0); an
under-estimated one is helped by the feedback (R < 0); R = 1 - 1/k for a compensation k times the
joint's friction. The watch **fires** when ``R >= max_cancelled`` (0.6: the compensation is at least
2.5x what the joint takes) and ``S >= min_share`` (0.5: the compensation is a real part of the
command, not noise beside a large load or inertia torque) have held for ``hold`` seconds, at least
``window`` after its first sample. Ratios of torques: the same on any joint, in any unit.

Measured on the presets with their true friction as the model (2 Hz band-limited tracking, 8 s):
R95 <= 0.48 at 0.7x-1.3x the true level on every preset where compensation matters; R50 0.67-0.88
at 8x (Coulomb x4, gain 2); where S < 0.5 the compensation hardly changes the tracking either way.
"""

from __future__ import annotations

import math

OVERCOMPENSATION_DEFAULTS = {"window": 1.0, "hold": 1.0, "max_cancelled": 0.6, "min_share": 0.5}


class OvercompensationWatch:
    """See the module docstring; ``update`` returns True once fired (latched)."""

    def __init__(
        self, *, window: float = 1.0, hold: float = 1.0, max_cancelled: float = 0.6, min_share: float = 0.5
    ):
        self.window, self.hold = float(window), float(hold)
        self.max_cancelled, self.min_share = float(max_cancelled), float(min_share)
        self.reset()

    def reset(self) -> None:
        self._cancel = self._comp = self._fb = 0.0
        self._t0: float | None = None
        self._held = 0.0
        self.fired = False
        self.fired_at = math.nan
        self.cancelled = 0.0  # R of the last sample
        self.share = 0.0  # S of the last sample

    def update(self, t: float, compensation: float, feedback: float, dt: float) -> bool:
        """One sample: the friction compensation and the feedback law's output (same unit)."""
        if self.fired:
            return True
        if self._t0 is None:
            self._t0 = t
        a = dt / (self.window + dt)
        s = 1.0 if compensation > 0.0 else (-1.0 if compensation < 0.0 else 0.0)
        self._cancel += a * (-feedback * s - self._cancel)
        self._comp += a * (abs(compensation) - self._comp)
        self._fb += a * (abs(feedback) - self._fb)
        if self._comp > 0.0:
            self.cancelled = self._cancel / self._comp
            self.share = self._comp / self._fb if self._fb > 0.0 else math.inf
        over = (
            t - self._t0 >= self.window
            and self._comp > 0.0
            and self.cancelled >= self.max_cancelled
            and self.share >= self.min_share
        )
        self._held = self._held + dt if over else 0.0
        if self._held >= self.hold:
            self.fired, self.fired_at = True, float(t)
        return self.fired
