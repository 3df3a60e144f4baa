"""A drive protocol defined outside the package: registered, then driven end to end.

The toy protocol has two frames: a command (host -> drive, id 0x200 + node: float32 motor torque,
mode byte 0 = disabled, 1 = torque control) and a telemetry frame (drive -> host, id 0x280 + node:
float16 position, velocity, torque, state byte, error byte). It goes through the real DriveAxis,
CanBusLink (filters, start-up frames) and the DriveEmulator on a python-can ``virtual`` bus, in lock
step on a simulated clock.
"""

from __future__ import annotations

import struct
import uuid
from importlib import metadata

import can
import pytest
from can_support import StandInPlant

from friction_ros.core.can import protocol
from friction_ros.core.can.axis import DriveAxis
from friction_ros.core.can.axis_config import AxisConfig
from friction_ros.core.can.emulator import DriveEmulator, EmulatorConfig
from friction_ros.core.can.faults import FAULT_DRIVE_ERROR, FAULT_TELEMETRY_STALE
from friction_ros.core.can.frame import Frame, SafeDecoder
from friction_ros.core.can.joint import JointConversion
from friction_ros.core.can.protocol import (
    DriveProtocol,
    DriveTelemetry,
    EmulatedDriveProtocol,
    drive_protocol,
    protocol_names,
    register_drive_protocol,
)
from friction_ros.core.can.telemetry_gate import MOTION
from friction_ros.core.validation import ParameterError, check_int
from friction_ros.nodes.can_bus import CanBusLink

CMD, TEL = 0x200, 0x280
_CMD = struct.Struct("<fB")
_TEL = struct.Struct("<eeeBB")
DT = 0.002


class ToyDecoder(SafeDecoder):
    def __init__(self, arb_id: int, fmt: struct.Struct):
        super().__init__()
        self.arb_id, self.fmt = arb_id, fmt

    def _decode(self, arb_id, data, is_remote, is_extended, is_error):
        if arb_id != self.arb_id or is_remote or is_extended or is_error:
            self.stats.ignored += 1
            return None
        if len(data) != self.fmt.size:
            self._reject(f"toy frame 0x{arb_id:X}: length {len(data)} is invalid: must be {self.fmt.size}")
            return None
        self.stats.decoded += 1
        return self.fmt.unpack(bytes(data))


class ToyProtocol(DriveProtocol):
    def __init__(self, cfg):
        super().__init__(cfg)
        self.decoder = ToyDecoder(TEL + cfg.node_id, _TEL)

    @classmethod
    def check_config(cls, cfg) -> None:
        check_int("node_id", cfg.node_id, 0, 0x7F)

    def decode(self, arb_id, data, is_remote, is_extended, is_error):
        m = self.decoder.decode(arb_id, data, is_remote, is_extended, is_error)
        if m is None:
            return None
        return DriveTelemetry(position=m[0], velocity=m[1], torque=m[2], state=m[3], error=m[4])

    def receive_filters(self):
        return [{"can_id": TEL + self.cfg.node_id, "can_mask": 0x7FF, "extended": False}]

    def gated_ids(self):
        return {TEL + self.cfg.node_id: MOTION}

    def closed_loop(self, state):
        return state == 1

    def error_text(self, code):
        return {7: "toy overheated"}.get(code, "")

    def _cmd(self, torque, mode):
        return Frame(CMD + self.cfg.node_id, _CMD.pack(torque, mode))

    @property
    def effort_source(self):
        return "torque_estimate"

    def startup_frames(self):
        return [self._cmd(0.0, 0)]

    def enable_frames(self):
        return [self._cmd(0.0, 1)]

    def disable_frames(self):
        return [self._cmd(0.0, 0)]

    def torque_frame(self, motor_torque):
        return self._cmd(motor_torque, 1)


