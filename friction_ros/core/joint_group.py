"""N joints of one compensating controller, stepped once per control period from one joint-state
sample (pure, no rclpy): the compensating_controller node and the closed-loop harness
(:func:`~friction_ros.core.harness.run_closed_loop_group`) run the same code.

Per sample (:meth:`JointGroup.step`) and joint j (a :class:`~friction_ros.core.joint_channel.JointChannel`):

1. **Input gate** (:class:`~friction_ros.core.input_gate.JointInputGate`): a rejected or missing
   sample of j holds j's last command; when every joint's sample is a duplicate (a lockstep
   re-send) the step asks for the last commands again (``RESEND``). A re-synchronisation resets
   j's velocity estimate; of the first joint and not after a jump, it also restarts the time base
   one period after the last accepted period.
2. **Time base**: ``t = (s - s0) * 1e-9`` with s the gate's stamp of the first admitted joint [ns]
   and s0 the first stamp.
3. **Reference choice** per joint: the newest ``desired_joint_states`` sample, else the trajectory
   (``reference`` topic) sampled at t, else the built-in generator; an add-on
   (``mode: compensation_only``) without any commands 0 ("waiting").
4. **Command**: ``tau_j = controller_j(t, r_j(t), (q_j, qdot_j), dt)``
   (:class:`~friction_ros.core.control.controller.CompensatingController`); its run-time watch
   (:mod:`~friction_ros.core.control.compensation_watch`) switches compensation off on j only (an
   ERROR event and ``fallback_fired``).

:meth:`JointGroup.check_timeout`: a joint with no valid state for ``limit`` seconds commands zero
torque; the others stay controlled. :meth:`JointGroup.statuses`: one diagnostics status per joint.
Log lines are events ``(level, text)`` in ``events`` (:mod:`friction_ros.core.joint_channel`).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from friction_ros.core.input_gate import DUPLICATE, REJECTED, RESYNC
from friction_ros.core.joint_channel import ERROR, OK, WARN, JointChannel
from friction_ros.core.joint_group_inputs import GroupInputs
from friction_ros.core.validation import ParameterError

#: results of :meth:`JointGroup.step`
IDLE, RESEND, COMPUTED = 0, 1, 2

_HOLD = "sample ignored, holding the last command"


class JointGroup(GroupInputs):
    """The joints of one controller; see the module docstring. ``dt``: the nominal control period
    [s]; ``labelled``: log lines start with the joint's name (default: with several joints).
    ``addon``: every joint is ``mode: compensation_only`` (some but not all: ParameterError)."""

    def __init__(self, channels: Sequence[JointChannel], dt: float, *, labelled: bool | None = None):
        self.channels = list(channels)
        self.joints = [ch.joint for ch in self.channels]
        self.by_joint = {ch.joint: ch for ch in self.channels}
        self.dt = dt
        addon = [ch.joint for ch in self.channels if ch.controller.mode == "compensation_only"]
        if addon and len(addon) < len(self.channels):
            raise ParameterError(
                "mode: compensation_only must be the mode of every joint or of none (joints "
                f"{', '.join(addon)} are add-on, the others are not)"
            )
        self.addon = bool(addon)
        labelled = len(self.channels) > 1 if labelled is None else labelled
        for ch in self.channels:
            ch.label = f"{ch.joint}: " if labelled else ""
        self.t0_ns: int | None = None
        self.last_ns: int | None = None  # stamp of the last computed period
        self.last_t = 0.0  # its controller time [s]
        self.counts = {
            "cycles": 0,
            "duplicates": 0,
            "rejected_references": 0,
            "saturated": 0,
            "adopted": 0,
            "rejected_estimates": 0,
        }
        self.events: list[tuple[int, str]] = []
        self.computed: list[JointChannel] = []  # joints whose terms the last step computed
        self._admitted: list[JointChannel] = []
        self.fallback_fired = False  # a joint's compensation fell back since the node last looked

    @property
    def commands(self) -> list[float]:
        """The command of every joint [N*m or N], in joint order."""
        return [ch.command for ch in self.channels]

    def take_events(self) -> list[tuple[int, str]]:
        events, self.events = self.events, []
        return events

    # -- the per-sample path ------------------------------------------------------------------------
    def step(self, msg, now_ns: int, now_s: float) -> int:
        """One control period from one JointState-like ``msg`` (``name``, ``position``, ``velocity``,
        ``effort``, ``stamp_ns``). ``now_ns``: node clock [ns] (0: unknown), ``now_s``: the clock of
        the state timeout [s]. Returns IDLE (nothing admitted), RESEND (all duplicates) or COMPUTED
        (``computed``: the joints with new terms; ``commands``: every joint's command)."""
        events = self.events
        computed = self.computed
        computed.clear()
        admitted = self._admitted
        admitted.clear()
        duplicates = 0
        for ch in self.channels:
            status = ch.admit(msg, now_ns, events, _HOLD, ch.label)
            if status >= DUPLICATE:
                if status == REJECTED:
                    continue
                if status == DUPLICATE:
                    duplicates += 1
                    continue
                if status == RESYNC:
                    self._resync(ch)
            admitted.append(ch)
        if not admitted:
            return RESEND if duplicates else IDLE
        t_ns = admitted[0].gate.stamp_ns
        if self.t0_ns is None:
            self.t0_ns = t_ns
            for ch in self.channels:  # a joint never seen times out from the first period on
                ch.last_state_s = now_s
        t = (t_ns - self.t0_ns) * 1e-9
        dt = self.dt
        for ch in admitted:
            ch.last_state_s = now_s
            if ch.timed_out:
                ch.timed_out = False
                events.append((OK, f"{ch.label}joint states valid again: controlling"))
            if ch.desired is not None:
                ref = ch.desired
            elif ch.trajectory is not None:
                ref = ch.trajectory.sample(t)
            elif self.addon and not ch.has_reference:
                if not ch.waiting_logged:
                    ch.waiting_logged = True
                    events.append(
                        (
                            WARN,
                            f"{ch.label}no desired trajectory yet (reference, desired_joint_states or "
                            "reference.* parameters): compensation output 0",
                        )
                    )
                ch.command = ch.compensation = 0.0
                continue
            else:
                ref = ch.reference.sample(t)
            ctrl = ch.controller
            terms = ctrl.compute(t, ref, (ch.gate.position, ch.gate.velocity), dt)
            ch.terms = terms
            ch.command = ch.compensation = terms.command
            if ctrl.guard.active:
                self._dropped_terms(ch, t)
            if terms.saturated:
                self.counts["saturated"] += 1
            if ctrl.compensation_fallback and ch.fallback_logged != ctrl.fallback_reason:
                ch.fallback_logged = ctrl.fallback_reason  # each stage once: fallback, unstable loop
                events.append((ERROR, ch.label + ctrl.fallback_reason))
                self.fallback_fired = True
            computed.append(ch)
        self.last_ns = t_ns
        self.last_t = t
        self.counts["cycles"] += 1
        return COMPUTED

    def _resync(self, ch: JointChannel) -> None:
        """The gate adopted a new reference after a run of consistent rejected samples."""
        if ch.gate.resync_reason != "jump" and self.t0_ns is not None and ch is self.channels[0]:
            # a new time base: the controller's time continues one period after the last accepted
            self.t0_ns = ch.gate.stamp_ns - int(round((self.last_t + self.dt) * 1e9))
        ch.controller.velocity.reset()  # no difference across the discontinuity

    def _dropped_terms(self, ch: JointChannel, t: float) -> None:
        """A dropped non-finite or out-of-limit term: once when it starts, once when it has been
        valid again for 1 s (:class:`~friction_ros.core.control.command_safety.TermGuard`)."""
        guard = ch.controller.guard
        for why in guard.take_new():
            self.events.append((ERROR, f"{ch.label}{why}: term dropped, its state reset"))
        for name in guard.clear_quiet(t, 1.0):
            self.events.append((OK, f"{ch.label}{name}: valid again for 1 s (cleared)"))

    # -- safety and health --------------------------------------------------------------------------
    def check_timeout(self, now_s: float, limit: float) -> bool:
        """Zero torque for every joint with no valid state for ``limit`` seconds (clock of
        :meth:`step`'s ``now_s``); True when a joint timed out just now (publish the commands)."""
        if self.last_ns is None:
            return False
        newly = False
        for ch in self.channels:
            if ch.timed_out or now_s - ch.last_state_s <= limit:
                continue
            ch.timed_out = newly = True
            ch.command = ch.compensation = 0.0
            log = ch.gate.log
            why = (
                f" ({log.total} rejected so far, last reason {log.last_reason}: see the rejection lines)"
                if log.total
                else ""
            )
            self.events.append(
                (WARN, f"{ch.label}no valid joint state for {limit:g} s{why}: commanding zero torque")
            )
        return newly

    def zero(self) -> None:
        """Every joint commands zero torque (shutdown)."""
        for ch in self.channels:
            ch.command = ch.compensation = 0.0

    def statuses(self, compute: dict[str, float]) -> list[tuple[str, int, str, dict[str, Any]]]:
        """One diagnostics status ``(joint, level, text, values)`` per joint; ``compute``: the
        compute-time values of the period (``compute_p50_s`` ...)."""
        return [(ch.joint, *self._status(ch, compute)) for ch in self.channels]

    def _status(self, ch: JointChannel, compute: dict) -> tuple[int, str, dict]:
        new_rejections, gate_values = ch.gate_values()
        values = {**self.counts, **gate_values, **compute}
        ctrl = ch.controller
        level, text = OK, f"{ctrl.mode} running"
        if not ctrl.compensation_enabled:
            text = f"{ctrl.mode} running, compensation switched off (~/set_feedforward_control)"
        if self.addon and not (ch.has_reference or ch.trajectory or ch.desired):
            level, text = WARN, "waiting for a desired trajectory: compensation output 0"
        if new_rejections:
            level = WARN
            text = (
                f"{new_rejections} joint states rejected since the last status "
                f"(last: {ch.gate.log.last_reason})"
            )
        if ch.timed_out:
            level, text = WARN, "no joint state: commanding zero torque"
        if ctrl.compensation_fallback:
            level, text = ERROR, ctrl.fallback_reason
        values["dropped_terms"] = ctrl.guard.total
        if ctrl.guard.active:
            level, text = ERROR, "; ".join(ctrl.guard.active.values()) + ": term dropped, its state reset"
        values["residual_nonfinite"] = ctrl.residual_nonfinite
        if ctrl.residual_note and not ch.residual_logged:
            ch.residual_logged = True  # once per controller (a parameter change builds a new one)
            self.events.append((ERROR, ch.label + ctrl.residual_note))
        if ctrl.residual_nonfinite and level == OK:
            level, text = WARN, ctrl.residual_note
        # what compensates: the source with a friction model, else none (friction-bringup's summary)
        fr = ctrl.friction
        values["compensation"] = fr.source if fr.model is not None and fr.source != "none" else "none"
        values["compensation_fallback"] = int(ctrl.compensation_fallback)
        values["compensation_enabled"] = int(ctrl.compensation_enabled)
        values["feedback_bound_limited"] = int(bool(ctrl.feedback_bound_note))
        if ctrl.feedback_bound_note:
            values["feedback_bound"] = ctrl.feedback_bound_note
        return level, text, values

    def summary(self) -> list[tuple[int, str]]:
        """The start-up lines: per joint its mode, friction model, load feedforward, learned
        residual and reference (and a feedback bound, WARN)."""
        lines = []
        for ch in self.channels:
            c = ch.controller
            ref = ch.reference.config().get("type", "?") if ch.has_reference or not self.addon else "topic"
            lines.append(
                (
                    OK,
                    f"{ch.label}mode {c.mode}, friction model "
                    f"{c.friction.model.name if c.friction.model else 'none'}, "
                    f"load feedforward {'on' if c.load.active else 'off'}, "
                    f"learned residual {c.residual.residual.kind if c.residual is not None else 'off'}, "
                    f"reference {ref}",
                )
            )
            if c.feedback_bound_note:
                lines.append((WARN, ch.label + c.feedback_bound_note))
        return lines
