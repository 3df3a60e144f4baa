"""drive_interface: one servo-drive axis on CAN (ODrive CANSimple or MIT) as ROS joint topics.

Publishes ``joint_states`` (sensor_msgs/JointState: position rad, velocity rad/s, effort = joint
torque N*m) and ``drive_state`` (friction_msgs/DriveState) once per control period, subscribes to
``joint_commands`` (sensor_msgs/JointState effort = joint torque command) with keep-last 1, and
publishes ``diagnostics``. Service ``~/enable`` (std_srvs/SetBool) enables (clearing latched faults)
or disables the drive.

Safe by default: the drive is only enabled on request (``enable_on_start`` or ``~/enable``); command
watchdog, torque/current/velocity limits, NaN/inf rejection, stale-telemetry and drive-error faults
live in :class:`friction_ros.core.can.axis.DriveAxis`; every fault, Ctrl-C/SIGTERM and shutdown send
zero torque + IDLE (ODrive) or zero command + exit motor mode (MIT). Bus errors are counted, a dead
bus (bus-off, reader failure, repeated send failures) latches a bus fault and is reopened.

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

import dataclasses
import math
import struct
import threading
import time

import can
from friction_msgs.msg import DriveState
from rclpy.impl.implementation_singleton import rclpy_implementation as _rclpy
from rclpy.node import Node
from rclpy.serialization import deserialize_message
from rclpy.type_support import check_is_valid_msg_type
from sensor_msgs.msg import JointState
from std_srvs.srv import SetBool

from friction_ros.core.can import mit as mitc
from friction_ros.core.can import odrive as od
from friction_ros.core.can.axis import (
    FAULT_BUS,
    LATCHING,
    PROTOCOLS,
    AxisConfig,
    DriveAxis,
    fault_text,
)
from friction_ros.core.can.frame import Frame
from friction_ros.core.can.joint import JointConversion
from friction_ros.core.validation import ParameterError
from friction_ros.nodes.node_utils import (
    COMMAND_QOS,
    ERROR,
    OK,
    SCHEDULING_PARAMS,
    SENSOR_QOS,
    STATE_QOS,
    WARN,
    DeadlineLoop,
    DiagnosticsPublisher,
    FixedRateLoop,
    JointStateDecoder,
    JointStateEncoder,
    Param,
    add_runtime_validation,
    apply_scheduling,
    declare,
    run_node,
)


def _level(x) -> int:
    """node_utils' OK/WARN/ERROR are bytes (msg constants) but DiagnosticsPublisher wants an int."""
    return x[0] if isinstance(x, bytes) else int(x)


CAN_ERR_BUSOFF = 0x40  # SocketCAN error class bit in the id of an error frame
RX_BATCH_MAX = 256  # frames read per period at most (a 1 Mbit/s bus carries ~8 per ms)
INTERFACES = tuple(sorted(can.VALID_INTERFACES))