class ToyDrive(EmulatedDriveProtocol):
    def __init__(self, drive):
        super().__init__(drive)
        self.decoder = ToyDecoder(CMD + drive.cfg.node_id, _CMD)
        self.mode, self.torque = 0, 0.0

    def cyclic(self):
        return [(self.drive.cfg.encoder_rate_hz, "telemetry")]

    def telemetry_frame(self, key):
        d = self.drive
        data = _TEL.pack(d.motor_position, d.motor_velocity, d.applied_torque, int(self.armed), d.axis_error)
        return Frame(TEL + d.cfg.node_id, data)

    def handle(self, msg, t):
        self.torque, self.mode = msg
        if self.mode == 1 and not self.drive.axis_error:
            self.drive.stats.commands += 1
        return []

    @property
    def armed(self):
        return self.mode == 1 and not self.drive.axis_error

    def motor_torque(self):
        return self.torque if self.armed else 0.0

    def fault(self):
        self.mode = 0


ToyProtocol.emulated = ToyDrive


@pytest.fixture
def toy(monkeypatch):
    """Register the toy protocol for this test only (the registry is restored afterwards)."""
    monkeypatch.setattr(protocol, "_registered", dict(protocol._registered))
    register_drive_protocol("toy", ToyProtocol)
    return "toy"


class Logger:
    def error(self, *a, **k):
        raise AssertionError(a)

    warning = error


class Rig:
    """DriveAxis + CanBusLink (host) and DriveEmulator (drive) on one virtual bus, lock step."""

    def __init__(self, **axis):
        channel = f"toy_{uuid.uuid4().hex[:8]}"
        conv = JointConversion(gear_ratio=2.0, torque_constant=0.1)
        self.now = 100.0
        self.emu_bus = can.Bus(interface="virtual", channel=channel)
        cfg = EmulatorConfig(protocol="toy", node_id=3, conversion=conv, encoder_rate_hz=500.0)
        self.emu = DriveEmulator(self.emu_bus, StandInPlant(), cfg, clock=lambda: self.now)
        self.emu.rx_log = []
        self.axis = DriveAxis(
            AxisConfig(protocol="toy", node_id=3, conversion=conv, telemetry_period=DT, **axis)
        )
        self.link = CanBusLink(
            "virtual", channel, 1_000_000, [self.axis], lambda a, d: self.axis, 5, 1.0, Logger()
        )
        self.results, self.times = [], []

    def run(self, seconds: float, torque: float | None = None) -> None:
        for _ in range(round(seconds / DT)):
            self.now += DT
            self.emu.poll(0.0)  # the host's frames of the previous period, plant step, telemetry
            self.link.receive(self.now)
            if torque is not None:
                self.axis.set_command(torque, self.now)
            r = self.axis.cycle(self.now)
            assert self.link.send(r.frames)
            self.results.append(r)
            self.times.append(self.now)

    def sent(self):
        return [_CMD.unpack(f.data) for _, f in self.emu.rx_log]

    def close(self):
        self.link.close()
        self.emu_bus.shutdown()


def test_registry_lists_the_toy_and_refuses_unknown_names(toy):
    assert protocol_names()[:2] == ("odrive_cansimple", "mit") and "toy" in protocol_names()
    assert drive_protocol("toy") is ToyProtocol
    with pytest.raises(ParameterError) as e:
        AxisConfig(protocol="toi")
    assert (
        str(e.value) == "protocol = 'toi' is not allowed: must be one of odrive_cansimple, mit, cia402, toy"
    )
    with pytest.raises(ParameterError, match=r"must be one of odrive_cansimple, mit, cia402, toy$"):
        drive_protocol("toi")
    with pytest.raises(ParameterError, match=r"node_id = 200 is out of range"):
        AxisConfig(protocol="toy", node_id=200)  # the protocol's own id check
    with pytest.raises(TypeError):
        register_drive_protocol("bad", dict)
    # every list of protocol names comes from the registry: node parameter, emulator options
    from friction_ros.nodes import drive_emulator, drive_interface

    field = dict(drive_interface.parameter_schema().fields())["protocol"]
    assert "toy" in field.choices and field.range_text() == "one of odrive_cansimple, mit, cia402, toy"
    assert "{odrive_cansimple,mit,cia402,toy}" in drive_emulator.build_parser().format_help()
    assert drive_emulator.build_parser().parse_args(["--protocol", "toy"]).protocol == "toy"


