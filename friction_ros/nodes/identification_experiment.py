"""identification_experiment: run an excitation program (friction_ros.core.experiment.excitation) on one joint.

Drives the joint directly with a joint torque, event-driven like the controller: every
``joint_states`` message is one control period and is answered by one ``joint_commands`` message
whose header stamp is the state's stamp (lockstep-safe: a duplicate state, same stamp, is answered
with the cached command, nothing is recomputed).

Topics (relative, so one namespace per joint works):

* in  ``joint_states`` (sensor_msgs/JointState; STATE_QOS)
* out ``joint_commands`` (sensor_msgs/JointState effort = joint torque N*m; COMMAND_QOS),
  ``experiment_events`` (friction_msgs/ExperimentEvent, START/END/ABORT segment markers stamped
  with the state they belong to; STATE_QOS), ``diagnostics``

Parameters: the node's own (below) and the program's sections, one ROS parameter per leaf
(``plateaus.v_min``, ``breakaway.resolution``, ``limits.max_velocity`` ...; defaults from
``profile``, ranges checked by the core: a bad value refuses to start with one clear line).

The program starts with the first joint state once ``wait_for_subscribers`` subscribers (e.g. the
bag recorder) listen on ``experiment_events`` and ``joint_states``; until then states are not
answered (lockstep: the plant waits; realtime: the plant/drive applies zero torque by timeout).
When the program is over (completed or stopped by a safety limit) the node answers with zero
torque for ``end_tail`` seconds of joint time (stamps, not wall time), then answers no more states
(a lockstep plant stops, so the record ends at the same simulated time on any machine), waits
``exit_delay`` of wall time and exits by itself: exit code 0 when it completed, 3 when a safety
limit stopped it, 4 when the joint was not excited (the program's motion check,
``motion_check.*``: no motion, no reversals, plateaus that do not reach their speed; an ABORT
event and an error line give the reason). Ctrl-C/SIGTERM: zero torque, exit. Progress
(percentage, segment) is logged every ``progress_period`` s of wall time. Joint states that do not
carry ``joint_name`` are logged (once, naming the joints they carry, then every 10 s while they
last), so a wrong joint name does not wait silently.

An arm (``joints: [j1, j2, ...]``; unset = the one joint ``joint_name``, exactly as before): one
program per joint (:mod:`friction_ros.core.experiment.arm`), every ``joint_states`` message (which
must carry every joint) answered by one ``joint_commands`` message with every joint's torque.
``joint_sequence``: ``one_at_a_time`` (default; the joints in turn, ``joint_gap`` s apart, the
others held at their position by a PD hold with ``hold_p``/``hold_d``, by default each joint's
velocity-loop gains, which are the tracking design's PD) or ``together``. Per-joint values in the
layout of :mod:`friction_ros.core.joint_config`: ``<section>.<joint>.<key>`` (``limits.j2.max_travel``,
``plateaus.j2.v_max`` ...) and ``gains.<joint>.<key>`` for ``program``, ``sequence``, ``gap``,
``bias``, ``hold_p``, ``hold_d``, on top of the node-level values. Each event names its joint in
``header.frame_id`` (``friction-fit --joint j2`` keeps j2's; a single-joint experiment leaves it
empty). A joint leaving its limits (held or excited, ``on_limit: stop``) or not excited stops the
whole experiment: zero torque on every joint and one error line naming the joint and the limit
(``joint j2: position limit ... limits.j2.max_travel``); the exit codes are those above.
"""

from __future__ import annotations

import copy
import dataclasses
import math
import time

from friction_msgs.msg import ExperimentEvent
from sensor_msgs.msg import JointState

from friction_ros.core.config import Field, Schema
from friction_ros.core.control_period import control_period_field
from friction_ros.core.experiment.arm import SEQUENCES, ArmExperiment, hold_gains
from friction_ros.core.experiment.events import EVENT_NAMES
from friction_ros.core.experiment.excitation import EXIT_ABORTED, EXIT_NOT_EXCITED, ExcitationProgram
from friction_ros.core.experiment.excitation_config import DEFAULTS, PROFILES, SECTIONS, profile_defaults
from friction_ros.core.input_gate import select_sample
from friction_ros.core.joint_config import GAINS, name_joint_error
from friction_ros.core.validation import ParameterError
from friction_ros.nodes.commands import ArmCommandPublisher, CommandPublisher, stamp_to_ns
from friction_ros.nodes.diagnostics import ERROR, OK, WARN, DiagnosticsPublisher
from friction_ros.nodes.joint_parameters import declare_joint_config, declare_joints, values_of_joint
from friction_ros.nodes.parameters import ParameterNode, declare_config
from friction_ros.nodes.qos import RECORDED_QOS, STATE_QOS
from friction_ros.nodes.runtime import request_stop, run_node
from friction_ros.nodes.safe_subscription import safe_subscription

