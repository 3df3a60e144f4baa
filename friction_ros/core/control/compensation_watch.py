"""The run-time compensation watch of one joint's controller: three detectors, one latched state.

1. **Limit cycle** (:class:`.limit_cycle.LimitCycleDetector`), watched while a feedback path of the
   compensation is active (a feedforward term is a function of the reference and cannot make the
   loop oscillate by itself): a fast oscillation that the reference does not contain.
2. **Over-compensation** (:class:`.overcompensation.OvercompensationWatch`), watched whenever friction
   compensation is on and the controller has a feedback law of its own: the feedback persistently
   cancelling most of the compensation (a slow hunting the limit-cycle detector cannot see).
3. After either fired, friction compensation is off (``fallback``, latched) and a second
   limit-cycle detector watches the plain loop; if it fires with the command swinging over a
   quarter of its range, the loop itself is unstable (its gains): ``loop_unstable`` (latched), the
   controller stops the position feedback and damps the joint to rest (see the controller).

All three are latched until the controller is rebuilt or reconfigured; ``reason`` says why.
"""

from __future__ import annotations

from friction_ros.core.control.limit_cycle import LimitCycleDetector
from friction_ros.core.control.overcompensation import OvercompensationWatch


class CompensationWatch:
    """See the module docstring. ``limit_cycle``: the first detector (None when detection is off)."""

    def __init__(
        self,
        *,
        enabled: bool,
        limit_cycle: dict,
        feedback_path: bool,
        overcompensation: bool,
        command_range: float,
    ):
        """``limit_cycle``: the detector's keyword arguments; ``feedback_path``: whether the
        compensation feeds the measured motion back (limit cycles are watched); ``overcompensation``:
        whether over-compensation is watched (friction compensation and a feedback law of its own);
        ``command_range``: ``u_max - u_min`` of the command."""
        self.limit_cycle = LimitCycleDetector(**limit_cycle) if enabled else None
        self._plain_loop = LimitCycleDetector(**limit_cycle) if enabled else None
        self.overcompensation = OvercompensationWatch() if enabled and overcompensation else None
        self.feedback_path = feedback_path
        self.command_range = command_range
        self.fallback = False
        self.loop_unstable = False
        self.reason = ""

    def update(self, t, error, command, ref_vel, pos, dt, ref_pos, compensation, feedback) -> None:
        """One period after the command was computed (SI units); ``compensation``: the friction
        compensation in the command, ``feedback``: the feedback law's output."""
        lc = self.limit_cycle
        if lc is None or self.loop_unstable:
            return
        if self.fallback:
            if self._plain_loop.update(t, error, command, ref_vel, pos, dt, ref_pos):
                self._plain_loop_oscillates(t)
            return
        if self.feedback_path and lc.update(t, error, command, ref_vel, pos, dt, ref_pos):
            self.fallback = True
            self.reason = (
                f"compensation-induced limit cycle {_what(lc, t)}: friction compensation switched off"
            )
        oc = self.overcompensation
        if not self.fallback and oc is not None and oc.update(t, compensation, feedback, dt):
            self.fallback = True
            self.reason = (
                f"over-compensation at t = {t:.3f} s: for {oc.hold:g} s the feedback cancelled "
                f"{100 * oc.cancelled:.0f} % of the friction compensation ({100 * oc.share:.0f} % of the "
                "feedback's size): the model or its gain is too large; friction compensation switched off"
            )

    def _plain_loop_oscillates(self, t: float) -> None:
        det = self._plain_loop
        if det.command_amplitude < 0.25 * 0.5 * self.command_range:
            det.reset()  # a small ring or chatter of the plain loop, not an unstable one: watch on
            return
        self.loop_unstable = True
        self.reason = (
            f"the loop oscillates without friction compensation {_what(det, t)}: the gains make it "
            "unstable; position feedback stopped, the joint damped to rest until the gains change"
        )


def _what(det: LimitCycleDetector, t: float) -> str:
    return f"({det.frequency:.0f} Hz, error {det.amplitude:.3g} RMS, not in the reference) at t = {t:.3f} s"
