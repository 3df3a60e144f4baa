"""The inputs of a :class:`~friction_ros.core.joint_group.JointGroup` besides joint states
(pure, no rclpy): references per joint, adopted friction coefficients, compensation on/off and
run-time parameter changes.

References are checked at the door against each joint's limits
(:mod:`friction_ros.core.control.command_safety`): a trajectory with any sample that is not finite
or beyond a limit is refused whole (the previous reference stays); a desired state per joint
likewise. A trajectory stamped ``s`` starts at ``t = (s - s0) * 1e-9`` of the group's time base, an
unstamped one (or one before the first state) at the last computed period.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

from friction_ros.core.coefficient_exchange import from_fields
from friction_ros.core.control.command_safety import check_reference_sample, check_trajectory
from friction_ros.core.experiment.trajectory import TrajectoryReference
from friction_ros.core.joint_channel import OK, WARN, JointChannel
from friction_ros.core.validation import ParameterError


def _column(rows: Sequence[Sequence[float]], j: int) -> list[float] | None:
    """Joint j's values of every trajectory point, None when a point has none."""
    return [r[j] for r in rows] if all(len(r) > j for r in rows) else None


class GroupInputs:
    """Mixin of JointGroup (its ``channels``, ``joints``, ``by_joint``, ``counts``, ``events``,
    ``t0_ns``, ``last_ns``)."""

    def set_trajectory(
        self,
        names: Sequence[str],
        times: Sequence[float],
        stamp_ns: int,
        positions: Sequence[Sequence[float]],
        velocities: Sequence[Sequence[float]],
        accelerations: Sequence[Sequence[float]],
    ) -> str:
        """A JointTrajectory: ``times`` [s from start], per point the values of ``names``. Returns ''
        when adopted, else the reason it was refused (the previous references stay)."""
        names = list(names)
        mine = [ch for ch in self.channels if ch.joint in names]
        try:
            if not mine:
                raise ParameterError(f"none of the joints {', '.join(self.joints)} is in joint_names {names}")
            if stamp_ns == 0 or self.t0_ns is None:
                start = (self.last_ns - self.t0_ns) * 1e-9 if self.last_ns is not None else 0.0
            else:
                start = (stamp_ns - self.t0_ns) * 1e-9
            built = []
            for ch in mine:
                j = names.index(ch.joint)
                pos = [p[j] if j < len(p) else math.nan for p in positions]
                vel, acc = _column(velocities, j), _column(accelerations, j)
                try:  # refused whole when any sample is not finite or beyond the joint's limits
                    check_trajectory(ch.reference_limits, times, pos, vel, acc)
                except ParameterError as exc:
                    raise ParameterError(f"{ch.label}{exc}") from None
                built.append((ch, TrajectoryReference(times, pos, vel, start_time=start)))
        except ParameterError as exc:
            self.counts["rejected_references"] += 1
            return str(exc)
        for ch, traj in built:
            ch.trajectory, ch.desired = traj, None
        return ""

    def set_desired(
        self, names: Sequence[str], positions: Sequence[float], velocities: Sequence[float]
    ) -> list[str]:
        """The desired state per joint (position; velocity, 0 when not given): the reference of the
        next period. Returns the refusals, one line per refused joint."""
        names = list(names)
        refused = []
        for ch in self.channels:
            if ch.joint not in names:
                continue
            i = names.index(ch.joint)
            pos = float(positions[i]) if i < len(positions) else math.nan
            vel = float(velocities[i]) if i < len(velocities) else 0.0
            why = check_reference_sample(ch.reference_limits, pos, vel, 0.0)
            if why:
                self.counts["rejected_references"] += 1
                refused.append(
                    f"{ch.label}rejected desired_joint_states: {why}; keeping the previous reference"
                )
                continue
            ch.desired, ch.trajectory = (pos, vel, 0.0), None
        return refused

    @property
    def adopting(self) -> bool:
        """Whether any joint adopts the estimator's coefficients (``adopt_estimator_coefficients``)."""
        return any(ch.values.get("adopt_estimator_coefficients") for ch in self.channels)

    def adopt(self, joint: str, model: str, names: Sequence[str], coefficients: Sequence[float]) -> str:
        """A converged estimate of ``joint`` ('' = the first joint), adopted when that joint adopts
        estimates; '' or the reason it was not adopted."""
        ch = self.by_joint.get(joint) if joint else self.channels[0]
        if ch is None or not ch.values.get("adopt_estimator_coefficients"):
            return ""
        try:
            ch.controller.set_coefficients(from_fields(model, names, coefficients))
            self.counts["adopted"] += 1
        except (ParameterError, ValueError) as exc:
            self.counts["rejected_estimates"] += 1
            return f"{ch.label}estimator coefficients not adopted: {exc}"
        return ""

    def set_compensation(self, on: bool) -> None:
        """Friction/load compensation on or off for every joint."""
        for ch in self.channels:
            ch.controller.compensation_enabled = bool(on)

    def set_gains(self, ch: JointChannel, gains: Mapping[str, Any], values: dict, overrides: dict, what: str):
        """New PID gains in the running controller (its states stay); ``what``: the changed names."""
        note = ch.controller.feedback_bound_note
        ch.controller.set_pid_gains(**gains)
        ch.values, ch.overrides = values, overrides
        self.events.append((OK, f"{ch.label}parameters changed: {what} (states kept)"))
        if ch.controller.feedback_bound_note != note and ch.controller.feedback_bound_note:
            self.events.append((WARN, ch.label + ch.controller.feedback_bound_note))

    def replace(self, ch: JointChannel, controller, reference, values: dict, overrides: dict, what: str):
        """A new controller and reference generator for ``ch`` (compensation on/off carries over;
        a latched fallback is cleared); ``what``: the changed names."""
        old = ch.controller
        if old.compensation_fallback:
            self.events.append(
                (
                    OK,
                    f"{ch.label}compensation fallback cleared by a parameter change: compensation active again",
                )
            )
            ch.fallback_logged = ""
        controller.compensation_enabled = old.compensation_enabled
        note_changed = controller.feedback_bound_note != old.feedback_bound_note
        ch.controller, ch.reference, ch.values, ch.overrides = controller, reference, values, overrides
        ch.residual_logged = False
        self.events.append((OK, f"{ch.label}parameters changed: {what}"))
        if note_changed and controller.feedback_bound_note:
            self.events.append((WARN, ch.label + controller.feedback_bound_note))


def control_channel(
    joint: str, controller, reference, gate, values=None, overrides=None, has_reference=True
) -> JointChannel:
    """A joint of a JointGroup: its controller, built-in reference generator and input gate;
    ``has_reference``: an add-on's generator counts (a reference section was given)."""
    ch = JointChannel(joint, gate, values, overrides)
    ch.controller, ch.reference, ch.has_reference = controller, reference, has_reference
    return ch
