"""One identification experiment run without ROS: what the identification_experiment node does with
each ``joint_states`` message, when it ends and what it reports.

Every new state (stamp ``t_ns`` after the last one) is one control period: the program (one joint:
:class:`~friction_ros.core.experiment.excitation.ExcitationProgram`; an arm:
:class:`~friction_ros.core.experiment.arm.ArmExperiment`) is evaluated at ``t = (t_ns - t0_ns) 1e-9``
s of joint time, ``t0_ns`` the first answered stamp. A state with the last stamp is a lockstep
re-send: answered with the cached command (nothing recomputed); an older one is not answered. Once
the program is over (completed, stopped by a safety limit, or the joint not excited) states up to
``end_tail`` s of joint time later are answered (with zero torque, by the program), later ones are
not, so a lockstep plant stops at the same simulated time on any machine. The exit code is
:data:`~friction_ros.core.experiment.excitation.EXIT_ABORTED`, ``EXIT_NOT_EXCITED`` or 0. Log
lines are returned as events ``(level, text)`` (levels of :mod:`friction_ros.core.joint_channel`).
"""

from __future__ import annotations

import math

from friction_ros.core.experiment.arm import ArmExperiment, hold_gains
from friction_ros.core.experiment.events import EVENT_NAMES
from friction_ros.core.experiment.excitation import EXIT_ABORTED, EXIT_NOT_EXCITED, ExcitationProgram
from friction_ros.core.experiment.excitation_config import SECTIONS
from friction_ros.core.input_gate import select_sample
from friction_ros.core.joint_channel import ERROR, OK, WARN
from friction_ros.core.joint_config import JointNames, joint_errors

WRONG_JOINT_LOG_PERIOD = 10.0  # s between two "joint not in joint_states" lines
ABORT = 2  # ExperimentEvent.event of an aborted segment
#: what :meth:`ExperimentRun.step` did with a state
IGNORED, RESEND, COMPUTED = "ignored", "resend", "computed"


def program_config(values: dict, node_values: dict) -> dict:
    """An excitation program's config from the node's values (``values``: one joint's, on an arm)."""
    cfg = {s: values[s] for s in SECTIONS}
    cfg.update(
        program=values["program"],
        profile=node_values["profile"],
        sequence=list(values["sequence"]),
        gap=values["gap"],
        bias=values["bias"],
        control_period=node_values["control_period"],
    )
    return cfg


def arm_experiment(joints, joint_values: dict, node_values: dict, layout, overrides: dict) -> ArmExperiment:
    """The experiment of an arm: one program and PD hold per joint (``joint_values[j]``: joint j's
    values, ``overrides[j]`` its own ones); every message names a joint's parameters as written
    (:class:`~friction_ros.core.joint_config.JointNames`)."""
    programs, holds = [], []
    for j in joints:
        jv = joint_values[j]
        names = JointNames(layout, j, overrides[j])
        with joint_errors(names):
            prog = ExcitationProgram(program_config(jv, node_values), names)
            holds.append(hold_gains(prog.config, jv["hold_p"], jv["hold_d"]))
        programs.append(prog)
    return ArmExperiment(joints, programs, node_values["joint_sequence"], node_values["joint_gap"], holds)


def event_line(e, joint: str = "") -> str:
    """The log line of a program event (``joint``: the arm joint it is about, '' for one joint)."""
    who = f"{joint}: " if joint and not e.note.startswith(f"joint {joint}: ") else ""
    return f"{who}{EVENT_NAMES[e.event]} {e.program}/{e.segment} at {e.time:.3f} s {e.note}".rstrip()


