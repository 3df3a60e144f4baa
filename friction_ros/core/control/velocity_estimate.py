"""The controller's velocity estimate: the measured velocity, or a filtered backward difference of the
measured position (GA friction thesis 2002 section 6.1) with the lost-bit hold filter ``position_jump_limit``."""

from __future__ import annotations


class VelocityEstimator:
    """Measured velocity, or a filtered backward difference of position with a jump-hold filter."""

    def __init__(self, source: str, filter_time_constant: float, jump_limit: float):
        self.source = source
        self.tf = filter_time_constant
        self.jump_limit = jump_limit
        self.reset()

    def reset(self) -> None:
        self._pos = None
        self._v = 0.0

    def update(self, position: float, velocity: float | None, dt: float) -> tuple[float, float]:
        """Return (position used, velocity estimate)."""
        pos = float(position)
        if self._pos is not None and abs(pos - self._pos) > self.jump_limit:
            pos = self._pos  # GA friction thesis 2002 lost-bit hold
        if self.source == "measured" and velocity is not None:
            raw = float(velocity)
        else:
            raw = 0.0 if self._pos is None else (pos - self._pos) / dt
        self._pos = pos
        if self.tf > 0.0:
            self._v += dt / (self.tf + dt) * (raw - self._v)
        else:
            self._v = raw
        return pos, self._v
