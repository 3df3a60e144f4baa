"""N joints of one friction estimator, fed from one joint-state sample (pure, no rclpy): the
friction_estimator node's per-sample path.

Per sample (:meth:`EstimatorGroup.step`) and joint j (a
:class:`~friction_ros.core.joint_channel.JointChannel` with an
:class:`~friction_ros.core.estimation.estimator.OnlineFrictionEstimator`): the input gate (the
controller's; velocity and effort required) admits j's sample or skips j for this sample only (its
estimate does not advance, the other joints' do); a duplicate (lockstep re-send) is skipped; a
re-synchronisation (new time base, a bag loop) restarts j's estimator. The estimator steps with
``dt_k = (s_k - s_{k-1}) * 1e-9`` (s: the gate's stamps [ns]; ``period`` for the first sample).
Every ``publish_every`` samples of j, j is ``due``: :meth:`estimate` gives its FrictionEstimate fields.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

from friction_ros.core.coefficient_exchange import to_fields
from friction_ros.core.input_gate import DUPLICATE, REJECTED, RESYNC
from friction_ros.core.joint_channel import OK, WARN, JointChannel


class EstimatorGroup:
    """The joints of one estimator; see the module docstring. ``period``: nominal sample period [s]."""

    def __init__(self, channels: Sequence[JointChannel], period: float, publish_every: int = 1):
        self.channels = list(channels)
        self.period = period
        self.publish_every = publish_every
        self.events: list[tuple[int, str]] = []
        self.due: list[JointChannel] = []  # joints whose estimate is to be published after a step
        self._layout_key: tuple = ()

    def take_events(self) -> list[tuple[int, str]]:
        events, self.events = self.events, []
        return events

    def _index(self, msg) -> None:
        """Each joint's index in this joint_states layout; -1 when its gate must look (missing joint,
        wrong lengths, unnamed message): the gate's ``admit`` then gives the reason."""
        names = msg.name
        n = len(names)
        self._layout_key = (names, len(msg.position), len(msg.velocity), len(msg.effort))
        whole = n > 0 and len(msg.position) == n and len(msg.velocity) == n and len(msg.effort) == n
        where = {name: i for i, name in enumerate(names)} if whole else {}
        for ch in self.channels:
            ch.index = where.get(ch.joint, -1)

    def step(self, msg, now_ns: int) -> list[JointChannel]:
        """One JointState-like sample (``name``, ``position``, ``velocity``, ``effort``,
        ``stamp_ns``); ``now_ns``: node clock [ns]. Returns ``due``."""
        due = self.due
        due.clear()
        if (msg.name, len(msg.position), len(msg.velocity), len(msg.effort)) != self._layout_key:
            self._index(msg)
        stamp_ns = msg.stamp_ns
        pos, vel, eff = msg.position, msg.velocity, msg.effort
        events = self.events
        for ch in self.channels:
            gate = ch.gate
            i = ch.index
            status = (
                gate.check(stamp_ns, now_ns, pos[i], vel[i], eff[i]) if i >= 0 else gate.admit(msg, now_ns)
            )
            if gate.log_line:
                ch.note(status, events, "sample ignored")
            if status == REJECTED or status == DUPLICATE:
                continue
            self._update(ch, status)
        return due

    def _update(self, ch: JointChannel, status: int) -> None:
        gate = ch.gate
        t_ns = gate.stamp_ns
        if status == RESYNC:
            ch.estimator.reset()  # new time base or position reference (a bag loop): start over
            ch.last_ns = None
        dt = (t_ns - ch.last_ns) * 1e-9 if ch.last_ns is not None else self.period
        ch.last_ns = t_ns
        excited = ch.estimator.step(t_ns * 1e-9, gate.position, gate.velocity, gate.effort, dt)
        counts = ch.counts
        counts["samples"] += 1
        counts["excited_samples"] += int(excited)
        if counts["samples"] % self.publish_every == 0:
            self.due.append(ch)

    @staticmethod
    def estimate(ch: JointChannel) -> tuple:
        """The FrictionEstimate fields of ``ch`` after ``model``: (model, friction_torque, model_torque,
        velocity, state, coefficient_names, coefficients, coefficient_std, excitation_ok, converged)."""
        est = ch.estimator
        e = est.record()  # coefficient lists and convergence: only for a published estimate
        model, names, coefs = to_fields(est.model_config())
        std = est.coefficient_std
        return (
            model,
            float(e.friction_torque),
            float(e.model_torque),
            float(e.velocity),
            [float(x) for x in e.state],
            names,
            [float(c) for c in coefs],
            [float(std.get(n, math.nan)) for n in names] if std else [],
            e.excitation_ok,
            e.converged,
        )

    def statuses(self) -> list[tuple[str, int, str, dict]]:
        """One diagnostics status ``(joint, level, text, values)`` per joint."""
        out = []
        for ch in self.channels:
            new_rejections, gate_values = ch.gate_values()
            est = ch.estimator
            values = {**ch.counts, **gate_values, **{f"coef.{k}": v for k, v in est.coefficients.items()}}
            level = OK if est.converged else WARN
            text = "converged" if est.converged else "adapting (not converged yet)"
            if new_rejections:
                level = WARN
                text += (
                    f"; {new_rejections} joint states rejected since the last status "
                    f"(last: {ch.gate.log.last_reason})"
                )
            out.append((ch.joint, level, text, values))
        return out
