"""ODrive CANSimple codec (firmware 0.6.x layout, 0.5.x compatible for the supported messages).

Pure: no rclpy, no bus I/O. Arbitration id = ``node_id << 5 | cmd_id`` (11-bit), little-endian
payloads, IEEE-754 float32. The wire carries turns, turns/s, N*m (motor side) and A; every function
here takes and returns SI values (rad, rad/s, N*m, A): the turns <-> rad conversion happens here and
nowhere else. Layouts: ``anchors.md`` section 2.1 and ``odrive-cansimple.dbc`` (the test oracle).
"""

from __future__ import annotations

import math
import struct
from enum import IntEnum
from typing import NamedTuple

from friction_ros.core.can.frame import Frame, SafeDecoder
from friction_ros.core.validation import ParameterError, check_choice, check_int

TWO_PI = 2.0 * math.pi
NODE_ID_MAX = 0x3F
CMD_MASK = 0x1F
NODE_MASK = 0x7E0  # kernel filter mask selecting one node's 32 command ids


class Cmd(IntEnum):
    """CANSimple command ids (low 5 bits of the arbitration id)."""

    HEARTBEAT = 0x001
    ESTOP = 0x002
    GET_ERROR = 0x003
    SET_AXIS_STATE = 0x007
    GET_ENCODER_ESTIMATES = 0x009
    SET_CONTROLLER_MODE = 0x00B
    SET_INPUT_TORQUE = 0x00E
    SET_LIMITS = 0x00F
    GET_IQ = 0x014
    GET_BUS_VOLTAGE_CURRENT = 0x017
    CLEAR_ERRORS = 0x018
    GET_TORQUES = 0x01C


class AxisState(IntEnum):
    UNDEFINED = 0
    IDLE = 1
    STARTUP_SEQUENCE = 2
    FULL_CALIBRATION_SEQUENCE = 3
    MOTOR_CALIBRATION = 4
    ENCODER_INDEX_SEARCH = 6
    ENCODER_OFFSET_CALIBRATION = 7
    CLOSED_LOOP_CONTROL = 8


class ControlMode(IntEnum):
    VOLTAGE_CONTROL = 0
    TORQUE_CONTROL = 1
    VELOCITY_CONTROL = 2
    POSITION_CONTROL = 3


class InputMode(IntEnum):
    INACTIVE = 0
    PASSTHROUGH = 1


# ODrive 0.6 ODriveError bits used by the emulator and the diagnostics.
ERROR_CURRENT_LIMIT_VIOLATION = 0x1000
ERROR_WATCHDOG_TIMER_EXPIRED = 0x1000000
ERROR_ESTOP_REQUESTED = 0x2000000

TELEMETRY_CMDS = frozenset(
    {
        Cmd.HEARTBEAT,
        Cmd.GET_ERROR,
        Cmd.GET_ENCODER_ESTIMATES,
        Cmd.GET_IQ,
        Cmd.GET_BUS_VOLTAGE_CURRENT,
        Cmd.GET_TORQUES,
    }
)
COMMAND_CMDS = frozenset(
    {
        Cmd.ESTOP,
        Cmd.SET_AXIS_STATE,
        Cmd.SET_CONTROLLER_MODE,
        Cmd.SET_INPUT_TORQUE,
        Cmd.SET_LIMITS,
        Cmd.CLEAR_ERRORS,
    }
)

_F2 = struct.Struct("<ff")
_F1 = struct.Struct("<f")
_U2 = struct.Struct("<II")
_U1 = struct.Struct("<I")
_HB = struct.Struct("<IBBBx")


# ---- decoded messages (SI units; motor side) -------------------------------------------------------
class Heartbeat(NamedTuple):
    node_id: int
    axis_error: int
    axis_state: int
    procedure_result: int = 0
    trajectory_done: bool = False


class EncoderEstimates(NamedTuple):
    node_id: int
    position: float  # rad, motor
    velocity: float  # rad/s, motor


class Iq(NamedTuple):
    node_id: int
    setpoint: float  # A
    measured: float  # A


