"""ODrive CANSimple as a :class:`~friction_ros.core.can.protocol.DriveProtocol` (host and drive side).

Wire codec: :mod:`friction_ros.core.can.odrive`. Host: enable = Clear_Errors, Set_Limits,
Set_Controller_Mode (torque, passthrough), Set_Input_Torque 0, Set_Axis_State CLOSED_LOOP_CONTROL;
disable = Set_Input_Torque 0, Set_Axis_State IDLE; quick stop = Estop. Telemetry: cyclic
Get_Encoder_Estimates, Get_Iq / Get_Torques (or RTR requests every period), Heartbeat (state, error),
Get_Error, Get_Bus_Voltage_Current.
"""

from __future__ import annotations

import math

from friction_ros.core.can import odrive as od
from friction_ros.core.can.frame import Frame
from friction_ros.core.can.protocol import (
    CURRENT_PAIR,
    MOTION_PAIR,
    DriveProtocol,
    DriveTelemetry,
    EmulatedDriveProtocol,
    register_drive_protocol,
)
from friction_ros.core.can.telemetry_gate import EFFORT, MOTION
from friction_ros.core.validation import check_int

POSITION_TURNS = 2.0**24  # float32 turns: beyond this a position no longer resolves one turn


class OdriveProtocol(DriveProtocol):
    motion_scale = od.TWO_PI

    def __init__(self, cfg):
        super().__init__(cfg)
        self.node_id = n = cfg.node_id
        self.decoder = od.OdriveDecoder([n], role="host")
        self._effort_cmd = od.Cmd.GET_IQ if cfg.effort_source == "current" else od.Cmd.GET_TORQUES

    @classmethod
    def check_config(cls, cfg) -> None:
        check_int("node_id", cfg.node_id, 0, od.NODE_ID_MAX)

    @classmethod
    def position_range(cls, cfg) -> tuple[float, float]:
        return POSITION_TURNS * od.TWO_PI, 0.0

    def decode(self, arb_id, data, is_remote, is_extended, is_error):
        m = self.decoder.decode(arb_id, data, is_remote, is_extended, is_error)
        if m is None:
            return None
        if isinstance(m, od.EncoderEstimates):
            return DriveTelemetry(position=m.position, velocity=m.velocity)
        if isinstance(m, od.Iq):
            return DriveTelemetry(current=m.measured, current_setpoint=m.setpoint)
        if isinstance(m, od.Torques):
            return DriveTelemetry(torque=m.estimate, torque_target=m.target)
        if isinstance(m, od.Heartbeat):
            return DriveTelemetry(error=m.axis_error, state=m.axis_state)
        if isinstance(m, od.BusVoltageCurrent):
            return DriveTelemetry(bus_voltage=m.voltage)
        if isinstance(m, od.DriveError):
            return DriveTelemetry(error=m.active_errors)
        return DriveTelemetry()

    def receive_filters(self) -> list[dict]:
        return [od.kernel_filter(self.node_id)]

    def gated_ids(self) -> dict[int, str]:
        gated = {od.Cmd.GET_ENCODER_ESTIMATES: MOTION, od.Cmd.GET_IQ: EFFORT, od.Cmd.GET_TORQUES: EFFORT}
        return {(self.node_id << 5) | c: ch for c, ch in gated.items()}

    def float_pairs(self) -> dict[int, int]:
        n = self.node_id << 5
        return {n | od.Cmd.GET_ENCODER_ESTIMATES: MOTION_PAIR, n | od.Cmd.GET_IQ: CURRENT_PAIR}

    def route_key(self, arb_id: int, data: bytes) -> int:
        return arb_id >> 5

    def closed_loop(self, state: int) -> bool:
        return state == od.AxisState.CLOSED_LOOP_CONTROL

    def state_name(self, state: int) -> str:
        return od.AxisState(state).name if state in od.AxisState._value2member_map_ else str(state)

    def enable_frames(self) -> list[Frame]:
        n, cfg = self.node_id, self.cfg
        motor_vel_limit = abs(cfg.conversion.motor_velocity(cfg.velocity_limit))
        return [
            od.encode_clear_errors(n),
            od.encode_set_limits(n, motor_vel_limit, cfg.current_limit),
            od.encode_set_controller_mode(n, od.ControlMode.TORQUE_CONTROL, od.InputMode.PASSTHROUGH),
            od.encode_set_input_torque(n, 0.0),
            od.encode_set_axis_state(n, od.AxisState.CLOSED_LOOP_CONTROL),
        ]

    def disable_frames(self) -> list[Frame]:
        n = self.node_id
        return [od.encode_set_input_torque(n, 0.0), od.encode_set_axis_state(n, od.AxisState.IDLE)]

    def quick_stop_frames(self) -> list[Frame]:
        return [od.encode_estop(self.node_id)]

    def torque_frame(self, motor_torque: float) -> Frame:
        return od.encode_set_input_torque(self.node_id, motor_torque)

    def poll_frames(self, enabled: bool) -> tuple[Frame, ...]:
        if not self.cfg.request_telemetry:
            return ()
        n = self.node_id
        return (od.encode_rtr(n, od.Cmd.GET_ENCODER_ESTIMATES), od.encode_rtr(n, self._effort_cmd))