class ExperimentRun:
    """The per-state bookkeeping of the identification_experiment node (module docstring).

    ``program``: an ExcitationProgram (``arm_joints`` empty, ``joint`` its joint) or an
    ArmExperiment (``arm_joints`` its joints); ``end_tail`` [s] of joint time.
    """

    def __init__(self, program, joint: str, arm_joints, end_tail: float):
        self.program = program
        self.joint = joint
        self.arm_joints = list(arm_joints)
        self.end_tail = end_tail
        self.t0_ns: int | None = None
        self.last_ns: int | None = None
        self.end_ns: int | None = None
        self.code = 0  # the exit code once the program is over
        self.wrong_joint_logged: float | None = None
        self.counts = {"cycles": 0, "duplicates": 0, "rejected_states": 0, "events": 0, "aborts": 0}

    # -- states ---------------------------------------------------------------------------------------
    def select(self, msg, now: float) -> tuple[list | None, list]:
        """``(samples, log events)``: one ``(position, velocity|None, effort|None)`` per joint of a
        JointState-like ``msg``, or None when it lacks one (counted; a warning at most every
        ``WRONG_JOINT_LOG_PERIOD`` s of wall time ``now``)."""
        samples = []
        for j in self.arm_joints or [self.joint]:
            sel, reason, detail = select_sample(msg, j)
            if sel is None:
                return None, self._rejected(msg, j, reason, detail, now)
            samples.append(sel)
        return samples, []

    def _rejected(self, msg, joint: str, reason: str, detail: str, now: float) -> list:
        self.counts["rejected_states"] += 1
        last = self.wrong_joint_logged
        if last is not None and now - last < WRONG_JOINT_LOG_PERIOD:
            return []
        self.wrong_joint_logged = now
        n = self.counts["rejected_states"]
        if reason != "wrong_joint":
            return [(WARN, f"ignored joint_states: {detail} ({n} state(s) ignored so far)")]
        seen = ", ".join(msg.name) if msg.name else f"{len(msg.position)} unnamed position(s)"
        fix = (
            "set joint_name (friction-experiment --joint) to one of them"
            if not self.arm_joints
            else "set joints (friction-experiment --joints) to joints they carry"
        )
        return [
            (
                WARN,
                f"joint_states carry no joint {joint!r} (they carry: {seen}); {fix} "
                f"({n} state(s) ignored so far)",
            )
        ]

    def step(self, t_ns: int, samples, can_resend: bool) -> tuple[str, object, list, list]:
        """``(action, command, program events, log events)`` for a state stamped ``t_ns`` [ns].

        ``action``: IGNORED (not answered), RESEND (answer with the cached command, when
        ``can_resend``: there is one) or COMPUTED (``command``: the torque [N*m], a list on an arm;
        program events as ``(joint, event)``, joint '' for one joint)."""
        if self.end_ns is not None and t_ns > self.end_ns:
            return IGNORED, None, [], []  # the program and its tail are over (ends on joint time)
        if self.last_ns is not None and t_ns <= self.last_ns:
            if t_ns == self.last_ns and can_resend:
                self.counts["duplicates"] += 1
                return RESEND, None, [], []  # lockstep re-send: same answer, no recompute
            return IGNORED, None, [], []
        if self.t0_ns is None:
            self.t0_ns = t_ns
        self.last_ns = t_ns
        t = (t_ns - self.t0_ns) * 1e-9
        vel = [math.nan if s[1] is None else s[1] for s in samples]
        if self.arm_joints:
            command, arm_events = self.program.update(t, [s[0] for s in samples], vel)
            events = [(self.arm_joints[i], e) for i, e in arm_events]
        else:
            command, single = self.program.update(t, samples[0][0], vel[0])
            events = [("", e) for e in single]
        self.counts["cycles"] += 1
        return COMPUTED, command, events, []

    def count_event(self, e) -> None:
        """Count a published program event (an ABORT also as an abort)."""
        self.counts["events"] += 1
        if e.event == ABORT:
            self.counts["aborts"] += 1

    def finish(self, t_ns: int, wall: float) -> list:
        """The program just ended at the state ``t_ns``: book the end of the tail, set the exit code
        and return its log line (``wall``: wall time [s] since the first state)."""
        self.end_ns = t_ns + int(round(self.end_tail * 1e9))
        prog = self.program
        st = prog.status()
        if prog.aborted and prog.on_limit == "stop":
            self.code = EXIT_ABORTED
            return [
                (ERROR, f"program stopped by a safety limit at t = {st.time:.2f} s: {prog.abort_reasons[-1]}")
            ]
        if prog.not_excited is not None:
            self.code = EXIT_NOT_EXCITED
            return [(ERROR, f"program stopped at t = {st.time:.2f} s: {prog.not_excited}")]
        return [
            (
                OK,
                f"[100%] program {prog.name} complete: {st.time:.2f} s simulated/real joint time in {wall:.1f} s wall",
            )
        ]

    # -- reports --------------------------------------------------------------------------------------
    def progress_line(self) -> str:
        """The progress line: percentage, program, segment, joint time."""
        st = self.program.status()
        return (
            f"[{100 * st.progress:3.0f}%] {st.program} {st.segment} ({st.segment_number}/{st.segments}) "
            f"t = {st.time:.1f} / {st.total:.1f} s"
        )

    def diagnostics(self) -> tuple[int, str, dict]:
        """``(level, text, values)`` of the diagnostics status."""
        prog = self.program
        st = prog.status()
        values = dict(self.counts)
        values.update(
            progress=round(st.progress, 4),
            program=st.program,
            segment=st.segment,
            time_s=st.time,
            total_s=st.total,
        )
        level, text = OK, "running" if self.t0_ns is not None else "waiting for joint states"
        if prog.not_excited is not None:
            level, text = ERROR, prog.not_excited
        elif prog.aborted:
            level, text = WARN, f"segment aborted: {prog.abort_reasons[-1]}"
            if prog.done and prog.on_limit == "stop":
                level = ERROR
        elif prog.done:
            text = "complete"
        return level, text, values
