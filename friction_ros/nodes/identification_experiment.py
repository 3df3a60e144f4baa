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

import math
import time

from builtin_interfaces.msg import Time
from friction_msgs.msg import ExperimentEvent
from sensor_msgs.msg import JointState

from friction_ros.core.experiment.excitation import ExcitationProgram
from friction_ros.core.experiment.experiment_run import (
    ABORT,
    COMPUTED,
    RESEND,
    ExperimentRun,
    arm_experiment,
    event_line,
    program_config,
)
from friction_ros.core.joint_config import GAINS
from friction_ros.core.wire import DecodedJointState, JointStateDecoder
from friction_ros.nodes.commands import ArmCommandPublisher, CommandPublisher
from friction_ros.nodes.diagnostics import DiagnosticsPublisher
from friction_ros.nodes.experiment_parameters import (  # noqa: F401 (the node's API)
    PER_JOINT_PLAIN_KEYS,
    parameter_schema,
    profile_of,
)
from friction_ros.nodes.joint_parameters import declare_joint_config, declare_joints, values_of_joint
from friction_ros.nodes.parameters import ParameterNode, declare_config
from friction_ros.nodes.qos import RECORDED_QOS, STATE_QOS
from friction_ros.nodes.runtime import log_events, request_stop, run_node, wait_delivered
from friction_ros.nodes.safe_subscription import safe_subscription

# s of wall time the recorders must stay matched before the program starts: the plant's state
# publisher discovers and matches them on its own time; with both cores loaded that took longer
# than 0.5 s once in a CI run (the bag lacked the first state, so the fit of the same run differed)
MATCH_GRACE = 2.0


class IdentificationExperiment(ParameterNode):
    """Thin adapter over :class:`~friction_ros.core.experiment.experiment_run.ExperimentRun`; see
    the module docstring."""

    def __init__(self, **kwargs):
        super().__init__("identification_experiment", **kwargs)
        #: the process exit code this node asks for (0, 3 or 4: module docstring); run_node and
        #: composition return it
        self.exit_code = 0
        profile = profile_of(self)
        reserved = {item.name for item in parameter_schema(profile, arm=True)} | {GAINS, "joints"}
        self.arm_joints = declare_joints(self, reserved)  # [] -> one joint, joint_name
        if self.arm_joints:
            joints = self.arm_joints
            self.values, self.layout, overrides = declare_joint_config(
                self,
                parameter_schema(profile, arm=True),
                joints,
                self._apply,
                plain_keys=PER_JOINT_PLAIN_KEYS,
            )
            per_joint = {j: values_of_joint(self.values, overrides[j], j, single=False) for j in joints}
            self.program = arm_experiment(joints, per_joint, self.values, self.layout, overrides)
            self.joint = ",".join(joints)
            self.commands = ArmCommandPublisher(self, joints)
        else:
            self.values = declare_config(self, parameter_schema(profile), self._apply)
            self.program = ExcitationProgram(program_config(self.values, self.values))  # may refuse
            self.joint = self.values["joint_name"]
            self.commands = CommandPublisher(self, self.joint)
        self.run = ExperimentRun(self.program, self.joint, self.arm_joints, self.values["end_tail"])
        self.counts = self.run.counts
        self.event_pub = self.create_publisher(ExperimentEvent, "experiment_events", RECORDED_QOS)
        # joint states decoded by the wire module (no rclpy message object per period)
        self._decoder = JointStateDecoder()
        safe_subscription(
            self, JointState, "joint_states", self._on_state, STATE_QOS, decode=self._decoder.decode
        )
        self.diag = DiagnosticsPublisher(self, "identification_experiment", self.joint)
        self.create_timer(self.values["diagnostics_period"], self._publish_diagnostics)
        self.create_timer(0.05, self._check_exit)

        self._last_stamp = None
        self._ready = self.values["wait_for_subscribers"] == 0
        self._seen_since: float | None = None
        self._done_wall: float | None = None
        self._last_progress = time.monotonic()
        self._wall0: float | None = None
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

    def _on_state(self, msg: DecodedJointState) -> None:
        samples, lines = self.run.select(msg, time.monotonic())
        log_events(self.get_logger(), lines)
        if samples is None:
            return
        if not self._ready:
            if not self._subscribers_ready():
                return  # not answered: lockstep plant waits and re-sends, realtime plant times out to 0
            self._ready = True
            self.get_logger().info("subscribers present: starting the program")
        t_ns = msg.stamp_ns
        action, command, events, _ = self.run.step(t_ns, samples, self.commands.last is not None)
        if action == RESEND:
            self.commands.republish()  # lockstep re-send: same answer, no recompute
        if action != COMPUTED:
            return
        if self._wall0 is None:
            self._wall0 = time.monotonic()
        self._last_stamp = (msg.sec, msg.nanosec)
        for joint, e in events:
            self._publish_event(Time(sec=msg.sec, nanosec=msg.nanosec), e, joint)
        self.commands.publish_stamp(msg.sec, msg.nanosec, command)
        self._report_progress()
        if self.program.done and self._done_wall is None:
            self._done_wall = time.monotonic()
            wall = time.monotonic() - (self._wall0 or time.monotonic())
            log_events(self.get_logger(), self.run.finish(t_ns, wall))
            self.exit_code = self.run.code

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
        self.run.count_event(e)
        if e.event == ABORT:
            self.get_logger().warning(event_line(e, joint))
        elif e.event != 0:
            self.get_logger().debug(event_line(e, joint))

    def _report_progress(self) -> None:
        period = self.values["progress_period"]
        now = time.monotonic()
        if period <= 0 or now - self._last_progress < period or self.program.done:
            return
        self._last_progress = now
        self.get_logger().info(self.run.progress_line())

    # -- end, safety, health ----------------------------------------------------------------------
    def _check_exit(self) -> None:
        if self._done_wall is None or not self.values["exit_when_done"]:
            return
        if time.monotonic() - self._done_wall >= self.values["exit_delay"]:
            self._done_wall = math.inf  # once
            request_stop()  # run_node leaves its loop and calls on_shutdown()

    def _publish_diagnostics(self) -> None:
        self.diag.publish(*self.run.diagnostics())

    def on_shutdown(self) -> None:
        """Leave the joint(s) safe: answer the newest state (or now) with zero torque; then let the
        recorder confirm the last events."""
        if self._last_stamp is not None:
            sec, nanosec = self._last_stamp
        else:
            now = self.get_clock().now().to_msg()
            sec, nanosec = now.sec, now.nanosec
        for _ in range(3):
            self.commands.publish_stamp(
                sec, nanosec, [0.0] * len(self.arm_joints) if self.arm_joints else 0.0
            )
            time.sleep(0.01)
        wait_delivered(self.event_pub, "experiment_events", self.get_logger())


def main(args=None) -> int:
    return run_node(IdentificationExperiment, args)


if __name__ == "__main__":
    raise SystemExit(main())
