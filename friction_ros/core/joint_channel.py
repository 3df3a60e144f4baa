"""One joint of a multi-joint node: the per-joint holder of the controller's
:class:`~friction_ros.core.joint_group.JointGroup` and the estimator's
:class:`~friction_ros.core.estimation.joint_estimators.EstimatorGroup` (pure, no rclpy).

A channel is a joint's input gate (:class:`~friction_ros.core.input_gate.JointInputGate`), the
freshness of its state and its counters; the group puts its worker in it (``controller`` with its
reference and command, or ``estimator``). Log lines and diagnostics leave the core as events
``(level, text)`` with the levels of diagnostic_msgs/DiagnosticStatus (``OK`` = info, ``WARN``,
``ERROR``): the node logs them, one call site per level.
"""

from __future__ import annotations

import dataclasses
from typing import Any

from friction_ros.core.input_gate import DUPLICATE, REJECTED, RESYNC, JointInputGate

#: levels of diagnostic_msgs/DiagnosticStatus; as log levels OK is info
OK, WARN, ERROR = 0, 1, 2


class JointChannel:
    """One joint: gate, freshness, counters and its worker (see the module docstring)."""

    def __init__(self, joint: str, gate: JointInputGate, values: dict | None = None, overrides=None):
        self.joint = joint
        self.label = ""  # prefix of its log lines ("<joint>: " in a group of several joints)
        self.gate = gate
        self.values: dict[str, Any] = values if values is not None else {}
        self.overrides: dict[str, Any] = overrides if overrides is not None else {}
        self.diag_rejected = 0  # gate rejections at the last diagnostics status
        self.last_state_s: float | None = None  # clock of the last valid state (s; None: never)
        self.timed_out = False
        # controller side (JointGroup)
        self.controller = None
        self.reference = None  # the built-in reference generator
        self.has_reference = True  # add-on: whether the generator counts (a reference section given)
        self.trajectory = None  # from the reference topic
        self.desired: tuple[float, float, float] | None = None  # from desired_joint_states
        self.command = 0.0
        self.compensation = 0.0
        self.terms = None  # the ControllerTerms of the last computed period
        self.fallback_logged = ""  # the fallback reason last logged
        self.residual_logged = False
        self.waiting_logged = False
        # estimator side (EstimatorGroup)
        self.estimator = None
        self.config: dict[str, Any] = {}
        self.last_ns: int | None = None  # stamp of the last sample the estimator took
        self.counts = {"samples": 0, "excited_samples": 0, "published": 0}
        self.index = -1  # in the current joint_states layout (-1: the gate's admit looks)

    def admit(self, msg, now_ns: int, events: list, rejected: str, label: str = "") -> int:
        """Gate ``msg`` for this joint (:meth:`JointInputGate.admit`); returns the gate's status,
        its log line goes to ``events`` (:meth:`note`)."""
        status = self.gate.admit(msg, now_ns)
        if self.gate.log_line:
            self.note(status, events, rejected, label)
        return status

    def note(self, status: int, events: list, rejected: str, label: str = "") -> None:
        """The gate's log line as an event: a rejection (``rejected``: the words after its line)
        and a re-synchronisation (``label``: before its line) WARN, a recovery OK."""
        line = self.gate.log_line
        if not line:
            return
        if status == REJECTED:
            events.append((WARN, f"{line}; {rejected}"))
        elif status == RESYNC:
            events.append((WARN, label + line))
        elif status != DUPLICATE:
            events.append((OK, line))

    def gate_values(self) -> tuple[int, dict[str, Any]]:
        """(rejections since the last call, the gate's diagnostics values)."""
        gate = self.gate
        log = gate.log
        values = {"rejected_states": log.total, **log.values()}
        values.update(unstamped_states=gate.counts["unstamped"], resyncs=gate.counts["resyncs"])
        new, self.diag_rejected = log.total - self.diag_rejected, log.total
        return new, values

    @property
    def reference_limits(self):
        """The limits a reference must respect at the door: the controller's, and no more than the
        input gate's plausibility bounds (``input_gate.max_position`` / ``max_velocity``)."""
        lim, gate = self.controller.limits, self.gate
        return dataclasses.replace(
            lim,
            position_min=max(lim.position_min, -gate.max_position),
            position_max=min(lim.position_max, gate.max_position),
            velocity_limit=min(lim.velocity_limit, gate.max_velocity),
        )