PARAMS = [
    Param(
        "interface",
        "socketcan",
        "python-can interface (socketcan on robots; virtual in tests)",
        choices=INTERFACES,
        read_only=True,
    ),
    Param("channel", "can0", "CAN channel (socketcan: network interface name)", read_only=True),
    Param(
        "bitrate",
        1000000,
        "bitrate for interfaces that set it (socketcan: set with ip link)",
        lo=10000,
        hi=1000000,
        read_only=True,
        unit="bit/s",
    ),
    Param("protocol", "odrive_cansimple", "drive protocol", choices=PROTOCOLS, read_only=True),
    Param("node_id", 0, "ODrive node id (0..63) or MIT motor CAN id", lo=0, hi=0x7FF, read_only=True),
    Param("mit.master_id", 0, "MIT: CAN id the motor replies to", lo=0, hi=0x7FF, read_only=True),
    *[
        Param(f"mit.{k}", float(getattr(mitc.MitRanges(), k)), f"MIT scaling range {k}", read_only=True)
        for k in (
            "p_min",
            "p_max",
            "v_min",
            "v_max",
            "kp_min",
            "kp_max",
            "kd_min",
            "kd_max",
            "t_min",
            "t_max",
        )
    ],
    Param("joint_name", "joint", "joint name in joint_states / joint_commands", read_only=True),
    Param(
        "control_rate_hz",
        1000.0,
        "publication and command rate",
        lo=1.0,
        hi=5000.0,
        read_only=True,
        unit="Hz",
    ),
    Param("gear_ratio", 1.0, "motor revolutions per joint revolution", lo=1e-6, read_only=True),
    Param("torque_constant", 0.1, "motor torque constant", lo=1e-9, read_only=True, unit="N*m/A"),
    Param("direction", 1, "sign between motor and joint: 1 or -1", lo=-1, hi=1, read_only=True),
    Param("zero_offset", 0.0, "joint position reported when the motor reads 0", read_only=True, unit="rad"),
    Param(
        "effort_source",
        "current",
        "joint effort from Iq*k_t*gear (current) or the drive's Torque_Estimate",
        choices=("current", "torque_estimate"),
        read_only=True,
    ),
    Param(
        "request_telemetry",
        False,
        "ODrive: also send RTR requests for encoder + effort every period",
        read_only=True,
    ),
    Param("torque_limit", 1.0, "|joint torque command| limit", lo=0.0, unit="N*m"),
    Param("current_limit", 10.0, "|motor current| limit (also sent to the drive)", lo=0.0, unit="A"),
    Param(
        "velocity_limit",
        10.0,
        "|joint velocity| above which no accelerating torque is sent",
        lo=0.0,
        unit="rad/s",
    ),
    Param(
        "command_timeout",
        0.1,
        "watchdog: zero torque when no command arrived for this long",
        lo=1e-4,
        hi=10.0,
        unit="s",
    ),
    Param(
        "telemetry_timeout",
        0.01,
        "stale telemetry fault when no encoder/effort frame for this long",
        lo=1e-4,
        hi=10.0,
        unit="s",
    ),
    Param(
        "enable_on_start", False, "enable the drive (closed loop, zero torque) as soon as telemetry arrives"
    ),
    Param(
        "loop_spin",
        0.0,
        "busy-wait before each period for timing accuracy (costs spin/period of a core)",
        lo=0.0,
        hi=0.001,
        read_only=True,
        unit="s",
    ),
    Param("diagnostics_period", 1.0, "diagnostics publication period", lo=0.05, hi=60.0, unit="s"),
    Param("bus_error_limit", 20, "consecutive failed sends before the bus counts as dead", lo=1, hi=100000),
    Param("bus_recovery_period", 1.0, "wait before reopening a dead bus", lo=0.01, hi=60.0, unit="s"),
    *SCHEDULING_PARAMS,
]
RUNTIME = ("torque_limit", "current_limit", "velocity_limit", "command_timeout", "telemetry_timeout")


