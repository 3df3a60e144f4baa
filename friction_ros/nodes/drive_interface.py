"""drive_interface: servo drives on one CAN bus (ODrive CANSimple or MIT) as ROS joint topics.

One drive by default (``joint_name``, ``node_id``). Several drives on the bus (a manipulator's
joints): ``joints: [shoulder, elbow, ...]`` with ``<joint>.node_id`` for each and optionally
``<joint>.gear_ratio``, ``torque_constant``, ``direction``, ``zero_offset``, ``torque_limit``,
``current_limit``, ``velocity_limit`` (``mit.master_id``); the node-level values are their
defaults. Then ``joint_states`` carries all joints in one message, ``joint_commands`` may name any
subset (a drive left out is zeroed by its own watchdog), ``drive_state`` comes once per drive, and
every drive has its own safety state; ``~/enable``, faults of the bus, Ctrl-C and shutdown act on all.

Publishes ``joint_states`` (sensor_msgs/JointState: position rad, velocity rad/s, effort = joint
torque N*m; m, m/s and force N with ``joint_type: prismatic`` and ``lead``, the travel per motor turn) and ``drive_state`` (friction_msgs/DriveState) once per control period, subscribes to
``joint_commands`` (sensor_msgs/JointState effort = joint torque command) with keep-last 1, and
publishes ``diagnostics``. Service ``~/enable`` (std_srvs/SetBool) enables (clearing latched faults)
or disables the drive.

Safe by default: the drive is only enabled on request (``enable_on_start`` or ``~/enable``); command
watchdog, torque/current/velocity limits, NaN/inf rejection, stale-telemetry and drive-error faults,
the ODrive closed-loop check (heartbeat must report CLOSED_LOOP after enabling; one retry)
live in :class:`friction_ros.core.can.axis.DriveAxis`; every fault, Ctrl-C/SIGTERM and shutdown send
zero torque + IDLE (ODrive) or zero command + exit motor mode (MIT). Bus errors are counted, a dead
bus (bus-off, reader failure, repeated send failures) latches a bus fault and is reopened.

Stale telemetry, in two stages derived from the telemetry period T (``telemetry_rate_hz``, default
the control rate): telemetry older than 3 T gives no joint_states sample for the drive (never
repeated values) and zero torque until fresh frames arrive (counted: ``telemetry_late_periods``);
telemetry older than the timeout (``telemetry_timeout``, default 3 T plus a 0.5 s jitter margin: a
healthy emulator process on a loaded 2-core machine goes silent for up to ~0.3 s) is a fault:
zero torque + IDLE, logged, at the first control period after the timeout; the fault
stays latched when telemetry returns (logged: "cleared ...; drive stays disabled until ~/enable"),
``~/enable`` resets it. Encoder and effort frames pass a plausibility gate
(:mod:`friction_ros.core.can.telemetry_gate`: NaN/inf, beyond ``telemetry_gate.limit_factor`` x the
velocity or current limit, a position jump beyond what that speed covers): a rejected frame is never
published, is counted (diagnostics ``telemetry_rejected.<reason>``) and logged at most once a second;
``telemetry_gate.reject_run`` in a row latch the ``telemetry_implausible`` fault (zero torque + IDLE
until ``~/enable``). Every fault of a drive is logged once when it starts and once when it clears
(:class:`friction_ros.core.can.faults.FaultLog`); diagnostics carry ``stale_faults``,
``telemetry_age_max_ms`` (per diagnostics period) and ``telemetry_timeout_ms``. ``joint_commands``
messages for none of the node's joints or with mismatched arrays are ignored, counted
(``commands_foreign``, ``commands_malformed``) and logged at most once a second per kind.

Threads and wake-ups (< 25 % of a core per axis at 1 kHz): the control period runs in the
executor thread (:class:`~friction_ros.nodes.loops.DeadlineLoop`, driven by ``run_node``), which
sleeps to each deadline: commands and service requests that arrived meanwhile are handled just
before the period (one wake-up per period). The period reads the bus itself
(:class:`~friction_ros.nodes.can_bus.CanBusLink`: no Notifier, no reader thread), then
supervises, sends the command and publishes. ``loop_spin`` > 0 (busy-wait for timing
accuracy) runs the period on its own thread instead (:class:`~friction_ros.nodes.loops.FixedRateLoop`).
"""

from __future__ import annotations

import time

from std_srvs.srv import SetBool

from friction_ros.core.can.drive_set import DriveSet, frame_router
from friction_ros.nodes.can_bus import CanBusLink
from friction_ros.nodes.diagnostics import DiagnosticsPublisher
from friction_ros.nodes.drive_commands import CommandIntake
from friction_ros.nodes.drive_parameters import declare_drive_parameters, parameter_schema
from friction_ros.nodes.drive_state_publishers import DriveStatePublishers
from friction_ros.nodes.loops import DeadlineLoop, FixedRateLoop
from friction_ros.nodes.parameters import ParameterNode
from friction_ros.nodes.runtime import apply_scheduling, run_node

__all__ = ["DriveInterface", "main", "parameter_schema"]


