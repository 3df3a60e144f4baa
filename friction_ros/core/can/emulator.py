"""Frame-level servo-drive emulator (ODrive CANSimple or MIT) on a python-can bus.

A plant object (``step(command_torque, dt) -> measurement`` with joint ``position``, ``velocity``,
``effort`` attributes, e.g. ``friction_ros.core.plant.servo.GearheadServoPlant`` in torque mode) sits behind
a drive that answers the same frames a real one does:

* ODrive: Set_Axis_State (IDLE / CLOSED_LOOP_CONTROL), Set_Controller_Mode, Set_Input_Torque,
  Set_Limits, Clear_Errors, Estop, RTR requests of every telemetry message; cyclic Heartbeat,
  Get_Encoder_Estimates, Get_Iq, Get_Torques, Get_Bus_Voltage_Current at configurable rates.
  Only torque control mode moves the plant (other modes apply zero torque).
* MIT: enter / exit motor mode, set zero, command ``tau = kp (p_des - p) + kd (v_des - v) + t_ff``
  (clamped to the torque range) and one reply per received frame.

Faults for tests: latency of every transmitted frame, random frame loss, going silent, an injected
axis error (the axis drops to IDLE / leaves motor mode, as a real drive does).

The bus is only touched in :meth:`poll` / the background thread; :meth:`handle` and :meth:`advance`
are plain logic, so a test can run the emulator in lock step without threads.
"""

from __future__ import annotations

import collections
import math
import random
import threading
import time
from dataclasses import dataclass, field

from friction_ros.core.can import mit as mitc
from friction_ros.core.can import odrive as od
from friction_ros.core.can.frame import Frame
from friction_ros.core.can.joint import JointConversion
from friction_ros.core.validation import ParameterError, check_choice, check_int, check_real

PROTOCOLS = ("odrive_cansimple", "mit")


@dataclass(frozen=True)
class EmulatorConfig:
    protocol: str = "odrive_cansimple"
    node_id: int = 0
    mit_master_id: int = 0
    mit_ranges: mitc.MitRanges = field(default_factory=mitc.MitRanges)
    conversion: JointConversion = field(default_factory=JointConversion)
    physics_rate_hz: float = 1000.0
    encoder_rate_hz: float = 1000.0  # cyclic Get_Encoder_Estimates (0: only on RTR request)
    iq_rate_hz: float = 1000.0  # cyclic Get_Iq
    torques_rate_hz: float = 0.0  # cyclic Get_Torques
    heartbeat_rate_hz: float = 10.0
    bus_voltage_rate_hz: float = 0.0
    bus_voltage: float = 24.0  # [V]
    current_limit: float = 60.0  # the drive's own current limit [A] until Set_Limits
    latency: float = 0.0  # [s] added to every transmitted frame
    loss_probability: float = 0.0  # probability that a transmitted frame is lost
    seed: int = 0

    def __post_init__(self):
        check_choice("emulator.protocol", self.protocol, PROTOCOLS)
        if self.protocol == "odrive_cansimple":
            check_int("emulator.node_id", self.node_id, 0, od.NODE_ID_MAX)
        else:
            check_int("emulator.node_id", self.node_id, 0, 0x7FF)
        check_real("emulator.physics_rate_hz", self.physics_rate_hz, 0.0, 100_000.0, lo_open=True, unit="Hz")
        for name in (
            "encoder_rate_hz",
            "iq_rate_hz",
            "torques_rate_hz",
            "heartbeat_rate_hz",
            "bus_voltage_rate_hz",
        ):
            check_real(f"emulator.{name}", getattr(self, name), 0.0, 10_000.0, unit="Hz (0 = off)")
        check_real("emulator.current_limit", self.current_limit, 0.0, lo_open=True, unit="A")
        check_real("emulator.latency", self.latency, 0.0, 1.0, unit="s")
        check_real("emulator.loss_probability", self.loss_probability, 0.0, 1.0)


@dataclass
class EmulatorStats:
    frames_rx: int = 0
    frames_tx: int = 0
    frames_lost: int = 0
    frames_suppressed: int = 0  # not sent while silent
    send_errors: int = 0
    physics_steps: int = 0
    commands: int = 0