def axis_config(v: dict) -> AxisConfig:
    """Build the core AxisConfig from validated parameter values (ParameterError on bad combos)."""
    if v["direction"] not in (1, -1):
        raise ParameterError(f"direction = {v['direction']} is not allowed: must be one of 1, -1")
    for k in ("torque_limit", "current_limit", "velocity_limit"):
        if not v[k] > 0:
            raise ParameterError(f"{k} = {v[k]:g} is out of range: must be > 0")
    ranges = mitc.MitRanges(**{f.name: v[f"mit.{f.name}"] for f in dataclasses.fields(mitc.MitRanges)})
    return AxisConfig(
        protocol=v["protocol"],
        node_id=v["node_id"],
        mit_master_id=v["mit.master_id"],
        mit_ranges=ranges,
        conversion=JointConversion(v["gear_ratio"], v["torque_constant"], v["direction"], v["zero_offset"]),
        torque_limit=v["torque_limit"],
        current_limit=v["current_limit"],
        velocity_limit=v["velocity_limit"],
        command_timeout=v["command_timeout"],
        telemetry_timeout=v["telemetry_timeout"],
        effort_source=v["effort_source"],
        request_telemetry=v["request_telemetry"],
    )


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
class _Cdr:
    """Writer of little-endian plain CDR (XCDR1: what ROS 2 middlewares put on the wire), used to
    build a message template once; alignment is relative to the end of the 4-byte encapsulation header."""

    def __init__(self):
        self.buf = bytearray(b"\x00\x01\x00\x00")  # CDR_LE

    def align(self, n: int) -> None:
        self.buf += bytes(-(len(self.buf) - 4) % n)

    def put(self, fmt: str, *values) -> int:
        """Pack values of one primitive type (aligned to its size); return their offset."""
        st = struct.Struct("<" + fmt)
        self.align(struct.calcsize("<" + fmt[-1]))
        off = len(self.buf)
        self.buf += st.pack(*values)
        return off

    def string(self, text: str) -> None:
        raw = text.encode() + b"\x00"
        self.put("I", len(raw))
        self.buf += raw

    def header(self) -> int:
        off = self.put("iI", 0, 0)  # stamp sec, nanosec
        self.string("")  # frame_id
        return off


class StatePackets:
    """joint_states and drive_state as CDR bytes (rclpy ``publish_raw``; same wire types).

    joint_states: node_utils' :class:`JointStateEncoder`; drive_state: a template serialised once and
    patched in place (two ``struct.pack_into``). No message objects, no rclpy conversion, no
    middleware serialisation per period. Both are checked once against rclpy's own deserialiser
    (:meth:`verify`); the node falls back to publishing message objects if the check fails.
    """

    _STAMP = struct.Struct("<iI")
    _DS = struct.Struct(
        "<6d3I?"
    )  # motor_position .. bus_voltage, axis_state, axis_error, fault_flags, enabled

    def __init__(self, joint: str, protocol: str):
        self.joint, self.protocol = joint, protocol
        self.set_joint = JointStateEncoder([joint]).pack  # (sec, nanosec, position, velocity, effort)
        w = _Cdr()
        self.ds_stamp = w.header()
        w.string(joint)
        w.string(protocol)
        self.ds_block = w.put("6d", *([0.0] * 6))
        w.buf += bytes(self._DS.size - 48)
        self.ds = w.buf

    def set_drive(self, sec: int, nsec: int, *values) -> bytes:
        buf = self.ds
        self._STAMP.pack_into(buf, self.ds_stamp, sec, nsec)
        self._DS.pack_into(buf, self.ds_block, *values)
        return bytes(buf)

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
        self.set_drive(0, 0, *([0.0] * 6), 0, 0, 0, False)
        return "" if ok_js and ok_ds else "round trip through rclpy's deserialiser differs"


