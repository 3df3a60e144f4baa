"""drive_interface: servo drives on one CAN bus (ODrive CANSimple or MIT) as ROS joint topics.

One drive by default (``joint_name``, ``node_id``). Several drives on the bus (a manipulator's
joints): ``joints: [shoulder, elbow, ...]`` with ``<joint>.node_id`` for each and optionally
``<joint>.gear_ratio``, ``torque_constant``, ``direction``, ``zero_offset``, ``torque_limit``,
``current_limit``, ``velocity_limit`` (``mit.master_id``); the node-level values are their
defaults. Then ``joint_states`` carries all joints in one message, ``joint_commands`` may name any
subset (a drive left out is zeroed by its own watchdog), ``drive_state`` comes once per drive, and
every drive has its own safety state; ``~/enable``, faults of the bus, Ctrl-C and shutdown act on all.

Publishes ``joint_states`` (sensor_msgs/JointState: position rad, velocity rad/s, effort = joint
torque N*m) and ``drive_state`` (friction_msgs/DriveState) once per control period, subscribes to
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
``~/enable`` resets it. Every fault of a drive is logged once when it starts and once when it clears
(:class:`friction_ros.core.can.faults.FaultLog`); diagnostics carry ``stale_faults``,
``telemetry_age_max_ms`` (per diagnostics period) and ``telemetry_timeout_ms``. ``joint_commands``
messages for none of the node's joints or with mismatched arrays are ignored, counted
(``commands_foreign``, ``commands_malformed``) and logged at most once a second per kind.

Threads and wake-ups (issue 6: < 25 % of a core per axis at 1 kHz): the control period runs in
the executor thread (:class:`~friction_ros.nodes.node_utils.DeadlineLoop`, driven by ``run_node``)
and reads the bus itself: at each deadline it drains the frames received since the last period
(``bus.recv(0)`` until empty), then supervises, sends the command and publishes. There is no
python-can Notifier and no separate loop thread, so the node's Python code wakes up once per period
plus once per ROS command, and never hands the GIL between its own threads. Frames are time-stamped
with their receive time (``Message.timestamp``, the kernel's on SocketCAN) mapped onto the
monotonic clock and clamped to [previous drain, now]: exact with sane timestamps, never off by more
than one period whatever the interface reports, so stale-telemetry detection keeps its accuracy.
``loop_spin`` > 0 (busy-wait for timing accuracy) runs the period on its own thread instead
(:class:`~friction_ros.nodes.node_utils.FixedRateLoop`), with the same drain.
"""

from __future__ import annotations

import collections
import dataclasses
import math
import re
import threading
import time

import can
import rclpy
from friction_msgs.msg import DriveState
from rcl_interfaces.msg import ParameterDescriptor, ParameterType
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.serialization import deserialize_message
from sensor_msgs.msg import JointState
from std_srvs.srv import SetBool

from friction_ros.core.can import odrive as od
from friction_ros.core.can.axis import (
    AXIS_SCHEMA,
    FAULT_BUS,
    LATCHING,
    AxisConfig,
    DriveAxis,
    axis_config,
    fault_text,
    frame_router,
)
from friction_ros.core.can.frame import Frame
from friction_ros.core.config import Field, Schema, flatten
from friction_ros.core.validation import ParameterError
from friction_ros.core.wire import DriveStateEncoder, JointStateDecoder, JointStateEncoder
from friction_ros.nodes.node_utils import (
    COMMAND_QOS,
    ERROR,
    OK,
    RECORDED_QOS,
    SENSOR_QOS,
    WARN,
    DeadlineLoop,
    DiagnosticsPublisher,
    FixedRateLoop,
    apply_scheduling,
    run_node,
)
from friction_ros.nodes.parameters import SCHEDULING, ParameterNode, declare_config


def _level(x) -> int:
    """node_utils' OK/WARN/ERROR are bytes (msg constants) but DiagnosticsPublisher wants an int."""
    return x[0] if isinstance(x, bytes) else int(x)


