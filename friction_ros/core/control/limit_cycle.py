"""Run-time detector of a compensation-induced limit cycle (O(1) per sample, no allocation).

A friction-compensation term that feeds the measured motion back (LuGre micro-damping
``sigma1 * v``, a stiffness ``sigma0 * z``, an over-estimated Coulomb level) can destabilise a loop
that is stable without it: the joint then oscillates at a frequency the reference does not
contain. The detector watches, per sample, the tracking error ``e``, the command ``u`` and the
reference velocity ``v_ref``; with exponential averages of time constant ``window``:

* ``e_hp = e - LP(e)`` (first-order high-pass, corner ``1 / (2 pi tau_hp)``, ``tau_hp = window / 2``),
  ``A_e = sqrt(LP(e_hp^2))`` its RMS; likewise ``A_u`` for the command;
* ``f_e``: the rate of sign changes of ``e_hp`` outside a dead band of ``amplitude / 2``, as a
  frequency (``crossings / 2`` per second); ``f_ref``: the same for ``v_ref``;
* ``A_r = sqrt(LP(r_hp^2))`` for the reference position ``r`` (same high-pass): error motion that
  the reference itself has (a step, a fast reference) is explained by it;
* ``P_fast = LP_fast(e_hp^2)`` with time constant ``window / 4``: a *sustained* oscillation keeps
  ``P_fast >= P / 2`` (``P = A_e^2``); a decaying ring-down (a step response of a lightly damped
  loop, a slip event) drops below within ~1.5 fast time constants (the slow average lags it);
* **oscillation** when ``f_e >= min_frequency``, ``A_e >= amplitude``, ``A_e >= 2 A_r``,
  ``f_ref < f_e / 4`` (the reference does not explain it), ``P_fast >= P / 2`` (sustained) and
  ``A_u >= min_command`` (the command oscillates too);
* it **fires** when the oscillation has held for ``hold`` seconds; it is armed only ``window``
  after its first sample (or a reset), when the averages have settled: the start-up transient of a
  loop (averages that begin at zero, a first error sample) is never taken for an oscillation.

``amplitude`` is ``max(min_amplitude, 4 q)`` with ``q`` the smallest position step seen (the
encoder count, estimated online), so quantisation noise (one-count chatter) never qualifies.
Defaults: ``window`` 0.04 s, ``hold`` 0.03 s, ``min_frequency`` 15 Hz: with an oscillation that
starts at t0, the averages settle within about one window, so the detector fires within
``window + hold`` (~0.07 s) of the oscillation being established.

The detector cannot tell an oscillation that compensation causes from one the loop has without
it (gains at the stability limit): the controller only watches while a feedback path is active,
and a fallback then returns the joint to the uncompensated loop. Cost: ~30 floating-point
operations per sample, no allocation.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

LIMIT_CYCLE_DEFAULTS = {
    "enabled": True,
    "min_frequency": 15.0,
    "min_amplitude": 0.0,
    "min_command": 0.0,
    "window": 0.04,
    "hold": 0.03,
}


@dataclass
class LimitCycleStatus:
    oscillating: bool
    fired: bool
    frequency: float
    amplitude: float


class LimitCycleDetector:
    """See the module docstring; ``update(...)`` returns True once the detector has fired (latched)."""

    def __init__(
        self,
        *,
        min_frequency: float = 15.0,
        min_amplitude: float = 0.0,
        min_command: float = 0.0,
        window: float = 0.04,
        hold: float = 0.03,
    ):
        self.min_frequency = float(min_frequency)
        self.min_amplitude = float(min_amplitude)
        self.min_command = float(min_command)
        self.window = float(window)
        self.hold = float(hold)
        self.reset()

    def reset(self) -> None:
        self._e_lp = self._u_lp = self._r_lp = None
        self._pe = self._pu = self._pr = self._pf = 0.0
        self._cross = self._ref_cross = 0.0
        self._s_e = 0
        self._s_r = 0
        self._q = math.inf
        self._last_pos: float | None = None
        self._held = 0.0
        self._t0: float | None = None
        self.fired = False
        self.fired_at = math.nan
        self.frequency = 0.0
        self.amplitude = 0.0

    @property
    def threshold(self) -> float:
        q = 0.0 if math.isinf(self._q) else self._q
        return max(self.min_amplitude, 4.0 * q)

    def update(
        self,
        t: float,
        error: float,
        command: float,
        reference_velocity: float,
        position: float,
        dt: float,
        reference_position: float | None = None,
    ) -> bool:
        """One sample (SI units); ``reference_position`` defaults to ``position + error``."""
        if self.fired:
            return True
        if self._last_pos is not None:
            step = abs(position - self._last_pos)
            if 1e-9 < step < self._q:  # below 1e-9: floating-point noise, not a count
                self._q = step
        self._last_pos = position
        if self._t0 is None:
            self._t0 = t
        r = position + error if reference_position is None else reference_position
        a_hp = dt / (0.5 * self.window + dt)
        a = dt / (self.window + dt)
        a_f = dt / (0.25 * self.window + dt)
        if self._e_lp is None:
            self._e_lp, self._u_lp, self._r_lp = error, command, r
        self._e_lp += a_hp * (error - self._e_lp)
        self._u_lp += a_hp * (command - self._u_lp)
        self._r_lp += a_hp * (r - self._r_lp)
        e_hp = error - self._e_lp
        u_hp = command - self._u_lp
        r_hp = r - self._r_lp
        e2 = e_hp * e_hp
        self._pe += a * (e2 - self._pe)
        self._pf += a_f * (e2 - self._pf)
        self._pu += a * (u_hp * u_hp - self._pu)
        self._pr += a * (r_hp * r_hp - self._pr)
        thr = self.threshold
        s = 1 if e_hp > 0.5 * thr else (-1 if e_hp < -0.5 * thr else 0)
        crossed = 0.0
        if s != 0:
            if self._s_e != 0 and s != self._s_e:
                crossed = 1.0
            self._s_e = s
        self._cross += a * (crossed / dt - self._cross)
        sr = 1 if reference_velocity > 0 else (-1 if reference_velocity < 0 else 0)
        rc = 0.0
        if sr != 0:
            if self._s_r != 0 and sr != self._s_r:
                rc = 1.0
            self._s_r = sr
        self._ref_cross += a * (rc / dt - self._ref_cross)
        f_e = 0.5 * self._cross
        f_r = 0.5 * self._ref_cross
        amp = math.sqrt(max(self._pe, 0.0))
        self.frequency, self.amplitude = f_e, amp
        osc = (
            t - self._t0 >= self.window  # armed once the averages have settled (no start-up transient)
            and f_e >= self.min_frequency
            and amp >= thr
            and thr > 0.0
            and f_r < 0.25 * f_e
            and self._pe >= 4.0 * self._pr
            and self._pf >= 0.5 * self._pe
            and math.sqrt(max(self._pu, 0.0)) >= self.min_command
        )
        self._held = self._held + dt if osc else 0.0
        if self._held >= self.hold:
            self.fired = True
            self.fired_at = float(t)
        return self.fired

    @property
    def command_amplitude(self) -> float:
        """RMS of the command's oscillation (high-passed like the error's)."""
        return math.sqrt(max(self._pu, 0.0))
