"""Frame-level servo-drive emulator (any registered drive protocol) on a python-can bus.

A plant object (``step(command_torque, dt) -> measurement`` with joint ``position``, ``velocity``,
``effort`` attributes, e.g. ``friction_ros.core.plant.servo.GearheadServoPlant`` in torque mode) sits behind
a drive that answers the same frames a real one does:

* ODrive: Set_Axis_State (IDLE / CLOSED_LOOP_CONTROL), Set_Controller_Mode, Set_Input_Torque,
  Set_Limits, Clear_Errors, Estop, RTR requests of every telemetry message; cyclic Heartbeat,
  Get_Encoder_Estimates, Get_Iq, Get_Torques, Get_Bus_Voltage_Current at configurable rates.
  Only torque control mode moves the plant (other modes apply zero torque).
* MIT: enter / exit motor mode, set zero, command ``tau = kp (p_des - p) + kd (v_des - v) + t_ff``
  (clamped to the torque range) and one reply per received frame.

The drive's state machine and frames are the protocol's
:class:`~friction_ros.core.can.protocol.EmulatedDriveProtocol` (``DriveProtocol.emulated``); this
module owns the plant, time, the cyclic schedule and the faults. Faults for tests: latency of every
transmitted frame, random frame loss, going silent, an injected axis error (the axis drops to IDLE / leaves motor mode, as a real drive does).

The bus is only touched in :meth:`poll` / the background thread; :meth:`handle` and :meth:`advance`
are plain logic, so a test can run the emulator in lock step without threads.
"""

from __future__ import annotations

import collections
import random
import threading
import time
from dataclasses import dataclass, field

from friction_ros.core.can import mit as mitc
from friction_ros.core.can import odrive as od
from friction_ros.core.can.frame import Frame
from friction_ros.core.can.joint import JointConversion
from friction_ros.core.can.protocol import PROTOCOLS, EmulatedDriveProtocol, drive_protocol
from friction_ros.core.validation import ParameterError, check_choice, check_real


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
        drive = drive_protocol(self.protocol).emulated
        if drive is None:
            raise ParameterError(f"emulator.protocol = {self.protocol!r} has no emulated drive side")
        drive.check_config(self)
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
        # drive state (motor side); the protocol's state machine in self.drive
        self.axis_error = 0
        self.applied_torque = 0.0  # motor side [N*m]
        self.drive: EmulatedDriveProtocol = drive_protocol(cfg.protocol).emulated(self)
        self.decoder = self.drive.decoder
        self._cyclic = [[rate, 0.0, key] for rate, key in self.drive.cyclic() if rate > 0]

    # ---- faults -------------------------------------------------------------------------------------
    def set_silent(self, silent: bool = True) -> None:
        """Stop (or resume) transmitting anything, like a drive that lost power or its CAN link."""
        self.silent = silent

    def inject_axis_error(self, error: int = od.ERROR_CURRENT_LIMIT_VIOLATION) -> None:
        """Raise a drive error: the axis disarms (IDLE / leaves motor mode) and reports it."""
        with self._lock:
            self.axis_error |= int(error)
            self.drive.fault()

    # ---- motor-side measurements ----------------------------------------------------------------------
    @property
    def motor_position(self) -> float:
        return self.conv.motor_position(self.meas.position) - self.drive.position_offset

    @property
    def motor_velocity(self) -> float:
        return self.conv.motor_velocity(self.meas.velocity)

    @property
    def motor_torque_measured(self) -> float:
        return self.conv.motor_torque(self.meas.effort)

    @property
    def armed(self) -> bool:
        return self.drive.armed

    # ---- logic ----------------------------------------------------------------------------------------
    def telemetry_frame(self, key) -> Frame:
        """The telemetry frame ``key`` of the protocol (e.g. an ODrive command id) with the state now."""
        return self.drive.telemetry_frame(key)

    def handle(self, frame: Frame, t: float) -> None:
        """React to one received frame at time ``t``."""
        msg = self.decoder.decode_frame(frame)
        with self._lock:
            self.stats.frames_rx += 1
            if self.rx_log is not None:
                self.rx_log.append((t, frame))
            if msg is None:
                return
            for reply in self.drive.handle(msg, t):
                self._queue(reply, t)

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
                self.applied_torque = self.drive.motor_torque()
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