CAN_ERR_BUSOFF = 0x40  # SocketCAN error class bit in the id of an error frame
RX_BATCH_MAX = 256  # frames read per period at most (a 1 Mbit/s bus carries ~8 per ms)
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
        "control_rate_hz",
        1000.0,
        "publication and command rate",
        lo=1.0,
        hi=5000.0,
        read_only=True,
        unit="Hz",
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


def parameter_schema() -> Schema:
    """The node's parameters: the bus and loop, one drive (:data:`~friction_ros.core.can.axis.AXIS_SCHEMA`;
    with ``joints``, :data:`AXIS_KEYS` also per joint) and the scheduling."""
    return Schema("drive_interface", [*NODE_FIELDS, *AXIS_SCHEMA, *SCHEDULING])


# per-drive parameters when a node runs several drives (``joints``): <joint>.<key>
AXIS_KEYS = (
    "node_id",
    "mit.master_id",
    "gear_ratio",
    "torque_constant",
    "direction",
    "zero_offset",
    "torque_limit",
    "current_limit",
    "velocity_limit",
)
_JOINT_NAME = re.compile(r"[A-Za-z][A-Za-z0-9_]*\Z")


def can_filters(cfg: AxisConfig) -> list[dict]:
    if cfg.protocol == "odrive_cansimple":
        return [od.kernel_filter(cfg.node_id)]
    return [{"can_id": cfg.mit_master_id, "can_mask": 0x7FF, "extended": False}]


def open_bus(interface: str, channel: str, bitrate: int, filters: list[dict]) -> can.BusABC:
    """Open a python-can bus; a failure becomes one clear ValueError line."""
    try:
        return can.Bus(interface=interface, channel=channel, bitrate=bitrate, can_filters=filters)
    except Exception as exc:
        hint = ""
        if interface == "socketcan":
            hint = f"; bring the interface up first: sudo ip link set {channel} up type can bitrate {bitrate}"
        raise ParameterError(
            f"cannot open CAN bus interface={interface} channel={channel}: {type(exc).__name__}: {exc}{hint}"
        ) from None


# ---- pre-serialized state messages ------------------------------------------------------------------
class StatePackets:
    """joint_states and drive_state as CDR bytes (rclpy ``publish_raw``; same wire types).

    Both are packed by the wire encoders of :mod:`friction_ros.core.wire` (one ``struct.pack``
    each): no message objects, no rclpy conversion, no middleware serialisation per period. Both are
    checked once against rclpy's own deserialiser (:meth:`verify`); the node falls back to publishing
    message objects if the check fails.
    """

    def __init__(self, joint: str, protocol: str):
        self.joint, self.protocol = joint, protocol
        self.set_joint = JointStateEncoder([joint]).pack  # (sec, nanosec, position, velocity, effort)
        # (sec, nanosec, motor_position .. bus_voltage, axis_state, axis_error, fault_flags, enabled)
        self.set_drive = DriveStateEncoder(joint, protocol).pack

    def verify(self) -> str:
        """Empty string when both templates deserialise to exactly the values packed, else why not."""
        try:
            js = deserialize_message(self.set_joint(12, 345, 1.5, -2.25, 3.125), JointState)
            ok_js = (
                (js.header.stamp.sec, js.header.stamp.nanosec, js.header.frame_id) == (12, 345, "")
                and list(js.name) == [self.joint]
                and (list(js.position), list(js.velocity), list(js.effort)) == ([1.5], [-2.25], [3.125])
            )
            vals = (0.5, -1.5, 2.5, -3.5, 4.5, 24.0, 8, 0xDEADBEEF, 33, True)
            ds = deserialize_message(self.set_drive(-7, 999_999_999, *vals), DriveState)
            got = (
                ds.motor_position, ds.motor_velocity, ds.current_setpoint, ds.current_measured,
                ds.torque_estimate, ds.bus_voltage, ds.axis_state, ds.axis_error, ds.fault_flags, ds.enabled,
            )  # fmt: skip
            ok_ds = (
                (ds.header.stamp.sec, ds.header.stamp.nanosec, ds.header.frame_id) == (-7, 999_999_999, "")
                and (ds.joint_name, ds.protocol) == (self.joint, self.protocol)
                and got == vals
            )
        except Exception as exc:
            return f"{type(exc).__name__}: {exc}"
        return "" if ok_js and ok_ds else "round trip through rclpy's deserialiser differs"


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
    check_joint_names(joints)
    return joints