WRONG_JOINT_LOG_PERIOD = 10.0  # s between two "joint not in joint_states" lines
# s of wall time the recorders must stay matched before the program starts: the plant's state
# publisher discovers and matches them on its own time; with both cores loaded that took longer
# than 0.5 s once in a CI run (the bag lacked the first state, so the fit of the same run differed)
MATCH_GRACE = 2.0

NODE_FIELDS = [
    Field("joint_name", "joint1", "joint to excite (name in joint_states / joint_commands)", read_only=True),
    Field(
        "profile",
        "default",
        "program defaults: default (~2 min, ABB M19-S scale) or quick (~30 s, tests/demo)",
        choices=tuple(PROFILES),
        read_only=True,
    ),
    Field(
        "program",
        "sequence",
        "excitation program: plateaus, breakaway, random, chirp, presliding or sequence",
        choices=("plateaus", "breakaway", "random", "chirp", "presliding", "sequence"),
        read_only=True,
    ),
    Field(
        "sequence",
        list(DEFAULTS["sequence"]),
        "programs run by 'sequence', in order",
        read_only=True,
    ),
    Field(
        "gap",
        float(DEFAULTS["gap"]),
        "zero-torque pause between programs",
        lo=0.0,
        hi=60.0,
        unit="s",
        read_only=True,
    ),
    Field(
        "bias",
        float(DEFAULTS["bias"]),
        "torque added to every command of the program: holds a constant load such as gravity",
        lo=-1e6,
        hi=1e6,
        unit="N*m",
        read_only=True,
    ),
    control_period_field("nominal period of the joint states"),
    Field(
        "wait_for_subscribers",
        0,
        "start only once this many subscribers listen on experiment_events (the recorder)",
        lo=0,
        hi=100,
        read_only=True,
    ),
    Field("exit_when_done", True, "exit by itself when the program is over", read_only=True),
    Field(
        "end_tail",
        0.2,
        "joint time answered with zero torque after the program ends; later states are not answered, "
        "so a lockstep plant stops and the record ends on simulated time",
        lo=0.0,
        hi=60.0,
        unit="s",
        read_only=True,
    ),
    Field(
        "exit_delay", 0.5, "wall time between the end of the program and the exit", lo=0.0, hi=60.0, unit="s"
    ),
    Field(
        "progress_period",
        2.0,
        "log progress every this much wall time (0: never)",
        lo=0.0,
        hi=3600.0,
        unit="s",
    ),
    Field("diagnostics_period", 1.0, "period of the diagnostics status", lo=0.05, hi=60.0, unit="s"),
]
#: the node's parameters with ``joints`` (an arm); without ``joints`` they are not declared
ARM_FIELDS = [
    Field(
        "joint_sequence",
        SEQUENCES[0],
        "with joints: one_at_a_time (each joint's program in turn, the others held by a PD hold) or "
        "together (every joint's program at once)",
        choices=SEQUENCES,
        read_only=True,
    ),
    Field(
        "joint_gap",
        0.5,
        "with joints, one_at_a_time: time every joint is held between two joints' programs",
        lo=0.0,
        hi=60.0,
        unit="s",
        read_only=True,
    ),
    Field(
        "hold_p",
        0.0,
        "PD hold of a joint not being excited: position gain (0: the joint's velocity_loop.i, the "
        "tracking design's K_p)",
        lo=0.0,
        hi=1e9,
        unit="N*m/rad",
        read_only=True,
    ),
    Field(
        "hold_d",
        0.0,
        "PD hold: velocity gain (0: the joint's velocity_loop.p, the tracking design's K_d)",
        lo=0.0,
        hi=1e9,
        unit="N*m*s/rad",
        read_only=True,
    ),
]
#: node-level keys a joint may have its own value of, as ``gains.<joint>.<key>``
PER_JOINT_PLAIN_KEYS = ("program", "sequence", "gap", "bias", "hold_p", "hold_d")
_RESULT = {"code": 0}