class OdriveEmulatedDrive(EmulatedDriveProtocol):
    """An ODrive axis: Set_Axis_State, Set_Controller_Mode, Set_Input_Torque, Set_Limits,
    Clear_Errors, Estop and RTR requests; only torque control moves the plant, with the ODrive's
    torque-mode velocity limit."""

    def __init__(self, drive):
        super().__init__(drive)
        cfg = drive.cfg
        self.decoder = od.OdriveDecoder([cfg.node_id], role="drive")
        self.axis_state = od.AxisState.IDLE
        self.control_mode = od.ControlMode.TORQUE_CONTROL
        self.input_mode = od.InputMode.PASSTHROUGH
        self.input_torque = 0.0
        self.current_limit = cfg.current_limit  # the drive's own limit [A] until Set_Limits
        self.velocity_limit = math.inf  # motor [rad/s]

    @classmethod
    def check_config(cls, cfg) -> None:
        check_int("emulator.node_id", cfg.node_id, 0, od.NODE_ID_MAX)

    def cyclic(self):
        c = self.drive.cfg
        return [
            (c.heartbeat_rate_hz, od.Cmd.HEARTBEAT),
            (c.encoder_rate_hz, od.Cmd.GET_ENCODER_ESTIMATES),
            (c.iq_rate_hz, od.Cmd.GET_IQ),
            (c.torques_rate_hz, od.Cmd.GET_TORQUES),
            (c.bus_voltage_rate_hz, od.Cmd.GET_BUS_VOLTAGE_CURRENT),
        ]

    def telemetry_frame(self, cmd: int) -> Frame:
        d = self.drive
        n, kt = d.cfg.node_id, d.conv.torque_constant
        if cmd == od.Cmd.GET_ENCODER_ESTIMATES:
            return od.encode_encoder_estimates(n, d.motor_position, d.motor_velocity)
        if cmd == od.Cmd.GET_IQ:
            return od.encode_iq(n, d.applied_torque / kt, d.motor_torque_measured / kt)
        if cmd == od.Cmd.GET_TORQUES:
            return od.encode_torques(n, d.applied_torque, d.motor_torque_measured)
        if cmd == od.Cmd.HEARTBEAT:
            return od.encode_heartbeat(n, d.axis_error, self.axis_state)
        if cmd == od.Cmd.GET_BUS_VOLTAGE_CURRENT:
            return od.encode_bus_voltage_current(n, d.cfg.bus_voltage, 0.0)
        return od.encode_error(n, d.axis_error, 0)

    def handle(self, msg, t: float) -> list[Frame]:
        d = self.drive
        if isinstance(msg, od.SetInputTorque):
            self.input_torque = msg.torque
            d.stats.commands += 1
        elif isinstance(msg, od.RtrRequest):
            return [self.telemetry_frame(msg.cmd)]
        elif isinstance(msg, od.SetAxisState):
            if msg.state == od.AxisState.CLOSED_LOOP_CONTROL:
                if not d.axis_error:
                    self.axis_state = od.AxisState.CLOSED_LOOP_CONTROL
            elif msg.state == od.AxisState.IDLE:
                self.axis_state = od.AxisState.IDLE
                self.input_torque = 0.0
        elif isinstance(msg, od.SetControllerMode):
            self.control_mode, self.input_mode = msg.control_mode, msg.input_mode
        elif isinstance(msg, od.SetLimits):
            self.velocity_limit, self.current_limit = msg.velocity_limit, msg.current_limit
        elif isinstance(msg, od.ClearErrors):
            d.axis_error = 0
        elif isinstance(msg, od.Estop):
            d.axis_error |= od.ERROR_ESTOP_REQUESTED
            self.axis_state = od.AxisState.IDLE
        return []

    @property
    def armed(self) -> bool:
        return self.axis_state == od.AxisState.CLOSED_LOOP_CONTROL

    def motor_torque(self) -> float:
        if not self.armed or self.control_mode != od.ControlMode.TORQUE_CONTROL:
            return 0.0
        d = self.drive
        tau_max = self.current_limit * d.conv.torque_constant
        tau = min(max(self.input_torque, -tau_max), tau_max)
        v = d.motor_velocity
        if abs(v) > self.velocity_limit and tau * v > 0:
            tau = 0.0  # ODrive torque-mode velocity limit
        return tau

    def fault(self) -> None:
        self.axis_state = od.AxisState.IDLE


OdriveProtocol.emulated = OdriveEmulatedDrive
register_drive_protocol("odrive_cansimple", OdriveProtocol)