def check_joint_names(joints: list[str]) -> None:
    top = {name.split(".")[0] for name, _ in parameter_schema().fields()}
    for i, j in enumerate(joints):
        if not _JOINT_NAME.match(j):
            raise ParameterError(
                f"joints[{i}] = {j!r} is not allowed: must start with a letter and hold only letters, "
                "digits and '_' (it prefixes the per-joint parameters, e.g. <joint>.node_id)"
            )
        if j in top:
            raise ParameterError(f"joints[{i}] = {j!r} clashes with the parameter '{j}': rename the joint")
        if j in joints[:i]:
            raise ParameterError(f"joints[{i}] = {j!r} appears twice: joint names must differ")


def axis_param_specs(joints: list[str], v: dict) -> list[Field]:
    """Per-joint parameters ``<joint>.<key>`` for :data:`AXIS_KEYS`, defaulting to the top-level values."""
    by = dict(parameter_schema().fields())
    return [
        dataclasses.replace(by[k], name=f"{j}.{k}", default=v[k], doc=f"{j}: {by[k].doc}")
        for j in joints
        for k in AXIS_KEYS
    ]


def axis_values(joints: list[str], v: dict, per_joint: dict) -> list[dict]:
    """Parameter values of every axis: the node's, with the joint's own ``<joint>.<key>`` on top."""
    if not joints:
        return [dict(v)]
    return [{**v, "joint_name": j, **{k: per_joint[f"{j}.{k}"] for k in AXIS_KEYS}} for j in joints]


def check_distinct_ids(joints: list[str], configs: list[AxisConfig]) -> None:
    ids = [c.node_id for c in configs]
    if len(set(ids)) != len(ids):
        given = ", ".join(f"{j}.node_id = {c.node_id}" for j, c in zip(joints, configs))
        raise ParameterError(f"node ids must differ between the joints on one bus: {given}")


class AxisPort:
    """One drive of the node: its joint, the core :class:`DriveAxis`, its parameter values and its
    pre-serialised drive_state template."""

    def __init__(self, values: dict):
        self.values = values
        self.joint = values["joint_name"]
        self.axis = DriveAxis(axis_config(values, values["control_rate_hz"]))
        self.packets = StatePackets(self.joint, values["protocol"])
        self.ds = DriveState(joint_name=self.joint, protocol=values["protocol"])
        self.flags = 0
        self.diag_prev: tuple[float, int, int, int, int] | None = None
        self.label = f"drive '{self.joint}' (id {values['node_id']})"

    def drive_values(self, sample, flags: int) -> tuple:
        tel = self.axis.telemetry
        return (
            tel.motor_position if sample is not None else math.nan,
            tel.motor_velocity if sample is not None else math.nan,
            tel.current_setpoint,
            tel.current_measured,
            tel.torque_estimate,
            tel.bus_voltage,
            tel.axis_state & 0xFFFFFFFF,
            tel.axis_error & 0xFFFFFFFF,
            flags,
            self.axis.enabled,
        )