class Torques(NamedTuple):
    node_id: int
    target: float  # N*m, motor
    estimate: float  # N*m, motor


class BusVoltageCurrent(NamedTuple):
    node_id: int
    voltage: float  # V
    current: float  # A


class DriveError(NamedTuple):
    node_id: int
    active_errors: int
    disarm_reason: int


class SetAxisState(NamedTuple):
    node_id: int
    state: int


class SetControllerMode(NamedTuple):
    node_id: int
    control_mode: int
    input_mode: int


class SetInputTorque(NamedTuple):
    node_id: int
    torque: float  # N*m, motor


class SetLimits(NamedTuple):
    node_id: int
    velocity_limit: float  # rad/s, motor
    current_limit: float  # A


class ClearErrors(NamedTuple):
    node_id: int
    identify: int


class Estop(NamedTuple):
    node_id: int


class RtrRequest(NamedTuple):
    """A remote (RTR) frame asking the drive to send one telemetry message now."""

    node_id: int
    cmd: int


# ---- ids --------------------------------------------------------------------------------------------
def arbitration_id(node_id: int, cmd: int) -> int:
    """``node_id << 5 | cmd``; raises ParameterError for a node id outside 0..63 or cmd outside 0..31."""
    if not 0 <= node_id <= NODE_ID_MAX:
        raise ParameterError(f"odrive node_id = {node_id} is out of range: must be an integer 0..63")
    if not 0 <= cmd <= CMD_MASK:
        raise ParameterError(f"odrive cmd_id = {cmd} is out of range: must be an integer 0..31")
    return (node_id << 5) | cmd


def split_id(arb_id: int) -> tuple[int, int]:
    """Return ``(node_id, cmd_id)`` of an 11-bit arbitration id."""
    return (arb_id >> 5) & NODE_ID_MAX, arb_id & CMD_MASK


def kernel_filter(node_id: int) -> dict:
    """python-can ``can_filters`` entry that passes exactly the 32 ids of ``node_id``."""
    return {"can_id": arbitration_id(node_id, 0), "can_mask": NODE_MASK, "extended": False}


# ---- host -> drive encoders --------------------------------------------------------------------------
def encode_set_axis_state(node_id: int, state: int) -> Frame:
    return Frame(arbitration_id(node_id, Cmd.SET_AXIS_STATE), _U2.pack(int(state), 0))


def encode_set_controller_mode(
    node_id: int, control_mode: int = ControlMode.TORQUE_CONTROL, input_mode: int = InputMode.PASSTHROUGH
) -> Frame:
    return Frame(
        arbitration_id(node_id, Cmd.SET_CONTROLLER_MODE), _U2.pack(int(control_mode), int(input_mode))
    )


def encode_set_input_torque(node_id: int, torque: float) -> Frame:
    """Motor-side torque command [N*m]; refuses NaN/inf (ParameterError)."""
    if not math.isfinite(torque):
        raise ParameterError(
            f"Set_Input_Torque torque = {torque} is not finite: must be a finite number [N*m]"
        )
    return Frame((node_id << 5) | Cmd.SET_INPUT_TORQUE, _F2.pack(torque, 0.0))


def encode_set_limits(node_id: int, velocity_limit: float, current_limit: float) -> Frame:
    """Velocity limit [rad/s, motor] (sent as turns/s) and current limit [A]."""
    for name, v in (("velocity_limit", velocity_limit), ("current_limit", current_limit)):
        if not (math.isfinite(v) and v >= 0):
            raise ParameterError(f"Set_Limits {name} = {v} is out of range: must be a finite number >= 0")
    return Frame(arbitration_id(node_id, Cmd.SET_LIMITS), _F2.pack(velocity_limit / TWO_PI, current_limit))


def encode_clear_errors(node_id: int, identify: int = 0) -> Frame:
    return Frame(arbitration_id(node_id, Cmd.CLEAR_ERRORS), bytes([identify & 0xFF]))