class DriveInterface(Node):
    def __init__(self, **kwargs):
        super().__init__("drive_interface", **kwargs)
        self.v = v = declare(self, PARAMS)
        apply_scheduling(self, v)
        self.axis = DriveAxis(axis_config(v))
        self.joint = v["joint_name"]
        self.period = 1.0 / v["control_rate_hz"]
        self.error_frames = 0
        self.send_errors = 0
        self.bus_reopens = 0
        self._consecutive_send_errors = 0
        self._bus_dead_since: float | None = None
        self._bus_lock = threading.Lock()
        self._shutdown_done = False
        self.bus = open_bus(v["interface"], v["channel"], v["bitrate"], can_filters(self.axis.cfg))
        self._rx_ok = True  # False after a read failure until the bus is reopened
        self._rx_prev = time.monotonic()  # start of the previous drain (lower bound of receive times)

        self.pub_joint = self.create_publisher(JointState, "joint_states", STATE_QOS)
        self.pub_drive = self.create_publisher(DriveState, "drive_state", SENSOR_QOS)
        # joint_commands is taken by the control period itself (see _take_commands), not by the
        # executor: an rcl subscription that no executor waits on, so a command costs no wake-up.
        check_is_valid_msg_type(JointState)
        self._cmd_decoder = JointStateDecoder()
        with self.handle:
            self.sub_cmd = _rclpy.Subscription(
                self.handle, JointState, "joint_commands", COMMAND_QOS.get_c_qos_profile()
            )
        self.srv_enable = self.create_service(SetBool, "~/enable", self._on_enable)
        hw = f"{v['interface']}:{v['channel']}/{v['protocol']}#{v['node_id']}"
        self.diag = DiagnosticsPublisher(self, "drive_interface", hardware_id=hw)
        add_runtime_validation(self, PARAMS, self._apply)
        self.commands_foreign = 0
        self._diag_next = time.monotonic()
        self._diag_prev: tuple[float, int, int, int, int] | None = None
        self._js = JointState(name=[self.joint], position=[0.0], velocity=[0.0], effort=[0.0])
        self._ds = DriveState(joint_name=self.joint, protocol=v["protocol"])
        self._clock = self.get_clock()
        self._packets: StatePackets | None = StatePackets(self.joint, v["protocol"])
        why = self._packets.verify()
        if why:
            self._packets = None
            self.get_logger().warning(
                f"publishing message objects (pre-serialised templates unusable: {why})"
            )
        self._loop_error = ""
        if v["enable_on_start"]:
            self.axis.request_enable()
        if v["loop_spin"] > 0:  # busy-wait before each deadline: needs a thread of its own
            self.loop = FixedRateLoop(
                self.period, self._cycle, name="drive_interface_loop", spin=v["loop_spin"]
            )
            self.loop.start()
        else:  # run_node drives it in the executor thread (see the module docstring)
            self.loop = DeadlineLoop(self.period, self._cycle)
        self.get_logger().info(
            f"{v['protocol']} node {v['node_id']} on {v['interface']}:{v['channel']} at {v['control_rate_hz']:g} Hz, "
            f"joint '{self.joint}', drive {'enabling' if v['enable_on_start'] else 'disabled until ~/enable'}"
        )

    # ---- parameters / service / commands ------------------------------------------------------------
    def _apply(self, changes: dict) -> None:
        merged = {**self.v, **changes}
        new = axis_config(merged)  # raises ParameterError -> change rejected
        with self.axis._lock:
            self.axis.cfg = new
        self.v = merged

    def _on_enable(self, req, resp):
        if req.data:
            self.axis.request_enable()
            resp.success, resp.message = (
                True,
                "enable requested: the drive enables as soon as telemetry is fresh",
            )
        else:
            self.send_frames(self.axis.request_disable())
            resp.success, resp.message = True, "drive disabled (zero torque, idle)"
        self.get_logger().info(resp.message)
        return resp

    def _take_commands(self, now: float, lo: float, off: float) -> None:
        """Apply the newest joint_commands message received since the previous period.

        The subscription is keep-last 1 (COMMAND_QOS), so the middleware holds at most one
        message: one take per period (a second, empty take would cost ~15 us of rclpy each period).

        Taken as bytes and read by node_utils' :class:`JointStateDecoder` (no message object;
        anything unusual goes through rclpy's deserialiser). Receive time = the middleware's
        reception stamp (system clock) on the monotonic clock, clamped to [previous period, now]
        like the CAN frames.
        """
        got = self.sub_cmd.take_message(JointState, True)
        if got is None:
            return
        t = got[1]["received_timestamp"] * 1e-9 + off
        t = now if t > now else lo if t < lo else t
        try:
            cmd = self._cmd_decoder.decode(got[0])
        except Exception:  # undecodable: rejected like a NaN command (zero torque)
            self._command((), (math.nan,), t)
            return
        self._command(cmd.name, cmd.effort, t)

    def _on_command(self, msg: JointState, now: float | None = None) -> None:
        """A joint_commands message object (the node itself takes bytes, see _take_commands)."""
        self._command(msg.name, msg.effort, time.monotonic() if now is None else now)

    def _command(self, names, efforts, now: float) -> None:
        if names:
            try:
                i = list(names).index(self.joint)
            except ValueError:
                self.commands_foreign += 1
                return
        elif len(efforts) == 1:
            i = 0
        else:
            self.commands_foreign += 1
            return
        value = efforts[i] if i < len(efforts) else math.nan  # a command without effort is rejected
        if not self.axis.set_command(value, now):
            self.get_logger().warning(
                f"rejected joint command effort = {value} for '{self.joint}': must be a finite number [N*m]; "
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
        if self._bus_dead_since is None:
            self._bus_dead_since = time.monotonic()
            self.get_logger().error(f"CAN bus fault: {reason}; drive disabled, reopening the bus")
        self.axis.report_bus_fault(reason)

    def _recover_bus(self, now: float) -> None:
        if now - self._bus_dead_since < self.v["bus_recovery_period"]:
            return
        v = self.v
        try:
            with self._bus_lock:
                self.bus.shutdown()
                self.bus = open_bus(v["interface"], v["channel"], v["bitrate"], can_filters(self.axis.cfg))
            self._rx_ok = True
            self._rx_prev = now
            self.bus_reopens += 1
            self._consecutive_send_errors = 0
            self._bus_dead_since = None
            self.get_logger().warning("CAN bus reopened; drive stays disabled until ~/enable")
        except Exception as exc:
            self._bus_dead_since = now
            self.get_logger().error(f"reopening the CAN bus failed: {exc}", throttle_duration_sec=5.0)

    def _drain(self, now: float, lo: float, off: float) -> None:
        """Feed every frame received since the previous period to the axis (control thread).

        Receive time = the frame's own timestamp (wall clock in python-can, the kernel's on
        SocketCAN) on the monotonic clock (``+ off``), clamped to [``lo`` = previous period, now].
        """
        if not self._rx_ok:
            return
        bus, on_frame = self.bus, self.axis.on_frame
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
                on_frame(
                    msg.arbitration_id,
                    msg.data,
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
            self.axis.report_bus_fault(f"internal error: {self._loop_error}")
            try:
                self.send_frames(self.axis.shutdown_frames())
            except Exception:
                pass

    def _cycle_inner(self) -> None:
        now = time.monotonic()
        if self._bus_dead_since is not None:
            self._recover_bus(now)
        lo, self._rx_prev = self._rx_prev, now
        off = now - time.time()  # wall clock -> monotonic, for receive stamps
        self._drain(now, lo, off)
        self._take_commands(now, lo, off)
        res = self.axis.cycle(now)
        flags = res.flags
        if res.frames and not self.send_frames(res.frames):
            flags |= FAULT_BUS
        clock = self._clock
        sec, nsec = divmod(
            clock.now().nanoseconds if clock.ros_time_is_active else time.time_ns(), 1_000_000_000
        )
        tel, sample = self.axis.telemetry, res.sample
        drive = (
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
        packets = self._packets
        if packets is not None:
            if sample is not None:
                self.pub_joint.publish(
                    packets.set_joint(sec, nsec, sample.position, sample.velocity, sample.effort)
                )
            if self.pub_drive.get_subscription_count():  # nobody listening: nothing to send
                self.pub_drive.publish(packets.set_drive(sec, nsec, *drive))
        else:
            self._publish_objects(sec, nsec, sample, drive)
        if now >= self._diag_next:
            self._diag_next = now + self.v["diagnostics_period"]
            self._publish_diagnostics(now, flags)

    def _publish_objects(self, sec: int, nsec: int, sample, drive: tuple) -> None:
        """Fallback of the pre-serialised path: the same values through reused message objects."""
        js, ds = self._js, self._ds
        js.header.stamp.sec = ds.header.stamp.sec = sec
        js.header.stamp.nanosec = ds.header.stamp.nanosec = nsec
        if sample is not None:
            js.position[0], js.velocity[0], js.effort[0] = sample.position, sample.velocity, sample.effort
            self.pub_joint.publish(js)
        (
            ds.motor_position, ds.motor_velocity, ds.current_setpoint, ds.current_measured, ds.torque_estimate,
            ds.bus_voltage, ds.axis_state, ds.axis_error, ds.fault_flags, ds.enabled,
        ) = drive  # fmt: skip
        if self.pub_drive.get_subscription_count():
            self.pub_drive.publish(ds)

    def _publish_diagnostics(self, now: float, flags: int) -> None:
        c, st = self.axis.counters, self.axis.decode_stats
        cur = (now, c.frames_rx, c.frames_tx, c.encoder_frames, c.commands)
        rates = [math.nan] * 4
        if self._diag_prev is not None and now > self._diag_prev[0]:
            dt = now - self._diag_prev[0]
            rates = [(a - b) / dt for a, b in zip(cur[1:], self._diag_prev[1:])]
        self._diag_prev = cur
        try:
            bus_state = self.bus.state.name.lower()
        except Exception:
            bus_state = "unknown"
        if self._bus_dead_since is not None:
            bus_state = "dead (reopening)"
        latched = self.axis.latched
        if latched & LATCHING:
            level, message = ERROR, f"fault: {self.axis.fault_reason}"
        elif flags:
            level, message = (
                WARN,
                f"{'enabled' if self.axis.enabled else 'disabled'}, flags {fault_text(flags)}",
            )
        else:
            level, message = OK, "enabled" if self.axis.enabled else "disabled (telemetry ok)"
        stats = self.loop.stats
        self.diag.publish(
            _level(level),
            message,
            {
                "enabled": self.axis.enabled,
                "fault_flags": fault_text(flags),
                "latched_faults": fault_text(latched),
                "fault_reason": self.axis.fault_reason,
                "rx_frame_rate_hz": rates[0],
                "tx_frame_rate_hz": rates[1],
                "encoder_rate_hz": rates[2],
                "command_rate_hz": rates[3],
                "frames_decoded": st.decoded,
                "frames_ignored": st.ignored,
                "frames_rejected": st.rejected,
                "last_reject_reason": st.last_reject_reason,
                "commands_rejected": c.commands_rejected,
                "commands_foreign": self.commands_foreign,
                "watchdog_trips": c.watchdog_trips,
                "fault_trips": c.fault_trips,
                "limit_hits": c.limit_hits,
                "send_errors": self.send_errors,
                "error_frames": self.error_frames,
                "bus_faults": c.bus_errors,
                "bus_reopens": self.bus_reopens,
                "bus_state": bus_state,
                "axis_state": self.axis.telemetry.axis_state,
                "axis_error": f"0x{self.axis.telemetry.axis_error:X}",
                "loop_overruns": stats.overruns,
                "loop_max_lateness_ms": stats.max_lateness * 1e3,
                "loop_exec_ms": stats.last_exec * 1e3,
            },
        )

    # ---- shutdown -------------------------------------------------------------------------------------
    def on_shutdown(self) -> None:
        """Stop the loop, then zero torque and idle / exit motor mode (retried), then close the bus."""
        if self._shutdown_done:
            return
        self._shutdown_done = True
        self.loop.stop()
        self.sub_cmd.destroy_when_not_in_use()
        frames = self.axis.shutdown_frames()
        for _attempt in range(3):
            if self.send_frames(frames):
                break
            time.sleep(0.01)
        else:
            self.get_logger().error("could not send the idle request: check the drive (its own watchdog)")
        time.sleep(0.005)  # let the frames leave the socket before closing it
        self.get_logger().info("drive left safe: zero torque, idle")
        try:
            self.bus.shutdown()
        except Exception as exc:
            self.get_logger().warning(f"closing the CAN bus: {exc}")


def main(args: list[str] | None = None) -> int:
    return run_node(DriveInterface, args)


if __name__ == "__main__":
    raise SystemExit(main())
