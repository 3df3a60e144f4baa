"""MIT mini-cheetah CAN codec (bgkatz/motorcontrol, CubeMars AK "MIT mode", T-motor).

Pure: no rclpy, no bus I/O. Command (host -> motor, id = motor CAN id, DLC 8), big-endian bit fields
``p16 v12 kp12 kd12 t12``; reply (motor -> host, id = master id, DLC 6 or 8)
``id8 p16 v12 t12 [temperature8 error8]``. Scaling is linear over per-motor ranges
(:class:`MitRanges`, parameters because they are firmware/model specific), values are clamped to
the range first and then truncated (``int``), exactly like ``float_to_uint`` in the firmware.
Position in rad, velocity in rad/s, torque in N*m (output side of the motor's own gearbox).
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from typing import NamedTuple

from friction_ros.core.can.frame import Frame, SafeDecoder
from friction_ros.core.validation import ParameterError, check_int, check_real

ENTER_MOTOR_MODE = b"\xff\xff\xff\xff\xff\xff\xff\xfc"
EXIT_MOTOR_MODE = b"\xff\xff\xff\xff\xff\xff\xff\xfd"
SET_ZERO = b"\xff\xff\xff\xff\xff\xff\xff\xfe"
SPECIAL = {ENTER_MOTOR_MODE: "enter", EXIT_MOTOR_MODE: "exit", SET_ZERO: "zero"}

ERROR_CODES = {
    0: "none",
    1: "over-temperature",
    2: "over-current",
    3: "over-voltage",
    4: "under-voltage",
    5: "encoder fault",
    6: "phase-current unbalance",
}


def float_to_uint(x: float, lo: float, hi: float, bits: int) -> int:
    """Clamp ``x`` to [lo, hi] and map it to an unsigned ``bits``-bit integer (truncating)."""
    if x != x:  # NaN -> refuse at the caller; here map to the low end defensively
        x = lo
    x = lo if x < lo else hi if x > hi else x
    return int((x - lo) * ((1 << bits) - 1) / (hi - lo))


def uint_to_float(u: int, lo: float, hi: float, bits: int) -> float:
    return u * (hi - lo) / ((1 << bits) - 1) + lo


@dataclass(frozen=True)
class MitRanges:
    """Per-motor scaling ranges (defaults: the common mini-cheetah / AK80-9 values)."""

    p_min: float = -12.5
    p_max: float = 12.5
    v_min: float = -65.0
    v_max: float = 65.0
    kp_min: float = 0.0
    kp_max: float = 500.0
    kd_min: float = 0.0
    kd_max: float = 5.0
    t_min: float = -18.0
    t_max: float = 18.0

    def __post_init__(self):
        for key in ("p", "v", "kp", "kd", "t"):
            lo = check_real(f"mit.{key}_min", getattr(self, f"{key}_min"))
            hi = check_real(f"mit.{key}_max", getattr(self, f"{key}_max"))
            if not hi > lo:
                raise ParameterError(
                    f"mit.{key}_max = {hi:g} is out of range: must be > mit.{key}_min = {lo:g}"
                )

    def as_dict(self) -> dict[str, float]:
        return asdict(self)


class MitCommand(NamedTuple):
    motor_id: int
    position: float
    velocity: float
    kp: float
    kd: float
    torque: float


class MitReply(NamedTuple):
    motor_id: int
    position: float  # rad
    velocity: float  # rad/s
    torque: float  # N*m
    temperature: float = math.nan  # degC (8-byte replies only)
    error: int = 0


class MitSpecial(NamedTuple):
    motor_id: int
    kind: str  # "enter", "exit" or "zero"


class MitCodec:
    """Encode/decode MIT frames for one motor id with one set of ranges."""

    def __init__(self, motor_id: int, ranges: MitRanges | None = None, master_id: int = 0):
        self.motor_id = check_int("mit.motor_id", motor_id, 0, 0x7FF)
        self.master_id = check_int("mit.master_id", master_id, 0, 0x7FF)
        if self.motor_id == self.master_id:
            raise ParameterError(
                f"mit.motor_id = {motor_id} equals mit.master_id: replies and commands would share an id"
            )
        self.r = ranges or MitRanges()

    # ---- host -> motor
    def encode_command(
        self,
        position: float = 0.0,
        velocity: float = 0.0,
        kp: float = 0.0,
        kd: float = 0.0,
        torque: float = 0.0,
    ) -> Frame:
        """Pack a command; values outside the ranges are clamped. NaN/inf raise ParameterError."""
        for name, v in (
            ("position", position),
            ("velocity", velocity),
            ("kp", kp),
            ("kd", kd),
            ("torque", torque),
        ):
            if not math.isfinite(v):
                raise ParameterError(f"mit command {name} = {v} is not finite: must be a finite number")
        r = self.r
        p = float_to_uint(position, r.p_min, r.p_max, 16)
        v = float_to_uint(velocity, r.v_min, r.v_max, 12)
        kp_i = float_to_uint(kp, r.kp_min, r.kp_max, 12)
        kd_i = float_to_uint(kd, r.kd_min, r.kd_max, 12)
        t = float_to_uint(torque, r.t_min, r.t_max, 12)
        data = bytes(
            (
                p >> 8,
                p & 0xFF,
                v >> 4,
                ((v & 0xF) << 4) | (kp_i >> 8),
                kp_i & 0xFF,
                kd_i >> 4,
                ((kd_i & 0xF) << 4) | (t >> 8),
                t & 0xFF,
            )
        )
        return Frame(self.motor_id, data)

    def encode_enter(self) -> Frame:
        return Frame(self.motor_id, ENTER_MOTOR_MODE)

    def encode_exit(self) -> Frame:
        return Frame(self.motor_id, EXIT_MOTOR_MODE)

    def encode_zero(self) -> Frame:
        return Frame(self.motor_id, SET_ZERO)

    def decode_command(self, data: bytes) -> MitCommand | MitSpecial:
        """Decode an 8-byte command payload (emulator side)."""
        data = bytes(data)
        if data in SPECIAL:
            return MitSpecial(self.motor_id, SPECIAL[data])
        r = self.r
        p = (data[0] << 8) | data[1]
        v = (data[2] << 4) | (data[3] >> 4)
        kp = ((data[3] & 0xF) << 8) | data[4]
        kd = (data[5] << 4) | (data[6] >> 4)
        t = ((data[6] & 0xF) << 8) | data[7]
        return MitCommand(
            self.motor_id,
            uint_to_float(p, r.p_min, r.p_max, 16),
            uint_to_float(v, r.v_min, r.v_max, 12),
            uint_to_float(kp, r.kp_min, r.kp_max, 12),
            uint_to_float(kd, r.kd_min, r.kd_max, 12),
            uint_to_float(t, r.t_min, r.t_max, 12),
        )

    # ---- motor -> host
    def encode_reply(
        self,
        position: float,
        velocity: float,
        torque: float,
        temperature: float | None = None,
        error: int = 0,
    ) -> Frame:
        """Reply frame; DLC 6 (bgkatz) or 8 when ``temperature`` is given (CubeMars: + temperature, error)."""
        r = self.r
        p = float_to_uint(position, r.p_min, r.p_max, 16)
        v = float_to_uint(velocity, r.v_min, r.v_max, 12)
        t = float_to_uint(torque, r.t_min, r.t_max, 12)
        data = bytes((self.motor_id & 0xFF, p >> 8, p & 0xFF, v >> 4, ((v & 0xF) << 4) | (t >> 8), t & 0xFF))
        if temperature is not None:
            temp = 0 if not math.isfinite(temperature) else max(0, min(255, int(temperature)))
            data += bytes((temp, error & 0xFF))
        return Frame(self.master_id, data)

    def decode_reply(self, data: bytes) -> MitReply:
        r = self.r
        p = (data[1] << 8) | data[2]
        v = (data[3] << 4) | (data[4] >> 4)
        t = ((data[4] & 0xF) << 8) | data[5]
        temp = float(data[6]) if len(data) >= 8 else math.nan
        err = data[7] if len(data) >= 8 else 0
        return MitReply(
            data[0],
            uint_to_float(p, r.p_min, r.p_max, 16),
            uint_to_float(v, r.v_min, r.v_max, 12),
            uint_to_float(t, r.t_min, r.t_max, 12),
            temp,
            err,
        )


class MitDecoder(SafeDecoder):
    """Decode MIT frames for one motor; never raises; counts decoded/ignored/rejected.

    ``role="host"``: replies on the master id whose first byte is our motor id.
    ``role="drive"``: commands and special frames on the motor id. ``"any"``: both.
    """

    def __init__(self, codec: MitCodec, role: str = "host"):
        if role not in ("host", "drive", "any"):
            raise ParameterError(
                f"mit decoder role = {role!r} is not allowed: must be one of host, drive, any"
            )
        self.codec = codec
        self.role = role
        super().__init__()

    def _decode(self, arb_id, data, is_remote, is_extended, is_error):
        st = self.stats
        c = self.codec
        if is_error or is_extended or is_remote:
            st.ignored += 1
            return None
        n = len(data)
        if arb_id == c.master_id and self.role != "drive":
            if n == 0 or data[0] != (c.motor_id & 0xFF):
                st.ignored += 1  # reply of another motor (or empty frame on the master id)
                return None
            if n not in (6, 8):
                self._reject(f"mit reply of motor {c.motor_id}: length {n} is invalid: must be 6 or 8 bytes")
                return None
            st.decoded += 1
            return c.decode_reply(data)
        if arb_id == c.motor_id and self.role != "host":
            if n != 8:
                self._reject(f"mit command to motor {c.motor_id}: length {n} is invalid: must be 8 bytes")
                return None
            st.decoded += 1
            return c.decode_command(data)
        st.ignored += 1
        return None