def encode_estop(node_id: int) -> Frame:
    return Frame(arbitration_id(node_id, Cmd.ESTOP), b"")


def encode_rtr(node_id: int, cmd: int) -> Frame:
    """Remote request for one telemetry message (DLC 8, empty payload)."""
    if cmd not in TELEMETRY_CMDS:
        allowed = ", ".join(f"0x{c:03X} {c.name}" for c in sorted(TELEMETRY_CMDS))
        raise ParameterError(
            f"RTR request cmd = 0x{cmd:03X} is not a telemetry message: must be one of {allowed}"
        )
    return Frame(arbitration_id(node_id, cmd), b"", is_remote=True, dlc=8)


# ---- drive -> host encoders (emulator) ---------------------------------------------------------------
def encode_heartbeat(
    node_id: int, axis_error: int, axis_state: int, procedure_result: int = 0, trajectory_done: bool = False
) -> Frame:
    data = _HB.pack(
        axis_error & 0xFFFFFFFF, axis_state & 0xFF, procedure_result & 0xFF, 1 if trajectory_done else 0
    )
    return Frame((node_id << 5) | Cmd.HEARTBEAT, data)


def encode_encoder_estimates(node_id: int, position: float, velocity: float) -> Frame:
    """Motor position [rad] and velocity [rad/s], sent as turns and turns/s."""
    return Frame((node_id << 5) | Cmd.GET_ENCODER_ESTIMATES, _F2.pack(position / TWO_PI, velocity / TWO_PI))


def encode_iq(node_id: int, setpoint: float, measured: float) -> Frame:
    return Frame((node_id << 5) | Cmd.GET_IQ, _F2.pack(setpoint, measured))


def encode_torques(node_id: int, target: float, estimate: float) -> Frame:
    return Frame((node_id << 5) | Cmd.GET_TORQUES, _F2.pack(target, estimate))


def encode_bus_voltage_current(node_id: int, voltage: float, current: float) -> Frame:
    return Frame((node_id << 5) | Cmd.GET_BUS_VOLTAGE_CURRENT, _F2.pack(voltage, current))


def encode_error(node_id: int, active_errors: int, disarm_reason: int = 0) -> Frame:
    return Frame(
        (node_id << 5) | Cmd.GET_ERROR, _U2.pack(active_errors & 0xFFFFFFFF, disarm_reason & 0xFFFFFFFF)
    )


# ---- decoder -----------------------------------------------------------------------------------------
_MIN_LEN = {
    Cmd.HEARTBEAT: 5,
    Cmd.GET_ERROR: 8,
    Cmd.GET_ENCODER_ESTIMATES: 8,
    Cmd.GET_IQ: 8,
    Cmd.GET_TORQUES: 8,
    Cmd.GET_BUS_VOLTAGE_CURRENT: 4,
    Cmd.ESTOP: 0,
    Cmd.SET_AXIS_STATE: 4,
    Cmd.SET_CONTROLLER_MODE: 8,
    Cmd.SET_INPUT_TORQUE: 4,
    Cmd.SET_LIMITS: 8,
    Cmd.CLEAR_ERRORS: 0,
}

ROLES = ("host", "drive", "any")


