"""MIT mode as a :class:`~friction_ros.core.can.protocol.DriveProtocol` (host and drive side).

Wire codec: :mod:`friction_ros.core.can.mit`. Torque control is a command with kp = kd = 0 and the
feed-forward torque; the motor answers every frame with one reply (position, velocity, torque,
error), so a disabled axis polls with a zero command each period. Enable = zero command + enter
motor mode; disable = zero command + exit motor mode. No state report: DriveAxis shows enabled/disabled.
"""

from __future__ import annotations

from friction_ros.core.can import mit as mitc
from friction_ros.core.can.frame import Frame
from friction_ros.core.can.protocol import (
    DriveProtocol,
    DriveTelemetry,
    EmulatedDriveProtocol,
    register_drive_protocol,
)
from friction_ros.core.can.telemetry_gate import MOTION
from friction_ros.core.validation import ParameterError, check_int

POSITION_STEPS = (1 << 16) - 1  # 16-bit position field
_NONE: tuple = ()


class MitProtocol(DriveProtocol):
    reports_state = False

    def __init__(self, cfg):
        super().__init__(cfg)
        self.codec = mitc.MitCodec(cfg.node_id, cfg.mit_ranges, cfg.mit_master_id)
        self.decoder = mitc.MitDecoder(self.codec, role="host")
        self._zero = self.codec.encode_command()

    @classmethod
    def check_config(cls, cfg) -> None:
        check_int("node_id", cfg.node_id, 0, 0x7FF)
        check_int("mit_master_id", cfg.mit_master_id, 0, 0x7FF)
        if cfg.node_id == cfg.mit_master_id:
            raise ParameterError(
                f"node_id = {cfg.node_id} equals mit_master_id: must differ (replies go to the master id)"
            )

    @classmethod
    def position_range(cls, cfg) -> tuple[float, float]:
        r = cfg.mit_ranges
        return max(abs(r.p_min), abs(r.p_max)), (r.p_max - r.p_min) / POSITION_STEPS

    @property
    def effort_source(self) -> str:
        return "torque_estimate"  # every reply carries the torque with the position

    def decode(self, arb_id, data, is_remote, is_extended, is_error):
        m = self.decoder.decode(arb_id, data, is_remote, is_extended, is_error)
        if m is None:
            return None
        # positional (hot path, every period): position, velocity, torque, torque_target, current, ...
        _, p, v, tau, _, err = m
        return DriveTelemetry(p, v, tau, None, tau / self.cfg.conversion.torque_constant, None, None, err)

    def receive_filters(self) -> list[dict]:
        return [{"can_id": self.codec.master_id, "can_mask": 0x7FF, "extended": False}]

    def gated_ids(self) -> dict[int, str]:
        return {self.codec.master_id: MOTION}

    def route_key(self, arb_id: int, data: bytes) -> int | None:
        return data[0] if data else None

    @property
    def own_route_key(self) -> int:
        return self.cfg.node_id & 0xFF

    def enable_frames(self) -> list[Frame]:
        return [self._zero, self.codec.encode_enter()]

    def disable_frames(self) -> list[Frame]:
        return [self._zero, self.codec.encode_exit()]

    def torque_frame(self, motor_torque: float) -> Frame:
        return self.codec.encode_command(torque=motor_torque)

    def poll_frames(self, enabled: bool) -> list[Frame]:
        return _NONE if enabled else [self._zero]  # the drive only reports when it receives a frame


class MitEmulatedDrive(EmulatedDriveProtocol):
    """An MIT motor: enter / exit motor mode, set zero, and ``tau = kp (p_des - p) + kd (v_des - v)
    + t_ff`` clamped to the torque range; one reply per received frame."""

    def __init__(self, drive):
        super().__init__(drive)
        cfg = drive.cfg
        self.codec = mitc.MitCodec(cfg.node_id, cfg.mit_ranges, cfg.mit_master_id)
        self.decoder = mitc.MitDecoder(self.codec, role="drive")
        self.motor_mode = False
        self.command = mitc.MitCommand(cfg.node_id, 0.0, 0.0, 0.0, 0.0, 0.0)
        self.zero_offset = 0.0  # motor rad

    @classmethod
    def check_config(cls, cfg) -> None:
        check_int("emulator.node_id", cfg.node_id, 0, 0x7FF)

    @property
    def position_offset(self) -> float:
        return self.zero_offset

    def reply(self) -> Frame:
        d = self.drive
        return self.codec.encode_reply(
            d.motor_position, d.motor_velocity, d.motor_torque_measured, 25.0, d.axis_error & 0xFF
        )

    def telemetry_frame(self, key) -> Frame:
        return self.reply()

    def handle(self, msg, t: float) -> list[Frame]:
        if isinstance(msg, mitc.MitSpecial):
            if msg.kind == "enter":
                self.motor_mode = not self.drive.axis_error
            elif msg.kind == "exit":
                self.motor_mode = False
            else:
                self.zero_offset += self.drive.motor_position
        else:
            self.command = msg
            self.drive.stats.commands += 1
        return [self.reply()]

    @property
    def armed(self) -> bool:
        return self.motor_mode and not self.drive.axis_error

    def motor_torque(self) -> float:
        if not self.armed:
            return 0.0
        d, c, r = self.drive, self.command, self.drive.cfg.mit_ranges
        tau = c.kp * (c.position - d.motor_position) + c.kd * (c.velocity - d.motor_velocity) + c.torque
        return min(max(tau, r.t_min), r.t_max)

    def fault(self) -> None:
        self.motor_mode = False


MitProtocol.emulated = MitEmulatedDrive
register_drive_protocol("mit", MitProtocol)
