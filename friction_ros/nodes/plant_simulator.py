"""plant_simulator: the gearhead DC servo plant (friction_ros.core.plant) as a ROS 2 node.

Stands in for the CAN drive interface with the same topics, so controller, estimator, recorder and
a ros2_control stack (topic_based_ros2_control) cannot tell the difference:

* subscribes ``joint_commands`` (sensor_msgs/JointState, effort = joint torque N*m; COMMAND_QOS)
* publishes ``joint_states`` (sensor_msgs/JointState: position rad, velocity rad/s, effort N*m),
  ``diagnostics`` and, in lockstep mode, ``/clock``.

Modes:

``realtime``  a fixed-rate loop thread steps the plant every ``control_period`` of wall time with
              the newest command (zero torque once no command came for ``command_timeout``).
``lockstep``  the plant advances exactly one control period per command whose header stamp equals
              the stamp of the state it answers, publishes ``/clock`` then the new state. Nodes with
              ``use_sim_time`` follow; the whole graph runs as fast as it can and deterministically.
              If no answer arrives within ``resend_period`` (wall) the pending state is published
              again (a subscriber that joined late gets it); duplicate commands are ignored.
"""

from __future__ import annotations

import math
import threading
import time

from builtin_interfaces.msg import Time
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState

from friction_ros.core.config import Field, Schema
from friction_ros.core.control_period import control_period_field
from friction_ros.core.input_gate import PLAUSIBLE_EFFORT, RejectionLog, select_command
from friction_ros.core.plant.servo import MAX_COMMAND
from friction_ros.core.presets import resolve_preset
from friction_ros.core.wire import JointStateDecoder, JointStateEncoder
from friction_ros.nodes.diagnostics import ERROR, OK, WARN, DiagnosticsPublisher
from friction_ros.nodes.loops import DeadlineLoop, LatencyHistogram, LoopStats
from friction_ros.nodes.parameters import SCHEDULING, ParameterNode, declare_config
from friction_ros.nodes.qos import COMMAND_QOS, RECORDED_QOS, STATE_QOS
from friction_ros.nodes.runtime import apply_scheduling, run_node

NODE_FIELDS = [
    Field(
        "preset",
        "abb_m19s",
        "plant preset: a name in params/ (abb_m19s, seed002_x ...), a YAML path, or '' (the plant.* / friction_*.* parameters are the whole plant)",
        read_only=True,
    ),
    Field("description", "", "free text describing the preset", read_only=True),
    Field(
        "joint_name",
        "joint1",
        "joint name used in joint_states and expected in joint_commands",
        read_only=True,
    ),
    Field(
        "mode",
        "realtime",
        "realtime: wall-clock loop; lockstep: one period per command + /clock",
        choices=("realtime", "lockstep"),
        read_only=True,
    ),
    control_period_field("control period (plant step per state)"),
    Field("initial_position", 0.0, "joint position at start", lo=-1e6, hi=1e6, unit="rad", read_only=True),
    Field(
        "command_timeout",
        0.1,
        "realtime: zero torque when no command arrived for this long",
        lo=0.0,
        hi=60.0,
        unit="s",
    ),
    Field(
        "max_effort",
        PLAUSIBLE_EFFORT,
        "plausibility bound: a commanded |effort| above it is rejected like a NaN (zero torque, logged)",
        lo=1e-9,
        unit="N*m",
    ),
    Field(
        "log_period",
        1.0,
        "at most one log line per command rejection reason per this period",
        lo=0.0,
        unit="s",
        read_only=True,
    ),
    Field(
        "resend_period",
        0.2,
        "lockstep: re-publish the pending state after this wall time",
        lo=0.005,
        hi=60.0,
        unit="s",
    ),
    Field(
        "clock_period",
        0.01,
        "lockstep: publish /clock every this much simulated time (0: every period)",
        lo=0.0,
        hi=1.0,
        unit="s",
        read_only=True,
    ),
    Field(
        "stats_file",
        "",
        "write loop/latency statistics as JSON here on shutdown (benchmarks)",
        read_only=True,
    ),
    Field("diagnostics_period", 1.0, "period of the diagnostics status", lo=0.05, hi=60.0, unit="s"),
    Field(
        "stats_delay",
        0.0,
        "loop/latency statistics start this long (wall) after the first command (benchmarks skip start-up)",
        lo=0.0,
        hi=3600.0,
        unit="s",
        read_only=True,
    ),
]


PRESET_SECTIONS = ("plant", "friction_motor", "friction_load")


def parameter_schema() -> Schema:
    """The node's parameters; the preset sections take the keys given in the parameter file (on top
    of the preset; the plant's keys: :data:`friction_ros.core.plant.params.PLANT_SCHEMA`)."""
    sections = [Schema(s, doc=f"preset {s} parameter", open=True, read_only=True) for s in PRESET_SECTIONS]
    return Schema("plant_simulator", [*NODE_FIELDS, *sections, *SCHEDULING])