class DriveEmulator:
    """One emulated drive axis behind a python-can ``bus`` (or none, for lock-step use)."""

    def __init__(self, bus, plant, config: EmulatorConfig | None = None, clock=time.monotonic):
        self.bus = bus
        self.plant = plant
        self.cfg = cfg = config or EmulatorConfig()
        self.conv = cfg.conversion
        self.clock = clock
        self.stats = EmulatorStats()
        self.silent = False
        self.rx_log: list[tuple[float, Frame]] | None = None  # set to [] to record received frames
        self._rng = random.Random(cfg.seed)
        self._out: collections.deque[tuple[float, Frame]] = collections.deque()
        self._lock = threading.RLock()
        self._thread: threading.Thread | None = None
        self._stop = threading.Event()
        self.dt = 1.0 / cfg.physics_rate_hz
        self._t_phys: float | None = None
        self.meas = plant.step(0.0, self.dt)
        self.time = 0.0
        # drive state (motor side)
        self.axis_error = 0
        self.axis_state = od.AxisState.IDLE
        self.control_mode = od.ControlMode.TORQUE_CONTROL
        self.input_mode = od.InputMode.PASSTHROUGH
        self.input_torque = 0.0
        self.applied_torque = 0.0  # motor side [N*m]
        self.current_limit = cfg.current_limit
        self.velocity_limit = math.inf  # motor [rad/s]
        if cfg.protocol == "odrive_cansimple":
            self.decoder = od.OdriveDecoder([cfg.node_id], role="drive")
            self.mit = None
            self._cyclic = [
                [cfg.heartbeat_rate_hz, 0.0, od.Cmd.HEARTBEAT],
                [cfg.encoder_rate_hz, 0.0, od.Cmd.GET_ENCODER_ESTIMATES],
                [cfg.iq_rate_hz, 0.0, od.Cmd.GET_IQ],
                [cfg.torques_rate_hz, 0.0, od.Cmd.GET_TORQUES],
                [cfg.bus_voltage_rate_hz, 0.0, od.Cmd.GET_BUS_VOLTAGE_CURRENT],
            ]
            self._cyclic = [c for c in self._cyclic if c[0] > 0]
        else:
            self.mit = mitc.MitCodec(cfg.node_id, cfg.mit_ranges, cfg.mit_master_id)
            self.decoder = mitc.MitDecoder(self.mit, role="drive")
            self._cyclic = []
            self.motor_mode = False
            self.mit_cmd = mitc.MitCommand(cfg.node_id, 0.0, 0.0, 0.0, 0.0, 0.0)
            self.zero_offset = 0.0  # motor rad

    # ---- faults -------------------------------------------------------------------------------------
    def set_silent(self, silent: bool = True) -> None:
        """Stop (or resume) transmitting anything, like a drive that lost power or its CAN link."""
        self.silent = silent

    def inject_axis_error(self, error: int = od.ERROR_CURRENT_LIMIT_VIOLATION) -> None:
        """Raise a drive error: the axis disarms (IDLE / leaves motor mode) and reports it."""
        with self._lock:
            self.axis_error |= int(error)
            self.axis_state = od.AxisState.IDLE
            if self.mit is not None:
                self.motor_mode = False

    # ---- motor-side measurements ----------------------------------------------------------------------
    @property
    def motor_position(self) -> float:
        p = self.conv.motor_position(self.meas.position)
        return p - self.zero_offset if self.mit is not None else p

    @property
    def motor_velocity(self) -> float:
        return self.conv.motor_velocity(self.meas.velocity)

    @property
    def motor_torque_measured(self) -> float:
        return self.conv.motor_torque(self.meas.effort)

    @property
    def armed(self) -> bool:
        if self.mit is not None:
            return self.motor_mode and not self.axis_error
        return self.axis_state == od.AxisState.CLOSED_LOOP_CONTROL

    # ---- logic ----------------------------------------------------------------------------------------
    def telemetry_frame(self, cmd: int) -> Frame:
        n = self.cfg.node_id
        kt = self.conv.torque_constant
        if cmd == od.Cmd.GET_ENCODER_ESTIMATES:
            return od.encode_encoder_estimates(n, self.motor_position, self.motor_velocity)
        if cmd == od.Cmd.GET_IQ:
            return od.encode_iq(n, self.applied_torque / kt, self.motor_torque_measured / kt)
        if cmd == od.Cmd.GET_TORQUES:
            return od.encode_torques(n, self.applied_torque, self.motor_torque_measured)
        if cmd == od.Cmd.HEARTBEAT:
            return od.encode_heartbeat(n, self.axis_error, self.axis_state)
        if cmd == od.Cmd.GET_BUS_VOLTAGE_CURRENT:
            return od.encode_bus_voltage_current(n, self.cfg.bus_voltage, 0.0)
        return od.encode_error(n, self.axis_error, 0)

    def mit_reply(self) -> Frame:
        return self.mit.encode_reply(
            self.motor_position, self.motor_velocity, self.motor_torque_measured, 25.0, self.axis_error & 0xFF
        )

    def handle(self, frame: Frame, t: float) -> None:
        """React to one received frame at time ``t``."""
        msg = self.decoder.decode_frame(frame)
        with self._lock:
            self.stats.frames_rx += 1
            if self.rx_log is not None:
                self.rx_log.append((t, frame))
            if msg is None:
                return
            if self.mit is not None:
                self._handle_mit(msg, t)
            else:
                self._handle_odrive(msg, t)

    def _handle_odrive(self, msg, t: float) -> None:
        if isinstance(msg, od.SetInputTorque):
            self.input_torque = msg.torque
            self.stats.commands += 1
        elif isinstance(msg, od.RtrRequest):
            self._queue(self.telemetry_frame(msg.cmd), t)
        elif isinstance(msg, od.SetAxisState):
            if msg.state == od.AxisState.CLOSED_LOOP_CONTROL:
                if not self.axis_error:
                    self.axis_state = od.AxisState.CLOSED_LOOP_CONTROL
            elif msg.state == od.AxisState.IDLE:
                self.axis_state = od.AxisState.IDLE
                self.input_torque = 0.0
        elif isinstance(msg, od.SetControllerMode):
            self.control_mode, self.input_mode = msg.control_mode, msg.input_mode
        elif isinstance(msg, od.SetLimits):
            self.velocity_limit, self.current_limit = msg.velocity_limit, msg.current_limit
        elif isinstance(msg, od.ClearErrors):
            self.axis_error = 0
        elif isinstance(msg, od.Estop):
            self.axis_error |= od.ERROR_ESTOP_REQUESTED
            self.axis_state = od.AxisState.IDLE

    def _handle_mit(self, msg, t: float) -> None:
        if isinstance(msg, mitc.MitSpecial):
            if msg.kind == "enter":
                self.motor_mode = not self.axis_error
            elif msg.kind == "exit":
                self.motor_mode = False
            else:
                self.zero_offset += self.motor_position
        else:
            self.mit_cmd = msg
            self.stats.commands += 1
        self._queue(self.mit_reply(), t)

    def _motor_torque(self) -> float:
        if self.mit is not None:
            if not self.armed:
                return 0.0
            c, r = self.mit_cmd, self.cfg.mit_ranges
            tau = (
                c.kp * (c.position - self.motor_position)
                + c.kd * (c.velocity - self.motor_velocity)
                + c.torque
            )
            return min(max(tau, r.t_min), r.t_max)
        if not self.armed or self.control_mode != od.ControlMode.TORQUE_CONTROL:
            return 0.0
        tau_max = self.current_limit * self.conv.torque_constant
        tau = min(max(self.input_torque, -tau_max), tau_max)
        if abs(self.motor_velocity) > self.velocity_limit and tau * self.motor_velocity > 0:
            tau = 0.0  # ODrive torque-mode velocity limit
        return tau

    def advance(self, t: float, max_backlog: float | None = None) -> None:
        """Step the plant in fixed ``dt`` steps up to time ``t`` and queue due cyclic telemetry.

        ``max_backlog`` (real-time use): when further behind than this, skip instead of replaying.
        """
        with self._lock:
            if self._t_phys is None:
                self._t_phys = t
                for c in self._cyclic:
                    c[1] = t
            if max_backlog is not None and t - self._t_phys > max_backlog:  # paused process: skip
                self._t_phys = t - self.dt
            while self._t_phys + self.dt <= t + 1e-9:
                self._t_phys += self.dt
                self.applied_torque = self._motor_torque()
                self.meas = self.plant.step(self.conv.joint_torque(self.applied_torque), self.dt)
                self.time += self.dt
                self.stats.physics_steps += 1
            for c in self._cyclic:
                if t >= c[1]:
                    self._queue(self.telemetry_frame(c[2]), t)
                    c[1] += 1.0 / c[0]
                    if c[1] < t:
                        c[1] = t + 1.0 / c[0]

    def _queue(self, frame: Frame, t: float) -> None:
        if self.silent:
            self.stats.frames_suppressed += 1
            return
        if self.cfg.loss_probability and self._rng.random() < self.cfg.loss_probability:
            self.stats.frames_lost += 1
            return
        self._out.append((t + self.cfg.latency, frame))

    def pop_due(self, t: float) -> list[Frame]:
        """Remove and return the queued frames due at time ``t`` (lock-step use without a bus)."""
        out = []
        with self._lock:
            while self._out and self._out[0][0] <= t:
                out.append(self._out.popleft()[1])
        return out

    # ---- bus I/O --------------------------------------------------------------------------------------
    def flush(self, t: float) -> None:
        import can

        for f in self.pop_due(t):
            if self.silent:
                self.stats.frames_suppressed += 1
                continue
            try:
                self.bus.send(can.Message(arbitration_id=f.arbitration_id, data=f.data, is_extended_id=False))
                self.stats.frames_tx += 1
            except Exception:  # a real drive does not crash when the bus is busy
                self.stats.send_errors += 1

    def poll(self, timeout: float = 0.0) -> None:
        """Receive pending frames (waiting up to ``timeout`` for the first), advance, transmit."""
        msg = self.bus.recv(timeout)
        while msg is not None:
            if not msg.is_error_frame:
                self.handle(
                    Frame(
                        msg.arbitration_id, bytes(msg.data), msg.is_remote_frame, msg.is_extended_id, msg.dlc
                    ),
                    self.clock(),
                )
            msg = self.bus.recv(0.0)
        now = self.clock()
        self.advance(now, max_backlog=0.05)
        self.flush(now)

    def start(self) -> None:
        """Run the emulator on a background thread in real time."""
        if self.bus is None:
            raise ParameterError("DriveEmulator.start() needs a python-can bus")
        self._stop.clear()
        self._thread = threading.Thread(target=self._run, name="drive_emulator", daemon=True)
        self._thread.start()

    def stop(self, timeout: float = 2.0) -> None:
        self._stop.set()
        if self._thread is not None and self._thread is not threading.current_thread():
            self._thread.join(timeout)

    def _run(self) -> None:
        while not self._stop.is_set():
            now = self.clock()
            nxt = (self._t_phys if self._t_phys is not None else now) + self.dt
            if self._out:
                nxt = min(nxt, self._out[0][0])
            self.poll(max(0.0, min(nxt - now, 0.01)))


def plant_from_preset(preset: str = "abb_m19s"):
    """A project plant (:class:`friction_ros.core.plant.servo.GearheadServoPlant`) for the emulator.

    The preset's plant is switched to torque actuation (the emulated drive closes the current loop,
    so the plant's command is the joint torque). Returns ``(plant, conversion)`` where the
    :class:`JointConversion` matches the preset's gear ratio and torque constant, i.e. what the
    drive_interface node must be configured with to get the plant's joint values back.
    """
    from friction_ros.core.presets import make_plant

    plant = make_plant(preset, actuation="torque")
    p = plant.params
    return plant, JointConversion(gear_ratio=p.ratio, torque_constant=p.torque_constant)
