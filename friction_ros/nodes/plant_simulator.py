"""plant_simulator: the gearhead DC servo plant (friction_ros.core.plant) as a ROS 2 node.

Stands in for the CAN drive interface with the same topics, so controller, estimator, recorder and
a ros2_control stack (topic_based_ros2_control) cannot tell the difference:

* subscribes ``joint_commands`` (sensor_msgs/JointState, effort = joint torque N*m; COMMAND_QOS)
* publishes ``joint_states`` (sensor_msgs/JointState: position rad, velocity rad/s, effort N*m;
  m, m/s and N with ``joint_type: prismatic``), ``diagnostics`` and, in lockstep, ``/clock``.

Modes:

``realtime``  a fixed-rate loop thread steps the plant every ``control_period`` of wall time with
              the newest command (zero torque once no command came for ``command_timeout``).
``lockstep``  the plant advances exactly one control period per command whose header stamp equals
              the stamp of the state it answers, publishes ``/clock`` then the new state. Nodes with
              ``use_sim_time`` follow; the whole graph runs as fast as it can and deterministically.
              If no answer arrives within ``resend_period`` (wall) the pending state is published
              again (a subscriber that joined late gets it); duplicate commands are ignored. With
              ``wait_for_subscribers`` N the first state goes out once ``joint_states`` has N
              subscribers: every one of them (a monitor too) sees the run from its first period.
              ``joint_states`` is published with LOCKSTEP_RECORDED_QOS (a 60,000-deep history): a
              recorder may fall a minute of joint time behind the graph before it loses a state.

Several joints (``joints: [j1, j2, ...]``; unset = the one joint ``joint_name``, exactly as before):
one core plant per joint, all stepped with the same ``control_period``, and one ``joint_states``
message per period with every joint (names in ``joints`` order). Per-joint plants:

* ``presets``: one preset per joint, in the order of ``joints`` (unset: every joint uses ``preset``);
* ``plant.<joint>.<key>``, ``friction_motor.<joint>.<key>``, ``friction_load.<joint>.<key>``: a
  joint's own values, laid over the node-level ``plant.*`` / ``friction_*.*`` values, which apply to
  every joint's preset (layout: :mod:`friction_ros.core.joint_config`); a per-joint friction section
  that names its own ``model`` replaces the node-level one for that joint. A robot joint's gravity
  load is ``plant.<joint>.gravity`` (m g l [N*m]) and ``plant.<joint>.gravity_phase`` [rad]
  (:mod:`friction_ros.core.plant.servo`). Example: ``params/arm7_plant.yaml``.

``joint_commands`` may name any subset of the joints (one message for all from one controller, or
one message per joint from one controller each); names that are not joints of this node are
ignored, a message naming none of them is ignored and counted. Realtime: each joint applies its
newest command and falls back to zero torque after ``command_timeout`` on its own. Lockstep: the
plant advances once every joint has a command stamped with the pending state's stamp (partial
messages are merged; a second command for an already answered joint is a duplicate, ignored).
With several joints the subscription keeps one command per joint (keep-last ``len(joints)``), so
answers that arrive together are not dropped. Diagnostics: one status for the node; with several
joints it also has ``<joint>.preset``, ``<joint>.commands_rejected`` and (realtime)
``<joint>.command_fresh``.
"""

from __future__ import annotations

import time

from builtin_interfaces.msg import Time
from rclpy.qos import QoSProfile
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState

from friction_ros.core.joint_config import JointLayout
from friction_ros.core.plant.multi_joint import PRESET_SECTIONS, resolve_joint_presets
from friction_ros.core.plant.stepping import PlantStepper
from friction_ros.core.validation import ParameterError
from friction_ros.core.wire import JointStateDecoder, JointStateEncoder
from friction_ros.nodes.command_owner import CommandOwnerWatch
from friction_ros.nodes.diagnostics import DiagnosticsPublisher
from friction_ros.nodes.joint_parameters import declare_joint_config, declare_joints
from friction_ros.nodes.loops import DeadlineLoop, LatencyHistogram
from friction_ros.nodes.parameters import ParameterNode, declare_config
from friction_ros.nodes.plant_health import PlantHealth
from friction_ros.nodes.plant_parameters import JOINTS_FIELD, parameter_schema
from friction_ros.nodes.qos import COMMAND_QOS, LOCKSTEP_RECORDED_QOS, RECORDED_QOS, STATE_QOS
from friction_ros.nodes.runtime import apply_scheduling, log_events, run_node, wait_delivered
from friction_ros.nodes.safe_subscription import BYTES, safe_subscription