class DriveInterface(ParameterNode):
    def __init__(self, **kwargs):
        super().__init__("drive_interface", **kwargs)
        self.joints_param = joints = declare_joints(self)
        self.v = v = flatten(declare_config(self, parameter_schema(), check_unknown=not joints))
        self.axis_specs = axis_param_specs(joints, v)
        per_joint = flatten(declare_config(self, Schema("axes", self.axis_specs), self._apply))
        apply_scheduling(self, v)
        self.ports = [AxisPort(a) for a in axis_values(joints, v, per_joint)]
        self.axes = [p.axis for p in self.ports]
        self.axis = self.axes[0]  # the (first) drive: single-axis code and tools read this one
        self.joints = [p.joint for p in self.ports]
        self.joint = self.joints[0]
        check_distinct_ids(self.joints, [a.cfg for a in self.axes])
        self._route = frame_router(self.axes)
        self.period = 1.0 / v["control_rate_hz"]
        self.error_frames = 0
        self.send_errors = 0
        self.bus_reopens = 0
        self._consecutive_send_errors = 0
        self._bus_dead_since: float | None = None
        self._bus_lock = threading.Lock()
        self._shutdown_done = False
        self.bus = open_bus(v["interface"], v["channel"], v["bitrate"], self._filters())
        self._rx_ok = True  # False after a read failure until the bus is reopened
        self._rx_prev = time.monotonic()  # start of the previous drain (lower bound of receive times)

        self.pub_joint = self.create_publisher(JointState, "joint_states", RECORDED_QOS)
        self.pub_drive = self.create_publisher(DriveState, "drive_state", SENSOR_QOS)
        # joint_commands as CDR bytes: the callback only keeps the newest message and when it
        # arrived, the control period applies it (see _take_commands).
        self._cmd_decoder = JointStateDecoder()
        self._cmd_pending: collections.deque = collections.deque(maxlen=1)
        self.sub_cmd = self.create_subscription(
            JointState, "joint_commands", self._on_command_bytes, COMMAND_QOS, raw=True
        )
        self.srv_enable = self.create_service(SetBool, "~/enable", self._on_enable)
        ids = ",".join(str(a.cfg.node_id) for a in self.axes)
        hw = f"{v['interface']}:{v['channel']}/{v['protocol']}#{ids}"
        self.diag = DiagnosticsPublisher(self, "drive_interface", hardware_id=hw)
        self.commands_foreign = 0  # for other joints only
        self.commands_malformed = 0  # array lengths that do not match
        self._ignored_last: dict[str, float] = {}
        self._diag_next = time.monotonic()
        n = len(self.joints)
        self._js = JointState(
            name=list(self.joints), position=[0.0] * n, velocity=[0.0] * n, effort=[0.0] * n
        )
        self._ros_clock = self.get_clock()
        self._pack_joints = JointStateEncoder(
            self.joints
        ).pack  # (sec, nsec, *positions, *velocities, *efforts)
        why = self.ports[0].packets.verify() or self._verify_joint_packer()
        self._raw = not why
        if why:
            self.get_logger().warning(
                f"publishing message objects (pre-serialised templates unusable: {why})"
            )
        self._loop_error = ""
        if v["enable_on_start"]:
            for a in self.axes:
                a.request_enable()
        if v["loop_spin"] > 0:  # busy-wait before each deadline: needs a thread of its own
            self.loop = FixedRateLoop(
                self.period, self._cycle, name="drive_interface_loop", spin=v["loop_spin"]
            )
            self.loop.start()
        else:  # run_node drives it in the executor thread (see the module docstring)
            self.loop = DeadlineLoop(self.period, self._cycle)
        drives = ", ".join(f"'{p.joint}' (id {p.axis.cfg.node_id})" for p in self.ports)
        self.get_logger().info(
            f"{v['protocol']} on {v['interface']}:{v['channel']} at {v['control_rate_hz']:g} Hz, "
            f"joint{'s' if n > 1 else ''} {drives}, drive{'s' if n > 1 else ''} "
            f"{'enabling' if v['enable_on_start'] else 'disabled until ~/enable'}"
        )

    def _verify_joint_packer(self) -> str:
        n = len(self.joints)
        vals = [0.5 + i for i in range(3 * n)]
        try:
            js = deserialize_message(self._pack_joints(3, 4, *vals), JointState)
        except Exception as exc:
            return f"{type(exc).__name__}: {exc}"
        got = [*js.position, *js.velocity, *js.effort]
        return "" if list(js.name) == self.joints and got == vals else "joint_states template differs"

    def _filters(self) -> list[dict]:
        out: list[dict] = []
        for a in self.axes:
            out += [f for f in can_filters(a.cfg) if f not in out]
        return out

    # ---- parameters / service / commands ------------------------------------------------------------
    def _apply(self, changes: dict) -> None:
        """Run-time change: rebuild every affected axis config first (all or nothing), then swap."""
        multi = bool(self.joints_param)
        shared = {k: v for k, v in changes.items() if "." not in k or k.split(".", 1)[0] not in self.joints}
        if multi:
            per_axis = [k for k in shared if k in AXIS_KEYS]
            if per_axis:
                raise ParameterError(
                    f"{per_axis[0]} applies per joint with several drives: set <joint>.{per_axis[0]} "
                    f"(joints: {', '.join(self.joints)})"
                )
        new_values = []
        for port in self.ports:
            vals = {**port.values, **shared}
            for k, val in changes.items():
                if k.startswith(port.joint + ".") and multi:
                    vals[k[len(port.joint) + 1 :]] = val
            new_values.append(vals)
        configs = [
            axis_config(vals, vals["control_rate_hz"]) for vals in new_values
        ]  # raises ParameterError -> rejected
        for port, vals, cfg in zip(self.ports, new_values, configs):
            with port.axis._lock:
                port.axis.cfg = cfg
            port.values = vals
        self.v = {**self.v, **shared}

    def _on_enable(self, req, resp):
        if req.data:
            for a in self.axes:
                a.request_enable()
            resp.success, resp.message = (
                True,
                "enable requested: the drive enables as soon as telemetry is fresh",
            )
        else:
            self.send_frames([f for a in self.axes for f in a.request_disable()])
            resp.success, resp.message = True, "drive disabled (zero torque, idle)"
        self.get_logger().info(resp.message)
        return resp

    def _on_command_bytes(self, data: bytes) -> None:
        """joint_commands callback (raw subscription): keep the newest message for the period.

        A one-element deque: appending replaces an older message not applied yet, and append /
        popleft are atomic, so the loop thread (``loop_spin`` > 0) may take while the executor
        thread appends. The receive time is when the executor runs this callback: rclpy's
        EventsExecutor cannot give a callback the middleware's message info (reception stamp),
        it raises SystemError for a two-argument callback (rclpy 7.1).
        """
        self._cmd_pending.append((data, time.monotonic()))

    def _take_commands(self, now: float, lo: float) -> None:
        """Apply the newest joint_commands message received since the previous period.

        The subscription is keep-last 1 (COMMAND_QOS) and the callback keeps only the newest
        message, so at most one message is decoded per period. It arrives as bytes and is read by
        node_utils' :class:`JointStateDecoder` (no message object; anything unusual goes through
        rclpy's deserialiser). Receive time = when the callback ran (monotonic clock), clamped to
        [previous period, now] like the CAN frames.
        """
        if not self._cmd_pending:
            return
        data, t = self._cmd_pending.popleft()
        t = now if t > now else lo if t < lo else t
        try:
            cmd = self._cmd_decoder.decode(data)
        except Exception:  # undecodable: rejected like a NaN command (zero torque) on every drive
            self._command((), (math.nan,) * len(self.ports), t)
            return
        self._command(cmd.name, cmd.effort, t)

    def _on_command(self, msg: JointState, now: float | None = None) -> None:
        """A joint_commands message object (the node itself takes bytes, see _take_commands)."""
        self._command(msg.name, msg.effort, time.monotonic() if now is None else now)

    def _command(self, names, efforts, now: float) -> None:
        """Efforts by joint name (a message may carry any subset of the joints; a drive left out
        gets no command, so its watchdog zeroes it), or by position when the message has no names
        and exactly one effort per drive. A message for none of this node's joints, or whose
        arrays do not match, is ignored (counted, logged at most once a second): the previous
        command stands until the watchdog."""
        ports = self.ports
        if names:
            if len(efforts) != len(names):
                self.commands_malformed += 1
                self._ignored(
                    "length",
                    f"ignored joint_commands with {len(names)} names but {len(efforts)} efforts: "
                    "must carry one effort per name",
                )
                return
            names = list(names)
            hit = False
            for port in ports:
                try:
                    i = names.index(port.joint)
                except ValueError:
                    continue
                hit = True
                self._set_command(port, efforts[i], now)
            if not hit:
                self.commands_foreign += 1
                self._ignored(
                    "foreign",
                    f"ignored joint_commands for {names}: this node drives {self.joints} "
                    "(set joint_name / joints to match the controller)",
                )
        elif len(efforts) == len(ports):
            for port, value in zip(ports, efforts):
                self._set_command(port, value, now)
        else:
            self.commands_malformed += 1
            self._ignored(
                "length",
                f"ignored joint_commands without names and {len(efforts)} efforts: "
                f"must name its joints or carry exactly {len(ports)} effort{'s' if len(ports) > 1 else ''} "
                f"(joints {self.joints})",
            )

    def _ignored(self, kind: str, text: str) -> None:
        """Warn about an ignored command message, at most once a second per kind."""
        now = time.monotonic()
        if now - self._ignored_last.get(kind, -math.inf) >= 1.0:
            self._ignored_last[kind] = now
            self.get_logger().warning(text)

    def _set_command(self, port: AxisPort, value, now: float) -> None:
        if not port.axis.set_command(value, now):  # a command without effort is rejected too
            self.get_logger().warning(
                f"rejected joint command effort = {value} for '{port.joint}': must be a finite number [N*m]; "
                "torque set to zero",
                throttle_duration_sec=1.0,
            )

    # ---- bus ------------------------------------------------------------------------------------------
    def send_frames(self, frames: list[Frame]) -> bool:
        ok = True
        for f in frames:
            msg = can.Message(
                arbitration_id=f.arbitration_id,
                data=f.data,
                is_extended_id=f.is_extended,
                is_remote_frame=f.is_remote,
                dlc=f.length,
            )
            try:
                with self._bus_lock:
                    self.bus.send(msg, timeout=0.001)
                self._consecutive_send_errors = 0
            except Exception as exc:  # can.CanError, OSError (ENOBUFS), closed bus ...
                ok = False
                self.send_errors += 1
                self._consecutive_send_errors += 1
                if self._consecutive_send_errors >= self.v["bus_error_limit"]:
                    self.bus_dead(f"{self._consecutive_send_errors} consecutive send failures: {exc}")
        return ok

    def bus_dead(self, reason: str) -> None:
        """Latch a bus fault on every drive (logged by each axis' fault log) and reopen the bus."""
        if self._bus_dead_since is None:
            self._bus_dead_since = time.monotonic()
            reason += f"; reopening the bus every {self.v['bus_recovery_period']:g} s"
        for a in self.axes:
            a.report_bus_fault(reason)

    def _recover_bus(self, now: float) -> None:
        if now - self._bus_dead_since < self.v["bus_recovery_period"]:
            return
        v = self.v
        try:
            with self._bus_lock:
                self.bus.shutdown()
                self.bus = open_bus(v["interface"], v["channel"], v["bitrate"], self._filters())
            self._rx_ok = True
            self._rx_prev = now
            self.bus_reopens += 1
            self._consecutive_send_errors = 0
            self._bus_dead_since = None
            for a in self.axes:  # each axis logs "bus cleared ...; drive stays disabled until ~/enable"
                a.clear_bus_fault()
        except Exception as exc:
            self._bus_dead_since = now
            self.get_logger().error(f"reopening the CAN bus failed: {exc}", throttle_duration_sec=5.0)

    def _drain(self, now: float, lo: float, off: float) -> None:
        """Feed every frame received since the previous period to its axis (control thread).

        Receive time = the frame's own timestamp (wall clock in python-can, the kernel's on
        SocketCAN) on the monotonic clock (``+ off``), clamped to [``lo`` = previous period, now].
        """
        if not self._rx_ok:
            return
        bus, route = self.bus, self._route
        try:
            for _ in range(RX_BATCH_MAX):
                msg = bus.recv(0.0)
                if msg is None:
                    return
                if msg.is_error_frame:
                    self.error_frames += 1
                    if msg.arbitration_id & CAN_ERR_BUSOFF:
                        self.bus_dead("bus-off error frame received")
                    continue
                t = msg.timestamp + off
                arb, data = msg.arbitration_id, msg.data
                route(arb, data).on_frame(
                    arb,
                    data,
                    msg.is_remote_frame,
                    msg.is_extended_id,
                    False,
                    now if t > now else lo if t < lo else t,
                )
        except Exception as exc:  # can.CanOperationError, OSError, closed bus ...
            self._rx_ok = False
            self.bus_dead(f"CAN reader failed: {type(exc).__name__}: {exc}")

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
                self.send_frames([f for a in self.axes for f in a.shutdown_frames()])
            except Exception:
                pass

    def _cycle_inner(self) -> None:
        now = time.monotonic()
        if self._bus_dead_since is not None:
            self._recover_bus(now)
        lo, self._rx_prev = self._rx_prev, now
        off = now - time.time()  # wall clock -> monotonic, for receive stamps
        self._drain(now, lo, off)
        self._take_commands(now, lo)
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
        if frames and not self.send_frames(frames):
            for port in ports:
                port.flags |= FAULT_BUS
        clock = self._ros_clock
        sec, nsec = divmod(
            clock.now().nanoseconds if clock.ros_time_is_active else time.time_ns(), 1_000_000_000
        )
        if None not in samples:
            if self._raw:
                self.pub_joint.publish(
                    self._pack_joints(
                        sec,
                        nsec,
                        *[s.position for s in samples],
                        *[s.velocity for s in samples],
                        *[s.effort for s in samples],
                    )
                )
            else:
                self._publish_joint_objects(sec, nsec, ports, samples)
        elif any(s is not None for s in samples):  # no made-up values: only the drives with telemetry
            fresh = [(p, s) for p, s in zip(ports, samples) if s is not None]
            self._publish_joint_objects(sec, nsec, [p for p, _ in fresh], [s for _, s in fresh])
        if self.pub_drive.get_subscription_count():  # nobody listening: nothing to send
            for port, sample in zip(ports, samples):
                drive = port.drive_values(sample, port.flags)
                if self._raw:
                    self.pub_drive.publish(port.packets.set_drive(sec, nsec, *drive))
                else:
                    self._publish_drive_object(sec, nsec, port, drive)
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

    def _publish_joint_objects(self, sec: int, nsec: int, ports: list[AxisPort], samples: list) -> None:
        """joint_states as a message object (fallback path, or a subset of the joints)."""
        js = self._js if len(ports) == len(self.ports) else JointState()
        js.header.stamp.sec, js.header.stamp.nanosec = sec, nsec
        js.name = [p.joint for p in ports]
        js.position = [s.position for s in samples]
        js.velocity = [s.velocity for s in samples]
        js.effort = [s.effort for s in samples]
        self.pub_joint.publish(js)

    def _publish_drive_object(self, sec: int, nsec: int, port: AxisPort, drive: tuple) -> None:
        ds = port.ds
        ds.header.stamp.sec, ds.header.stamp.nanosec = sec, nsec
        (
            ds.motor_position, ds.motor_velocity, ds.current_setpoint, ds.current_measured, ds.torque_estimate,
            ds.bus_voltage, ds.axis_state, ds.axis_error, ds.fault_flags, ds.enabled,
        ) = drive  # fmt: skip
        self.pub_drive.publish(ds)

    def _axis_status(self, port: AxisPort, now: float) -> tuple[int, str, dict]:
        """Diagnostic level, message and values of one drive."""
        axis, flags = port.axis, port.flags
        c, st = axis.counters, axis.decode_stats
        cur = (now, c.frames_rx, c.frames_tx, c.encoder_frames, c.commands)
        rates = [math.nan] * 4
        if port.diag_prev is not None and now > port.diag_prev[0]:
            dt = now - port.diag_prev[0]
            rates = [(a - b) / dt for a, b in zip(cur[1:], port.diag_prev[1:])]
        port.diag_prev = cur
        latched = axis.latched
        if latched & LATCHING:
            level, message = ERROR, f"fault: {axis.fault_reason}"
        elif flags:
            level, message = WARN, f"{'enabled' if axis.enabled else 'disabled'}, flags {fault_text(flags)}"
        elif axis.telemetry.encoder_time is None:
            level, message = WARN, "disabled, no telemetry yet"
        else:
            level, message = OK, "enabled" if axis.enabled else "disabled (telemetry ok)"
        values = {
            "enabled": axis.enabled,
            "fault_flags": fault_text(flags),
            "latched_faults": fault_text(latched),
            "fault_reason": axis.fault_reason,
            "rx_frame_rate_hz": rates[0],
            "tx_frame_rate_hz": rates[1],
            "encoder_rate_hz": rates[2],
            "command_rate_hz": rates[3],
            "frames_decoded": st.decoded,
            "frames_ignored": st.ignored,
            "frames_rejected": st.rejected,
            "last_reject_reason": st.last_reject_reason,
            "commands_rejected": c.commands_rejected,
            "telemetry_timeout_ms": axis.cfg.stale_after * 1e3,
            "telemetry_age_max_ms": axis.take_age_max() * 1e3,
            "telemetry_age_max_total_ms": c.telemetry_age_max * 1e3,
            "stale_faults": c.stale_faults,
            "telemetry_late_periods": c.late_periods,
            "watchdog_trips": c.watchdog_trips,
            "fault_trips": c.fault_trips,
            "limit_hits": c.limit_hits,
            "bus_faults": c.bus_errors,
            "axis_state": axis.telemetry.axis_state,
            "axis_error": f"0x{axis.telemetry.axis_error:X}",
        }
        return _level(level), message, values

    def _publish_diagnostics(self, now: float) -> None:
        try:
            bus_state = self.bus.state.name.lower()
        except Exception:
            bus_state = "unknown"
        if self._bus_dead_since is not None:
            bus_state = "dead (reopening)"
        statuses = [self._axis_status(p, now) for p in self.ports]
        if len(statuses) == 1:
            level, message, values = statuses[0]
        else:
            level = max(s[0] for s in statuses)
            message = "; ".join(f"{p.joint}: {s[1]}" for p, s in zip(self.ports, statuses))
            values = {f"{p.joint}.{k}": v for p, s in zip(self.ports, statuses) for k, v in s[2].items()}
        stats = self.loop.stats
        values.update(
            {
                "commands_foreign": self.commands_foreign,
                "commands_malformed": self.commands_malformed,
                "send_errors": self.send_errors,
                "error_frames": self.error_frames,
                "bus_reopens": self.bus_reopens,
                "bus_state": bus_state,
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
        self.destroy_subscription(self.sub_cmd)
        frames = [f for a in self.axes for f in a.shutdown_frames()]
        for _attempt in range(3):
            if self.send_frames(frames):
                break
            time.sleep(0.01)
        else:
            self.get_logger().error("could not send the idle request: check the drive (its own watchdog)")
        time.sleep(0.005)  # let the frames leave the socket before closing it
        self.get_logger().info(f"drive{'s' if len(self.axes) > 1 else ''} left safe: zero torque, idle")
        try:
            self.bus.shutdown()
        except Exception as exc:
            self.get_logger().warning(f"closing the CAN bus: {exc}")


def main(args: list[str] | None = None) -> int:
    return run_node(DriveInterface, args)


if __name__ == "__main__":
    raise SystemExit(main())