def _profile_of(node: ParameterNode) -> str:
    given = node.given_parameters.get("profile")
    return given.value if given is not None and given.value in PROFILES else "default"


def parameter_schema(profile: str = "default", arm: bool = False) -> Schema:
    """The node's parameters; program-level defaults follow the chosen ``profile``. ``arm``: with
    the parameters of an experiment on several joints (``joints``)."""
    base = profile_defaults(profile)
    fields = [
        dataclasses.replace(f, default=copy.deepcopy(base[f.name])) if f.name in ("sequence", "gap") else f
        for f in NODE_FIELDS
    ]
    sections = [Schema.from_defaults(s, base[s], f"{s} parameter", read_only=True) for s in SECTIONS]
    return Schema("identification_experiment", [*fields, *(ARM_FIELDS if arm else []), *sections])


class IdentificationExperiment(ParameterNode):
    """Thin adapter over :class:`ExcitationProgram`; see the module docstring."""

    def __init__(self):
        super().__init__("identification_experiment")
        profile = _profile_of(self)
        reserved = {item.name for item in parameter_schema(profile, arm=True)} | {GAINS, "joints"}
        self.arm_joints = declare_joints(self, reserved)  # [] -> one joint, joint_name
        if self.arm_joints:
            self._init_arm(profile)
        else:
            self.values = declare_config(self, parameter_schema(profile), self._apply)
            self.program = ExcitationProgram(_program_config(self.values, self.values))  # may refuse
            self.joint = self.values["joint_name"]
            self.commands = CommandPublisher(self, self.joint)
        self.event_pub = self.create_publisher(ExperimentEvent, "experiment_events", RECORDED_QOS)
        safe_subscription(self, JointState, "joint_states", self._on_state, STATE_QOS)
        self.diag = DiagnosticsPublisher(self, "identification_experiment", self.joint)
        self.create_timer(self.values["diagnostics_period"], self._publish_diagnostics)
        self.create_timer(0.05, self._check_exit)

        self._t0_ns: int | None = None
        self._last_ns: int | None = None
        self._last_stamp = None
        self._ready = self.values["wait_for_subscribers"] == 0
        self._seen_since: float | None = None
        self._done_wall: float | None = None
        self._end_ns: int | None = None
        self._last_progress = time.monotonic()
        self._wall0: float | None = None
        self._wrong_joint_logged: float | None = None
        self.counts = {"cycles": 0, "duplicates": 0, "rejected_states": 0, "events": 0, "aborts": 0}
        what = (
            f"joint {self.joint}"
            if not self.arm_joints
            else f"joints {', '.join(self.arm_joints)} ({self.values['joint_sequence']})"
        )
        self.get_logger().info(
            f"program {self.program.name} (profile {self.values['profile']}): {self.program.marked_count} "
            f"segments, {self.program.total_duration:.1f} s planned; {what}"
            + ("" if self._ready else f"; waiting for {self.values['wait_for_subscribers']} recorder(s)")
        )

    def _init_arm(self, profile: str) -> None:
        """Several joints: per-joint programs and holds (module docstring of core.experiment.arm)."""
        joints = self.arm_joints
        self.values, self.layout, overrides = declare_joint_config(
            self, parameter_schema(profile, arm=True), joints, self._apply, plain_keys=PER_JOINT_PLAIN_KEYS
        )
        programs, holds = [], []
        for j in joints:
            jv = values_of_joint(self.values, overrides[j], j, single=False)
            try:
                prog = ExcitationProgram(_program_config(jv, self.values))
                holds.append(hold_gains(prog.config, jv["hold_p"], jv["hold_d"]))
            except ParameterError as exc:
                raise ParameterError(name_joint_error(str(exc), self.layout, j, overrides[j])) from None
            programs.append(prog)

        def describe(joint: str, text: str) -> str:
            named = name_joint_error(text, self.layout, joint, overrides[joint])
            return named if named.startswith(f"joint {joint}: ") else f"joint {joint}: {named}"

        self.program = ArmExperiment(
            joints, programs, self.values["joint_sequence"], self.values["joint_gap"], holds, describe
        )
        self.joint = ",".join(joints)
        self.commands = ArmCommandPublisher(self, joints)

    def _apply(self, changes: dict) -> None:
        self.values.update(changes)

    # -- loop -------------------------------------------------------------------------------------
    def _subscribers_ready(self) -> bool:
        """The recorder(s) are discovered on both topics, matched to our event publisher, and have
        been for ``MATCH_GRACE`` s of wall time (the plant's state publisher matches them in that
        time too; states are not answered meanwhile, so a lockstep run stays the same run)."""
        n = self.values["wait_for_subscribers"]
        seen = (
            self.count_subscribers("experiment_events") >= n
            and self.event_pub.get_subscription_count() >= n  # matched, not only discovered
            and self.count_subscribers("joint_states") >= n + 1
        )
        now = time.monotonic()
        if not seen:
            self._seen_since = None
            return False
        if self._seen_since is None:
            self._seen_since = now
        return now - self._seen_since >= MATCH_GRACE

    def _rejected_state(self, msg: JointState, joint: str, reason: str, detail: str) -> None:
        self.counts["rejected_states"] += 1
        now = time.monotonic()
        if self._wrong_joint_logged is None or now - self._wrong_joint_logged >= WRONG_JOINT_LOG_PERIOD:
            self._wrong_joint_logged = now
            seen = ", ".join(msg.name) if msg.name else f"{len(msg.position)} unnamed position(s)"
            fix = (
                "set joint_name (friction-experiment --joint) to one of them"
                if not self.arm_joints
                else "set joints (friction-experiment --joints) to joints they carry"
            )
            self.get_logger().warning(
                f"joint_states carry no joint {joint!r} (they carry: {seen}); {fix} "
                f"({self.counts['rejected_states']} state(s) ignored so far)"
                if reason == "wrong_joint"
                else f"ignored joint_states: {detail} ({self.counts['rejected_states']} state(s) ignored so far)"
            )

    def _on_state(self, msg: JointState) -> None:
        if self.arm_joints:
            samples = []
            for j in self.arm_joints:
                sel, reason, detail = select_sample(msg, j)
                if sel is None:
                    self._rejected_state(msg, j, reason, detail)
                    return
                samples.append(sel)
        else:
            sel, reason, detail = select_sample(msg, self.joint)
            if sel is None:
                self._rejected_state(msg, self.joint, reason, detail)
                return
        if not self._ready:
            if not self._subscribers_ready():
                return  # not answered: lockstep plant waits and re-sends, realtime plant times out to 0
            self._ready = True
            self.get_logger().info("subscribers present: starting the program")
        t_ns = stamp_to_ns(msg.header.stamp)
        if self._end_ns is not None and t_ns > self._end_ns:
            return  # the program and its tail are over: not answered (ends on joint time)
        if self._last_ns is not None and t_ns <= self._last_ns:
            if t_ns == self._last_ns and self.commands.last is not None:
                self.counts["duplicates"] += 1
                self.commands.republish()  # lockstep re-send: same answer, no recompute
            return
        if self._t0_ns is None:
            self._t0_ns = t_ns
            self._wall0 = time.monotonic()
        self._last_ns = t_ns
        self._last_stamp = msg.header.stamp
        t = (t_ns - self._t0_ns) * 1e-9
        if self.arm_joints:
            vel = [math.nan if s[1] is None else s[1] for s in samples]
            torques, arm_events = self.program.update(t, [s[0] for s in samples], vel)
            for i, e in arm_events:
                self._publish_event(msg.header.stamp, e, self.arm_joints[i])
            self.commands.publish(msg.header.stamp, torques)
        else:
            pos, vel, _effort = sel
            if vel is None:
                vel = math.nan
            torque, events = self.program.update(t, pos, vel)
            for e in events:
                self._publish_event(msg.header.stamp, e)
            self._publish_command(msg.header.stamp, torque)
        self.counts["cycles"] += 1
        self._report_progress()
        if self.program.done and self._done_wall is None:
            self._done_wall = time.monotonic()
            self._end_ns = t_ns + int(round(self.values["end_tail"] * 1e9))
            st = self.program.status()
            wall = time.monotonic() - (self._wall0 or time.monotonic())
            if self.program.aborted and self.program.on_limit == "stop":
                _RESULT["code"] = EXIT_ABORTED
                self.get_logger().error(
                    f"program stopped by a safety limit at t = {st.time:.2f} s: {self.program.abort_reasons[-1]}"
                )
            elif self.program.not_excited is not None:
                _RESULT["code"] = EXIT_NOT_EXCITED
                self.get_logger().error(f"program stopped at t = {st.time:.2f} s: {self.program.not_excited}")
            else:
                self.get_logger().info(
                    f"[100%] program {self.program.name} complete: {st.time:.2f} s simulated/real joint time "
                    f"in {wall:.1f} s wall"
                )

    def _publish_event(self, stamp, e, joint: str = "") -> None:
        """``joint`` (an arm): the joint the event is about, in ``header.frame_id`` (events.event_joint_matches)."""
        m = ExperimentEvent()
        m.header.stamp = stamp
        m.header.frame_id = joint
        m.program = e.program
        m.segment = e.segment
        m.index = int(e.index)
        m.event = int(e.event)
        m.target = float(e.target)
        m.note = e.note
        self.event_pub.publish(m)
        self.counts["events"] += 1
        if e.event != 0:
            level = self.get_logger().warning if e.event == 2 else self.get_logger().debug
            who = f"{joint}: " if joint and not e.note.startswith(f"joint {joint}: ") else ""
            level(f"{who}{EVENT_NAMES[e.event]} {e.program}/{e.segment} at {e.time:.3f} s {e.note}".rstrip())
        if e.event == 2:
            self.counts["aborts"] += 1

    def _publish_command(self, stamp, torque: float) -> None:
        self.commands.publish(stamp, torque)

    def _report_progress(self) -> None:
        period = self.values["progress_period"]
        now = time.monotonic()
        if period <= 0 or now - self._last_progress < period or self.program.done:
            return
        self._last_progress = now
        st = self.program.status()
        self.get_logger().info(
            f"[{100 * st.progress:3.0f}%] {st.program} {st.segment} ({st.segment_number}/{st.segments}) "
            f"t = {st.time:.1f} / {st.total:.1f} s"
        )

    # -- end, safety, health ----------------------------------------------------------------------
    def _check_exit(self) -> None:
        if self._done_wall is None or not self.values["exit_when_done"]:
            return
        if time.monotonic() - self._done_wall >= self.values["exit_delay"]:
            self._done_wall = math.inf  # once
            request_stop()  # run_node leaves its loop and calls on_shutdown()

    def _publish_diagnostics(self) -> None:
        st = self.program.status()
        values = dict(self.counts)
        values.update(
            progress=round(st.progress, 4),
            program=st.program,
            segment=st.segment,
            time_s=st.time,
            total_s=st.total,
        )
        level, text = OK, "running" if self._t0_ns is not None else "waiting for joint states"
        if self.program.not_excited is not None:
            level, text = ERROR, self.program.not_excited
        elif self.program.aborted:
            level, text = WARN, f"segment aborted: {self.program.abort_reasons[-1]}"
            if self.program.done and self.program.on_limit == "stop":
                level = ERROR
        elif self.program.done:
            text = "complete"
        self.diag.publish(level, text, values)

    def on_shutdown(self) -> None:
        """Leave the joint(s) safe: answer the newest state (or now) with zero torque."""
        stamp = self._last_stamp if self._last_stamp is not None else self.get_clock().now().to_msg()
        for _ in range(3):
            if self.arm_joints:
                self.commands.publish(stamp, [0.0] * len(self.arm_joints))
            else:
                self._publish_command(stamp, 0.0)
            time.sleep(0.01)


def _program_config(values: dict, node_values: dict) -> dict:
    """An excitation program's config from the node's values (``values``: one joint's, on an arm)."""
    cfg = {s: values[s] for s in SECTIONS}
    cfg.update(
        program=values["program"],
        profile=node_values["profile"],
        sequence=list(values["sequence"]),
        gap=values["gap"],
        bias=values["bias"],
        dt=node_values["control_period"],
    )
    return cfg


def main(args=None) -> int:
    rc = run_node(IdentificationExperiment, args)
    return rc or _RESULT["code"]


if __name__ == "__main__":
    raise SystemExit(main())