__all__ = ["PlantSimulator", "main", "parameter_schema"]


class PlantSimulator(PlantHealth, ParameterNode):
    """Thin adapter: commands in, :class:`~friction_ros.core.plant.stepping.PlantStepper` (one
    GearheadServoPlant per joint), joint states out."""

    def __init__(self, **kwargs):
        super().__init__("plant_simulator", **kwargs)
        schema = parameter_schema(with_joints=False)
        reserved = {item.name for item in schema} | {JOINTS_FIELD.name}
        joints_param = declare_joints(self, reserved)
        if joints_param:
            self.p, self.layout, overrides = declare_joint_config(self, schema, joints_param, self._apply)
        else:  # one joint (joint_name): the parameters exactly as without ``joints``
            self.layout, overrides = JointLayout([], PRESET_SECTIONS), {}
            self.p = declare_config(self, schema, self._apply)
        self.p["joints"] = joints_param
        self.multi = bool(joints_param)
        self.joints = list(joints_param) if self.multi else [self.p["joint_name"]]
        # the node's control_period is every preset's (it owns the period the plants are stepped at)
        self.presets = resolve_joint_presets(self.p, self.joints, overrides)
        self.plants = [pr.make_plant() for pr in self.presets]
        self.scales = [pl.command_scale for pl in self.plants]
        # the (first) joint: single-joint code and tools read these
        self.preset, self.plant, self.scale, self.joint = (
            self.presets[0],
            self.plants[0],
            self.scales[0],
            self.joints[0],
        )
        self.dt = self.preset.control_period
        self.lockstep = self.p["mode"] == "lockstep"
        n = self.n = len(self.joints)

        # joint states and commands are (de)serialised by the wire module's JointState codec and sent as
        # bytes: same wire type, no message objects in the 1 kHz path
        self._encoder = JointStateEncoder(self.joints)
        self._decoder = JointStateDecoder()
        state_qos = LOCKSTEP_RECORDED_QOS if self.lockstep else RECORDED_QOS
        self.state_pub = self.create_publisher(JointState, "joint_states", state_qos)
        self.clock_pub = self.create_publisher(Clock, "/clock", STATE_QOS) if self.lockstep else None
        # several joints: one command per joint may arrive at once (one controller per joint)
        qos = (
            COMMAND_QOS
            if n == 1
            else QoSProfile(
                history=COMMAND_QOS.history,
                depth=n,
                reliability=COMMAND_QOS.reliability,
                durability=COMMAND_QOS.durability,
            )
        )
        safe_subscription(self, JointState, "joint_commands", self._on_command, qos, decode=BYTES)
        self.owner = CommandOwnerWatch(self, self.joints)  # one command source per joint
        # realtime mode is the clock source: wall time without an rclpy Time object per cycle
        self._sim_clock = bool(self.get_parameter("use_sim_time").value)
        hardware = self.preset.name if not self.multi else ",".join(pr.name for pr in self.presets)
        self.diag = DiagnosticsPublisher(self, "plant_simulator", hardware)

        self.sim = PlantStepper(
            self.joints, self.plants, self.dt, self.p["initial_position"], self.p["log_period"]
        )
        self._diag_rejected = 0
        self._latency = LatencyHistogram()
        self._start_wall = time.monotonic()
        # statistics window: from the first command (+ stats_delay); before it no controller answers
        self._stats_reset_at: float | None = None
        self._stats_wall0 = self._start_wall
        self._stats_steps0 = 0
        self._stats_sim0 = 0.0
        self._clock_ns = int(round(self.p["clock_period"] * 1e9))
        self.create_timer(self.p["diagnostics_period"], self._publish_diagnostics)
        self._subscribers_ready = not self.lockstep or self.p["wait_for_subscribers"] == 0
        if not self._subscribers_ready:
            self.get_logger().info(
                f"lockstep: the first state waits for {self.p['wait_for_subscribers']} subscriber(s) "
                "of joint_states (wait_for_subscribers)"
            )
        if self.lockstep:
            self._last_publish = 0.0
            self.create_timer(self.p["resend_period"] / 4, self._resend)
            self._publish_pending()
            self.loop = None
        else:
            self._t0_ns = self._now_ns()
            # driven by run_node's executor loop
            self.loop = DeadlineLoop(self.dt, self._tick)
        apply_scheduling(self, self.p)
        if not self.multi:
            self.get_logger().info(
                f"preset {self.preset.name}: {self.p['mode']} at {1 / self.dt:g} Hz, joint {self.joint}, "
                f"command scale {self.scale:.6g} (plant unit per N*m)"
            )
        else:
            each = ", ".join(
                f"{j} ({pr.name}, scale {k:.6g})"
                for j, pr, k in zip(self.joints, self.presets, self.scales, strict=True)
            )
            self.get_logger().info(f"{n} joints, {self.p['mode']} at {1 / self.dt:g} Hz: {each}")

    @property
    def _pending(self) -> tuple:
        """The state to publish next (positions, velocities, efforts)."""
        return self.sim.pending

    # -- parameters ---------------------------------------------------------------------------------
    def _apply(self, changes):
        for k in changes:
            if self.layout.split(k) is not None:
                raise ParameterError(f"{k} is read-only (restart the node to change it)")
        for k, v in changes.items():
            self.p[k] = v

    # -- messages -------------------------------------------------------------------------------------
    def _now_ns(self) -> int:
        if self._sim_clock:
            return self.get_clock().now().nanoseconds
        return time.time_ns()  # = the ROS system clock

    def _on_command(self, data: bytes) -> None:
        msg = self._decoder.decode(data)
        if self._stats_reset_at is None:
            self._stats_reset_at = time.monotonic() + self.p["stats_delay"]
        if self._stats_reset_at <= time.monotonic():
            self._reset_statistics()
        efforts, events = self.sim.select(msg, self.p["max_effort"], time.monotonic())
        log_events(self.get_logger(), events)
        if efforts is None:
            return
        conflicted = self.owner.admit(msg.frame_id, msg.name)
        if conflicted:  # a joint with two command sources: follow neither (command_owner policy)
            efforts = {i: (0.0 if i in conflicted else e) for i, e in efforts.items()}
        if self.lockstep:
            if self.sim.answer(msg.stamp_ns, efforts):
                self._publish_pending()
            return
        sent = msg.stamp_ns
        self.sim.hold(sent, efforts, time.monotonic())
        if sent:
            self._latency.add((self._now_ns() - sent) * 1e-9)

    # -- stepping -------------------------------------------------------------------------------------
    def _publish_pending(self) -> None:
        if self._waiting_for_subscribers():
            return  # the resend timer tries again
        sec, nanosec = divmod(self.sim.t_ns, 1_000_000_000)
        if self.clock_pub is not None and self.sim.clock_due(self._clock_ns):
            self.clock_pub.publish(Clock(clock=Time(sec=sec, nanosec=nanosec)))
        self.state_pub.publish(self._encoder.pack(sec, nanosec, *self.sim.pending))
        self._last_publish = time.monotonic()

    def _waiting_for_subscribers(self) -> bool:
        """Lockstep, before the first state: fewer than ``wait_for_subscribers`` subscribers yet."""
        if self._subscribers_ready:
            return False
        self._subscribers_ready = self.state_pub.get_subscription_count() >= self.p["wait_for_subscribers"]
        return not self._subscribers_ready

    def _resend(self) -> None:
        if time.monotonic() - self._last_publish >= self.p["resend_period"]:
            self._publish_pending()

    def _tick(self) -> None:
        self.sim.tick(time.monotonic(), self.p["command_timeout"], self._now_ns)
        self._publish_pending()

    def on_shutdown(self) -> None:
        if self.loop is not None:
            self.loop.stop()
        if self.lockstep and self.p["exit_wait_for_readers"] > 0:  # a recorder may be behind the run
            wait_delivered(self.state_pub, "joint_states", self.get_logger(), self.p["exit_wait_for_readers"])
        if self.p["stats_file"]:
            import json

            with open(self.p["stats_file"], "w", encoding="utf-8") as fh:
                json.dump(self.loop_statistics(), fh, indent=2)


def main(args=None) -> int:
    return run_node(PlantSimulator, args)


if __name__ == "__main__":
    raise SystemExit(main())