class PlantSimulator(ParameterNode):
    """Thin adapter: commands in, GearheadServoPlant.step, joint states out."""

    def __init__(self):
        super().__init__("plant_simulator")
        self.p = declare_config(self, parameter_schema(), self._apply)
        sections = {s: self.p.get(s, {}) for s in PRESET_SECTIONS}
        # the node's control_period is the preset's (it owns the period the plant is stepped at)
        self.preset = resolve_preset(
            self.p["preset"], {**sections, "control_period": self.p["control_period"]}
        )
        self.plant = self.preset.make_plant()
        self.scale = self.plant.command_scale
        self.dt = self.preset.control_period
        self.dt_ns = int(round(self.dt * 1e9))
        self.joint = self.p["joint_name"]
        self.lockstep = self.p["mode"] == "lockstep"

        # joint states and commands are (de)serialised by the wire module's JointState codec and sent as
        # bytes: same wire type, no message objects in the 1 kHz path
        self._encoder = JointStateEncoder([self.joint])
        self._decoder = JointStateDecoder()
        self.state_pub = self.create_publisher(JointState, "joint_states", RECORDED_QOS)
        self.clock_pub = self.create_publisher(Clock, "/clock", STATE_QOS) if self.lockstep else None
        self.create_subscription(JointState, "joint_commands", self._on_command, COMMAND_QOS, raw=True)
        # realtime mode is the clock source: wall time without an rclpy Time object per cycle
        self._sim_clock = bool(self.get_parameter("use_sim_time").value)
        self.diag = DiagnosticsPublisher(self, "plant_simulator", self.preset.name)

        self._lock = threading.Lock()
        self._command = 0.0
        self._command_wall = -math.inf
        self._commands_rejected = 0  # implausible effort for this joint: zero torque applied instead
        self._commands_ignored = 0  # another joint / malformed (logged) or a lockstep duplicate
        self._rejections = RejectionLog(f"joint_commands for {self.joint}", self.p["log_period"])
        self._diag_rejected = 0
        self._steps = 0
        self._latency = LatencyHistogram()
        self._last_state_wall = 0.0
        self.plant.reset(position=self.p["initial_position"])
        self._t_ns = 0
        self._start_wall = time.monotonic()
        self._answered_ns = -1
        self._missed = 0
        # statistics window: from the first command (+ stats_delay); before it no controller answers
        self._stats_reset_at: float | None = None
        self._stats_wall0 = self._start_wall
        self._stats_steps0 = 0
        self._stats_sim0 = 0.0
        self._next_clock_ns = 0
        self._clock_ns = int(round(self.p["clock_period"] * 1e9))
        self._pending = (self.p["initial_position"], 0.0, 0.0)
        self.create_timer(self.p["diagnostics_period"], self._publish_diagnostics)
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
        self.get_logger().info(
            f"preset {self.preset.name}: {self.p['mode']} at {1 / self.dt:g} Hz, joint {self.joint}, "
            f"command scale {self.scale:.6g} (plant unit per N*m)"
        )

    # -- parameters ---------------------------------------------------------------------------------
    def _apply(self, changes):
        for k, v in changes.items():
            self.p[k] = v

    # -- messages -------------------------------------------------------------------------------------
    def _now_ns(self) -> int:
        if self._sim_clock:
            return self.get_clock().now().nanoseconds
        return time.time_ns()  # = the ROS system clock

    def _reset_statistics(self) -> None:
        self._stats_reset_at = math.inf  # once
        self._missed = 0
        self._latency = LatencyHistogram()
        if self.loop is not None:
            self.loop.stats = LoopStats()
        self._stats_wall0 = time.monotonic()
        self._stats_steps0 = self._steps
        self._stats_sim0 = self.plant.time

    def _on_command(self, data: bytes) -> None:
        msg = self._decoder.decode(data)
        if self._stats_reset_at is None:
            self._stats_reset_at = time.monotonic() + self.p["stats_delay"]
        if self._stats_reset_at <= time.monotonic():
            self._reset_statistics()
        # plausibility: the node's max_effort and the plant's own command range (MAX_COMMAND)
        limit = (
            min(self.p["max_effort"], MAX_COMMAND / abs(self.scale)) if self.scale else self.p["max_effort"]
        )
        effort, reason, detail = select_command(msg, self.joint, limit)
        if effort is None:
            line = self._rejections.reject(reason, detail, time.monotonic())
            if reason in ("wrong_joint", "wrong_length"):
                self._commands_ignored += 1  # not a command for this joint: ignored
                if line:
                    self.get_logger().warning(f"{line}; ignored")
                return
            self._commands_rejected += 1
            if line:
                self.get_logger().warning(f"{line}; applying zero torque instead")
            effort = 0.0
        if self.lockstep:
            if msg.stamp_ns != self._t_ns:
                self._commands_ignored += 1  # duplicate or stale answer
                return
            self._advance(effort)
            self._publish_pending()
            return
        now = time.monotonic()
        with self._lock:
            self._command = effort
            self._command_wall = now
        sent = msg.stamp_ns
        if sent:
            with self._lock:
                self._answered_ns = sent
            self._latency.add((self._now_ns() - sent) * 1e-9)

    # -- stepping -------------------------------------------------------------------------------------
    def _advance(self, torque: float) -> None:
        m = self.plant.step(torque * self.scale, self.dt)
        self._steps += 1
        self._t_ns += self.dt_ns
        self._pending = (m.position, m.velocity, m.effort)

    def _publish_pending(self) -> None:
        sec, nanosec = divmod(self._t_ns, 1_000_000_000)
        if self.clock_pub is not None and self._t_ns >= self._next_clock_ns:
            self._next_clock_ns = self._t_ns + self._clock_ns
            self.clock_pub.publish(Clock(clock=Time(sec=sec, nanosec=nanosec)))
        p, v, e = self._pending
        self.state_pub.publish(self._encoder.pack(sec, nanosec, p, v, e))
        self._last_publish = time.monotonic()

    def _resend(self) -> None:
        if time.monotonic() - self._last_publish >= self.p["resend_period"]:
            self._publish_pending()

    def _tick(self) -> None:
        with self._lock:
            fresh = time.monotonic() - self._command_wall <= self.p["command_timeout"]
            torque = self._command if fresh else 0.0
            if self._steps and self._answered_ns != self._t_ns:
                self._missed += 1  # the command for the last published state did not arrive in time
        self._advance(torque)
        self._t_ns = self._now_ns()
        self._publish_pending()

    # -- health ---------------------------------------------------------------------------------------
    def _publish_diagnostics(self) -> None:
        values = {
            "mode": self.p["mode"],
            "steps": self._steps,
            "sim_time": self.plant.time,
            "commands_rejected": self._commands_rejected,
            "commands_ignored": self._commands_ignored,
            **self._rejections.values(),
        }
        level, text = OK, "running"
        if self.loop is not None:
            s = self.loop.stats
            values.update(
                cycles=s.cycles,
                overruns=s.overruns,
                missed_commands=self._missed,
                max_lateness_s=s.max_lateness,
            )
            with self._lock:
                stale = time.monotonic() - self._command_wall > self.p["command_timeout"]
            if stale:
                level, text = WARN, "no fresh command: applying zero torque"
            if self._latency.n:
                values.update(
                    latency_p50_s=self._latency.percentile(50), latency_p99_s=self._latency.percentile(99)
                )
        new = self._rejections.total - self._diag_rejected
        self._diag_rejected = self._rejections.total
        if new:
            level = max(level, WARN)
            text = (
                f"{new} joint_commands rejected since the last status (last: {self._rejections.last_reason})"
            )
        self.diag.publish(level if level != ERROR else ERROR, text, values)

    def loop_statistics(self) -> dict:
        """Loop rate, overruns, missed commands and state-to-command latency percentiles.

        Rates and counts cover the statistics window (from the first command + ``stats_delay``);
        ``*_total`` figures cover the whole run including start-up.
        """
        now = time.monotonic()
        total = now - self._start_wall
        wall = now - self._stats_wall0
        out = {
            "mode": self.p["mode"],
            "steps": self._steps,
            "sim_time": self.plant.time,
            "wall_time_total": total,
            "sim_seconds_per_wall_second_total": self.plant.time / total if total > 0 else 0.0,
            "window_wall_time": wall,
            "window_steps": self._steps - self._stats_steps0,
            "sim_seconds_per_wall_second": (self.plant.time - self._stats_sim0) / wall if wall > 0 else 0.0,
            "commands_rejected": self._commands_rejected,
        }
        if self.loop is not None:
            s = self.loop.stats
            out.update(
                cycles=s.cycles,
                overruns=s.overruns,
                missed_commands=self._missed,
                rate_hz=s.cycles / wall if wall > 0 else 0.0,
                max_lateness_s=s.max_lateness,
                mean_lateness_s=s.total_lateness / s.cycles if s.cycles else 0.0,
            )
            if self._latency.n:
                out.update(
                    latency_samples=self._latency.n,
                    latency_p50_s=self._latency.percentile(50),
                    latency_p99_s=self._latency.percentile(99),
                    latency_max_s=self._latency.max,
                )
        return out

    def on_shutdown(self) -> None:
        if self.loop is not None:
            self.loop.stop()
        if self.p["stats_file"]:
            import json

            with open(self.p["stats_file"], "w", encoding="utf-8") as fh:
                json.dump(self.loop_statistics(), fh, indent=2)


def main(args=None) -> int:
    return run_node(PlantSimulator, args)


if __name__ == "__main__":
    raise SystemExit(main())