class DriveInterface(ParameterNode):
    def __init__(self, **kwargs):
        super().__init__("drive_interface", **kwargs)
        joints, self.v, values = declare_drive_parameters(self, self._apply)
        v = self.v
        apply_scheduling(self, v)
        self.drives = DriveSet(values, multi=bool(joints))
        self.axes, self.joints = self.drives.axes, self.drives.joints
        self.axis, self.joint = self.axes[0], self.joints[0]  # the (first) drive: single-axis tools read it
        self._shutdown_done = False
        self.link = CanBusLink(
            v["interface"],
            v["channel"],
            v["bitrate"],
            self.axes,
            frame_router(self.axes),
            v["bus_error_limit"],
            v["bus_recovery_period"],
            self.get_logger(),
        )
        self.states = DriveStatePublishers(self, self.joints, v["protocol"])
        self.pub_joint = self.states.pub_joint
        self.commands = CommandIntake(self, self.joints, self.axes)
        self.srv_enable = self.create_service(SetBool, "~/enable", self._on_enable)
        ids = ",".join(str(a.cfg.node_id) for a in self.axes)
        hw = f"{v['interface']}:{v['channel']}/{v['protocol']}#{ids}"
        self.diag = DiagnosticsPublisher(self, "drive_interface", hardware_id=hw)
        self._diag_next = time.monotonic()
        self._ros_clock = self.get_clock()
        if self.states.fallback_reason:
            self.get_logger().warning(
                f"publishing message objects (pre-serialised templates unusable: {self.states.fallback_reason})"
            )
        self._loop_error = ""
        if v["enable_on_start"]:
            self.drives.request_enable()
        period = v["control_period"]
        if v["loop_spin"] > 0:  # busy-wait before each deadline: needs a thread of its own
            self.loop = FixedRateLoop(period, self._cycle, name="drive_interface_loop", spin=v["loop_spin"])
            self.loop.start()
        else:  # run_node drives it in the executor thread (see the module docstring)
            self.loop = DeadlineLoop(period, self._cycle, wake_on_events=False)
        s = "s" if len(self.joints) > 1 else ""
        self.get_logger().info(
            f"{v['protocol']} on {v['interface']}:{v['channel']} at {1.0 / period:g} Hz, "
            f"joint{s} {self.drives.describe()}, drive{s} "
            f"{'enabling' if v['enable_on_start'] else 'disabled until ~/enable'}"
        )

    # ---- parameters / service -------------------------------------------------------------------------
    def _apply(self, changes: dict) -> None:
        """Run-time change: every affected drive (all or nothing), then the node's own values."""
        self.v = {**self.v, **self.drives.reconfigure(changes)}  # ParameterError -> rejected
        self.link.error_limit = self.v["bus_error_limit"]
        self.link.recovery_period = self.v["bus_recovery_period"]

    def _on_enable(self, req, resp):
        if req.data:
            self.drives.request_enable()
            resp.message = "enable requested: the drive enables as soon as telemetry is fresh"
        else:
            self.link.send(self.drives.disable_frames())
            resp.message = "drive disabled (zero torque, idle)"
        resp.success = True
        self.get_logger().info(resp.message)
        return resp

    # ---- control period -------------------------------------------------------------------------------
    def _cycle(self) -> None:
        try:
            self._cycle_inner()
        except Exception as exc:  # never let the loop thread die with the drive armed
            if not self._loop_error:
                self._loop_error = f"{type(exc).__name__}: {exc}"
                self.get_logger().error(
                    f"drive_interface cycle failed: {self._loop_error}; disabling the drive"
                )
            frames = self.drives.fail(f"internal error: {self._loop_error}")
            try:
                self.link.send(frames)
            except Exception:
                pass

    def _cycle_inner(self) -> None:
        now = time.monotonic()
        lo = self.link.receive(now)
        self.commands.take(now, lo)
        drives = self.drives
        frames, samples, lines = drives.cycle(now)
        if lines:
            self._log_faults(lines)
        if frames and not self.link.send(frames):
            drives.send_failed()
        clock = self._ros_clock
        sec, nsec = divmod(
            clock.now().nanoseconds if clock.ros_time_is_active else time.time_ns(), 1_000_000_000
        )
        states = self.states
        states.publish_joints(sec, nsec, samples)
        if states.drive_state_wanted():  # nobody listening: nothing to send
            states.publish_drives(sec, nsec, drives.ports, samples)
        if now >= self._diag_next:
            self._diag_next = now + self.v["diagnostics_period"]
            self._publish_diagnostics(now)

    def _log_faults(self, lines: list[tuple[str, str]]) -> None:
        """Fault start / clear lines of the drives (see friction_ros.core.can.faults)."""
        log = self.get_logger()
        for level, text in lines:  # one call site per severity (rclpy refuses a changing one)
            if level == "error":
                log.error(text)
            elif level == "warning":
                log.warning(text)
            else:
                log.info(text)

    def _publish_diagnostics(self, now: float) -> None:
        level, message, values = self.drives.health(now)
        stats = self.loop.stats
        values.update(
            {
                **self.commands.counts(),
                **self.link.counts(),
                "loop_overruns": stats.overruns,
                "loop_max_lateness_ms": stats.max_lateness * 1e3,
                "loop_exec_ms": stats.last_exec * 1e3,
            }
        )
        self.diag.publish(level, message, values)

    # ---- shutdown -------------------------------------------------------------------------------------
    def on_shutdown(self) -> None:
        """Stop the loop, then zero torque and idle / exit motor mode (retried), then close the bus."""
        if self._shutdown_done:
            return
        self._shutdown_done = True
        self.loop.stop()
        self.destroy_subscription(self.commands.subscription)
        if not self.link.send_final(self.drives.shutdown_frames()):
            self.get_logger().error("could not send the idle request: check the drive (its own watchdog)")
        self.get_logger().info(f"drive{'s' if len(self.axes) > 1 else ''} left safe: zero torque, idle")
        self.link.close()


def main(args: list[str] | None = None) -> int:
    return run_node(DriveInterface, args)


if __name__ == "__main__":
    from friction_ros.nodes.process_exit import exit_now

    exit_now(main())  # everything is closed: no interpreter teardown (see process_exit)