def test_entry_point_protocols_load_on_first_use(monkeypatch):
    monkeypatch.setattr(protocol, "_registered", {})
    monkeypatch.setattr(protocol, "_entry_points_loaded", False)
    eps = [
        metadata.EntryPoint("toy_ep", f"{__name__}:ToyProtocol", protocol.ENTRY_POINT_GROUP),
        metadata.EntryPoint("broken", f"{__name__}:NoSuchClass", protocol.ENTRY_POINT_GROUP),
    ]
    monkeypatch.setattr(metadata, "entry_points", lambda group: [e for e in eps if e.group == group])
    assert protocol_names() == ("odrive_cansimple", "mit", "cia402", "toy_ep", "broken")
    assert drive_protocol("toy_ep") is ToyProtocol
    with pytest.raises(ParameterError, match=r"protocol = 'broken' cannot be loaded from .*NoSuchClass"):
        drive_protocol("broken")


def test_toy_protocol_drives_the_emulated_axis_and_faults_to_the_safe_state(toy):
    rig = Rig(telemetry_timeout=0.02, command_timeout=1.0)
    try:
        rig.run(0.02)
        assert rig.sent()[0] == (0.0, 0)  # start-up frame, before anything else
        assert rig.axis.telemetry.encoder_time is not None and not rig.emu.armed
        rig.axis.request_enable()
        rig.run(0.3, torque=0.3)  # joint 0.3 N*m = motor 0.15 N*m through gear ratio 2
        assert rig.emu.armed and rig.axis.enabled and rig.results[-1].flags == 0
        assert rig.emu.applied_torque == pytest.approx(0.15, rel=1e-6)
        assert rig.emu.meas.effort == pytest.approx(0.3, rel=1e-6)  # the plant's joint torque
        sample = rig.results[-1].sample
        assert sample.velocity > 0.5 and sample.effort == pytest.approx(0.3, rel=2e-3)
        assert sample.position == pytest.approx(rig.emu.meas.position, abs=0.02)
        assert rig.axis.counters.heartbeat_frames > 100  # state reports: the closed-loop check ran

        n = len(rig.results)
        rig.emu.set_silent()  # the drive stops transmitting: stale telemetry
        rig.run(0.1, torque=0.3)
        stale = next(i for i, r in enumerate(rig.results) if r.flags & FAULT_TELEMETRY_STALE)
        last = rig.axis.telemetry.encoder_time  # the newest frame before the silence
        assert rig.times[stale - 1] - last <= 0.02 < rig.times[stale] - last  # the first period past it
        assert not rig.axis.enabled and rig.axis.latched & FAULT_TELEMETRY_STALE
        assert stale > n and all(r.joint_torque_command == 0.0 for r in rig.results[stale:])
        assert rig.sent()[-1] == (0.0, 0) and not rig.emu.armed and rig.emu.applied_torque == 0.0

        rig.emu.set_silent(False)
        rig.axis.request_enable()
        rig.run(0.1, torque=0.3)
        assert rig.axis.enabled and rig.emu.armed
        n = len(rig.results)
        rig.emu.inject_axis_error(7)  # a drive fault: reported in the telemetry frame
        rig.run(0.05, torque=0.3)
        assert rig.axis.latched & FAULT_DRIVE_ERROR and rig.axis.telemetry.axis_error == 7
        assert rig.axis.fault_reason == "drive reports error 0x7 (toy overheated)" and not rig.axis.enabled
        assert rig.results[-1].joint_torque_command == 0.0 and rig.sent()[-1] == (0.0, 0)
        assert sum(1 for r in rig.results[n:] for f in r.frames if f.data == _CMD.pack(0.0, 0)) == 1
    finally:
        rig.close()