class OdriveDecoder(SafeDecoder):
    """Decode CANSimple frames for a set of node ids; never raises on arbitrary input.

    ``role="host"`` decodes drive telemetry (what a controller PC needs) and ignores commands;
    ``role="drive"`` decodes commands and RTR requests (what the emulator needs); ``"any"`` both.
    Every call is counted in :attr:`stats` as decoded, ignored or rejected.
    """

    def __init__(self, node_ids, role: str = "host"):
        check_choice("odrive decoder role", role, ROLES)
        self.node_ids = frozenset(check_int("odrive node_id", n, 0, NODE_ID_MAX) for n in node_ids)
        self.role = role
        super().__init__()
        want = set()
        if role in ("host", "any"):
            want |= TELEMETRY_CMDS
        if role in ("drive", "any"):
            want |= COMMAND_CMDS
        self._wanted = frozenset(int(c) for c in want)
        self._rtr = role in ("drive", "any")

    def _decode(self, arb_id, data, is_remote, is_extended, is_error):
        st = self.stats
        if is_error or is_extended or arb_id > 0x7FF or arb_id < 0:
            st.ignored += 1
            return None
        node = arb_id >> 5
        cmd = arb_id & CMD_MASK
        if node not in self.node_ids:
            st.ignored += 1
            return None
        if is_remote:
            if self._rtr and cmd in TELEMETRY_CMDS:
                st.decoded += 1
                return RtrRequest(node, cmd)
            st.ignored += 1
            return None
        if cmd not in self._wanted:
            st.ignored += 1
            return None
        n = len(data)
        if n > 8 or n < _MIN_LEN[cmd]:
            self._reject(
                f"node {node} cmd 0x{cmd:03X}: length {n} is invalid: must be {_MIN_LEN[cmd]}..8 bytes"
            )
            return None
        if cmd == Cmd.GET_ENCODER_ESTIMATES:
            p, v = _F2.unpack_from(data)
            if not (math.isfinite(p) and math.isfinite(v)):
                self._reject(f"node {node} encoder estimate is not finite ({p}, {v})")
                return None
            st.decoded += 1
            return EncoderEstimates(node, p * TWO_PI, v * TWO_PI)
        if cmd == Cmd.GET_IQ or cmd == Cmd.GET_TORQUES or cmd == Cmd.GET_BUS_VOLTAGE_CURRENT:
            if cmd == Cmd.GET_BUS_VOLTAGE_CURRENT and n < 8:  # 0.5.x Get_Vbus_Voltage: one float
                a, b = _F1.unpack_from(data)[0], math.nan
                ok = math.isfinite(a)
            else:
                a, b = _F2.unpack_from(data)
                ok = math.isfinite(a) and math.isfinite(b)
            if not ok:
                self._reject(f"node {node} cmd 0x{cmd:03X} value is not finite ({a}, {b})")
                return None
            st.decoded += 1
            if cmd == Cmd.GET_IQ:
                return Iq(node, a, b)
            if cmd == Cmd.GET_TORQUES:
                return Torques(node, a, b)
            return BusVoltageCurrent(node, a, b)
        if cmd == Cmd.HEARTBEAT:
            err = _U1.unpack_from(data)[0]
            state = data[4]
            proc = data[5] if n > 5 else 0
            done = bool(data[6] & 1) if n > 6 else False
            st.decoded += 1
            return Heartbeat(node, err, state, proc, done)
        if cmd == Cmd.GET_ERROR:
            a, b = _U2.unpack_from(data)
            st.decoded += 1
            return DriveError(node, a, b)
        if cmd == Cmd.SET_INPUT_TORQUE:
            t = _F1.unpack_from(data)[0]
            if not math.isfinite(t):
                self._reject(f"node {node} Set_Input_Torque = {t} is not finite")
                return None
            st.decoded += 1
            return SetInputTorque(node, t)
        if cmd == Cmd.SET_AXIS_STATE:
            st.decoded += 1
            return SetAxisState(node, _U1.unpack_from(data)[0])
        if cmd == Cmd.SET_CONTROLLER_MODE:
            a, b = _U2.unpack_from(data)
            st.decoded += 1
            return SetControllerMode(node, a, b)
        if cmd == Cmd.SET_LIMITS:
            a, b = _F2.unpack_from(data)
            if not (math.isfinite(a) and math.isfinite(b)):
                self._reject(f"node {node} Set_Limits value is not finite ({a}, {b})")
                return None
            st.decoded += 1
            return SetLimits(node, a * TWO_PI, b)
        if cmd == Cmd.CLEAR_ERRORS:
            st.decoded += 1
            return ClearErrors(node, data[0] if n else 0)
        if cmd == Cmd.ESTOP:
            st.decoded += 1
            return Estop(node)
        st.ignored += 1  # unreachable: _wanted only holds handled commands
        return None
