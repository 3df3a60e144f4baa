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
executor thread (:class:`~friction_ros.nodes.loops.DeadlineLoop`, driven by ``run_node``) and reads
the bus itself (:class:`~friction_ros.nodes.can_bus.CanBusLink`: no Notifier, no reader thread),
then supervises, sends the command and publishes. ``loop_spin`` > 0 (busy-wait for timing
accuracy) runs the period on its own thread instead (:class:`~friction_ros.nodes.loops.FixedRateLoop`).
"""

from __future__ import annotations

import dataclasses
import time

import can
import rclpy
from rcl_interfaces.msg import ParameterDescriptor, ParameterType
from rclpy.node import Node
from rclpy.parameter import Parameter
from std_srvs.srv import SetBool

from friction_ros.core.can.axis import DriveAxis
from friction_ros.core.can.axis_config import AXIS_SCHEMA, axis_config
from friction_ros.core.can.axis_health import AxisHealth
from friction_ros.core.can.drive_set import (
    axis_values,
    changed_values,
    check_distinct_ids,
    check_joint_names,
    frame_router,
)
from friction_ros.core.can.faults import FAULT_BUS
from friction_ros.core.can.frame import Frame
from friction_ros.core.config import Field, Schema, flatten
from friction_ros.core.control_period import DEFAULT_CONTROL_PERIOD
from friction_ros.core.joint_type import JOINT_TYPES, check_joint_type, joint_schema
from friction_ros.core.validation import ParameterError
from friction_ros.nodes.can_bus import CanBusLink
from friction_ros.nodes.diagnostics import DiagnosticsPublisher
from friction_ros.nodes.drive_commands import CommandIntake
from friction_ros.nodes.drive_state_publishers import DriveStatePublishers, drive_values
from friction_ros.nodes.loops import DeadlineLoop, FixedRateLoop
from friction_ros.nodes.parameters import SCHEDULING, ParameterNode, declare_config
from friction_ros.nodes.runtime import apply_scheduling, run_node

INTERFACES = tuple(sorted(can.VALID_INTERFACES))

NODE_FIELDS = [
    Field(
        "interface",
        "socketcan",
        "python-can interface (socketcan on robots; virtual in tests)",
        choices=INTERFACES,
        read_only=True,
    ),
    Field("channel", "can0", "CAN channel (socketcan: network interface name)", read_only=True),
    Field(
        "bitrate",
        1000000,
        "bitrate for interfaces that set it (socketcan: set with ip link)",
        lo=10000,
        hi=1000000,
        read_only=True,
        unit="bit/s",
    ),
    Field("joint_name", "joint1", "joint name in joint_states / joint_commands", read_only=True),
    Field(
        "control_period",
        DEFAULT_CONTROL_PERIOD,
        "period of the joint_states publication and the torque commands (1 / the rate)",
        lo=2e-4,
        hi=1.0,
        read_only=True,
        unit="s",
    ),
    Field(
        "enable_on_start", False, "enable the drive (closed loop, zero torque) as soon as telemetry arrives"
    ),
    Field(
        "loop_spin",
        0.0,
        "busy-wait before each period for timing accuracy (costs spin/period of a core)",
        lo=0.0,
        hi=0.001,
        read_only=True,
        unit="s",
    ),
    Field("diagnostics_period", 1.0, "diagnostics publication period", lo=0.05, hi=60.0, unit="s"),
    Field("bus_error_limit", 20, "consecutive failed sends before the bus counts as dead", lo=1, hi=100000),
    Field("bus_recovery_period", 1.0, "wait before reopening a dead bus", lo=0.01, hi=60.0, unit="s"),
]


def parameter_schema(joint_type: str = "revolute") -> Schema:
    """The node's parameters: the bus and loop, one drive (:data:`~friction_ros.core.can.axis.AXIS_SCHEMA`;
    with ``joints``, :data:`AXIS_KEYS` also per joint) and the scheduling, in the units of
    ``joint_type``."""
    return joint_schema(Schema("drive_interface", [*NODE_FIELDS, *AXIS_SCHEMA, *SCHEDULING]), joint_type)


# per-drive parameters when a node runs several drives (``joints``): <joint>.<key>
AXIS_KEYS = (
    "node_id",
    "mit.master_id",
    "joint_type",
    "lead",
    "gear_ratio",
    "torque_constant",
    "direction",
    "zero_offset",
    "torque_limit",
    "current_limit",
    "velocity_limit",
)


def declare_joints(node: Node) -> list[str]:
    """Declare and validate ``joints`` (several axes on one bus); [] = one axis (``joint_name``)."""
    desc = ParameterDescriptor(
        name="joints",
        type=ParameterType.PARAMETER_STRING_ARRAY,
        description=(
            "several drives on this bus: their joint names, each with its own <joint>.node_id (and "
            "optionally <joint>.gear_ratio, torque_constant, direction, zero_offset, limits); "
            "unset = one drive (joint_name, node_id)"
        ),
        read_only=True,
    )
    try:
        joints = node.declare_parameter("joints", Parameter.Type.STRING_ARRAY, desc).value
    except (
        rclpy.exceptions.InvalidParameterTypeException,
        rclpy.exceptions.InvalidParameterValueException,
    ):
        raise ParameterError(
            "joints must be a list of joint names, e.g. joints: [shoulder, elbow] (leave it out for one drive)"
        ) from None
    joints = list(joints or [])
    check_joint_names(joints, {name.split(".")[0] for name, _ in parameter_schema().fields()})
    return joints


def axis_param_specs(joints: list[str], v: dict, joint_types: dict[str, str] | None = None) -> list[Field]:
    """Per-joint parameters ``<joint>.<key>`` for :data:`AXIS_KEYS`, defaulting to the top-level values,
    in the units of each joint's type (``joint_types``; default: the node's ``joint_type``)."""
    by = {t: dict(parameter_schema(t).fields()) for t in JOINT_TYPES}
    types = {j: (joint_types or {}).get(j, v.get("joint_type", "revolute")) for j in joints}
    return [
        dataclasses.replace(by[types[j]][k], name=f"{j}.{k}", default=v[k], doc=f"{j}: {by[types[j]][k].doc}")
        for j in joints
        for k in AXIS_KEYS
    ]


class AxisPort:
    """One drive of the node: its joint, the core :class:`DriveAxis`, its parameter values and its
    health report."""

    def __init__(self, values: dict):
        self.values = values
        self.joint = values["joint_name"]
        self.axis = DriveAxis(axis_config(values, 1.0 / values["control_period"]))
        self.health = AxisHealth()
        self.flags = 0
        self.label = f"drive '{self.joint}' (id {values['node_id']})"


class DriveInterface(ParameterNode):
    def __init__(self, **kwargs):
        super().__init__("drive_interface", **kwargs)
        self.joints_param = joints = declare_joints(self)
        self.v = v = flatten(declare_config(self, parameter_schema(), check_unknown=not joints))
        given = {j: self.given_parameters.get(f"{j}.joint_type") for j in joints}
        types = {j: check_joint_type(p.value, f"{j}.joint_type") for j, p in given.items() if p is not None}
        self.axis_specs = axis_param_specs(joints, v, types)
        per_joint = flatten(declare_config(self, Schema("axes", self.axis_specs), self._apply))
        apply_scheduling(self, v)
        self.ports = [AxisPort(a) for a in axis_values(joints, v, per_joint, AXIS_KEYS)]
        self.axes = [p.axis for p in self.ports]
        self.axis = self.axes[0]  # the (first) drive: single-axis code and tools read this one
        self.joints = [p.joint for p in self.ports]
        self.joint = self.joints[0]
        check_distinct_ids(self.joints, [a.cfg for a in self.axes])
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
            for a in self.axes:
                a.request_enable()
        period = v["control_period"]
        if v["loop_spin"] > 0:  # busy-wait before each deadline: needs a thread of its own
            self.loop = FixedRateLoop(period, self._cycle, name="drive_interface_loop", spin=v["loop_spin"])
            self.loop.start()
        else:  # run_node drives it in the executor thread (see the module docstring)
            self.loop = DeadlineLoop(period, self._cycle)
        n = len(self.joints)
        drives = ", ".join(f"'{p.joint}' (id {p.axis.cfg.node_id})" for p in self.ports)
        self.get_logger().info(
            f"{v['protocol']} on {v['interface']}:{v['channel']} at {1.0 / v['control_period']:g} Hz, "
            f"joint{'s' if n > 1 else ''} {drives}, drive{'s' if n > 1 else ''} "
            f"{'enabling' if v['enable_on_start'] else 'disabled until ~/enable'}"
        )

    # ---- parameters / service / commands ------------------------------------------------------------
    def _apply(self, changes: dict) -> None:
        """Run-time change: rebuild every affected axis config first (all or nothing), then swap."""
        values = [p.values for p in self.ports]
        new_values, shared = changed_values(self.joints, values, changes, AXIS_KEYS, bool(self.joints_param))
        configs = [
            axis_config(vals, 1.0 / vals["control_period"]) for vals in new_values
        ]  # raises ParameterError -> rejected
        for port, vals, cfg in zip(self.ports, new_values, configs):
            with port.axis._lock:
                port.axis.cfg = cfg
            port.values = vals
        self.v = {**self.v, **shared}
        self.link.error_limit = self.v["bus_error_limit"]
        self.link.recovery_period = self.v["bus_recovery_period"]

    def _on_enable(self, req, resp):
        if req.data:
            for a in self.axes:
                a.request_enable()
            resp.success, resp.message = (
                True,
                "enable requested: the drive enables as soon as telemetry is fresh",
            )
        else:
            self.link.send([f for a in self.axes for f in a.request_disable()])
            resp.success, resp.message = True, "drive disabled (zero torque, idle)"
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
            for a in self.axes:
                a.report_bus_fault(f"internal error: {self._loop_error}")
            try:
                self.link.send([f for a in self.axes for f in a.shutdown_frames()])
            except Exception:
                pass

    def _cycle_inner(self) -> None:
        now = time.monotonic()
        lo = self.link.receive(now)
        self.commands.take(now, lo)
        ports = self.ports
        frames: list[Frame] = []
        samples = []
        for port in ports:
            res = port.axis.cycle(now)
            port.flags = res.flags
            frames += res.frames
            samples.append(res.sample)
            if res.events:
                self._log_faults(port, res.events)
        if frames and not self.link.send(frames):
            for port in ports:
                port.flags |= FAULT_BUS
        clock = self._ros_clock
        sec, nsec = divmod(
            clock.now().nanoseconds if clock.ros_time_is_active else time.time_ns(), 1_000_000_000
        )
        states = self.states
        states.publish_joints(sec, nsec, samples)
        if states.drive_state_wanted():  # nobody listening: nothing to send
            for k, (port, sample) in enumerate(zip(ports, samples)):
                states.publish_drive(k, sec, nsec, drive_values(port.axis, sample, port.flags))
        if now >= self._diag_next:
            self._diag_next = now + self.v["diagnostics_period"]
            self._publish_diagnostics(now)

    def _log_faults(self, port: AxisPort, events) -> None:
        """Fault start / clear lines of the core (see friction_ros.core.can.faults)."""
        log = self.get_logger()
        for ev in events:  # one call site per severity (rclpy refuses a changing one)
            text = f"{port.label}: {ev.text}"
            if ev.level == "error":
                log.error(text)
            elif ev.level == "warning":
                log.warning(text)
            else:
                log.info(text)

    def _publish_diagnostics(self, now: float) -> None:
        statuses = [p.health.report(p.axis, p.flags, now) for p in self.ports]
        if len(statuses) == 1:
            level, message, values = statuses[0]
        else:
            level = max(s[0] for s in statuses)
            message = "; ".join(f"{p.joint}: {s[1]}" for p, s in zip(self.ports, statuses))
            values = {f"{p.joint}.{k}": v for p, s in zip(self.ports, statuses) for k, v in s[2].items()}
        stats, link = self.loop.stats, self.link
        values.update(
            {
                "commands_foreign": self.commands.foreign,
                "commands_malformed": self.commands.malformed,
                "send_errors": link.send_errors,
                "error_frames": link.error_frames,
                "bus_reopens": link.reopens,
                "bus_state": link.state(),
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
        frames = [f for a in self.axes for f in a.shutdown_frames()]
        for _attempt in range(3):
            if self.link.send(frames):
                break
            time.sleep(0.01)
        else:
            self.get_logger().error("could not send the idle request: check the drive (its own watchdog)")
        time.sleep(0.005)  # let the frames leave the socket before closing it
        self.get_logger().info(f"drive{'s' if len(self.axes) > 1 else ''} left safe: zero torque, idle")
        self.link.close()


def main(args: list[str] | None = None) -> int:
    return run_node(DriveInterface, args)


if __name__ == "__main__":
    raise SystemExit(main())
