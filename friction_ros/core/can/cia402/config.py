"""Parameters of one CiA 402 axis on the master side, with their ranges and where units come from.

Units resolution, per quantity: the parameter when it is set (non-zero), else the EDS default
(``eds_path``), else the drive's own object read by SDO at start-up (0x608F counts per revolution,
0x6091 gear ratio, 0x6076 rated torque, 0x6075 rated current).

The automatic timeouts add ``JITTER_MARGIN`` (0.5 s) like the other drive protocols: scheduler pauses
of a loaded machine reach hundreds of ms; on a robot with a quiet CPU set a few periods instead.
"""

from __future__ import annotations

from dataclasses import dataclass

from friction_ros.core.can.axis_config import JITTER_MARGIN  # pauses of a shared machine, measured there
from friction_ros.core.can.cia402 import objects as ob
from friction_ros.core.validation import ParameterError, check_int, check_real


@dataclass(frozen=True)
class Cia402Config:
    node_id: int = 1
    counts_per_rev: int = 0  # encoder counts per motor revolution (0: EDS / drive)
    gear_ratio: float = 0.0  # motor rev per joint rev (0: EDS / drive 0x6091)
    lead: float = 0.0  # prismatic joint: travel per motor revolution [m/rev]; 0 = revolute
    direction: int = 1
    zero_offset: float = 0.0  # [rad or m]
    rated_torque: float = 0.0  # motor N*m (0: EDS / drive 0x6076)
    rated_current: float = 0.0  # A (0: EDS / drive 0x6075)
    max_torque: float = 0.0  # joint N*m (N if prismatic) written to 0x6072; 0 = keep the drive's
    heartbeat_ms: int = 100  # producer heartbeat time written to 0x1017
    heartbeat_timeout: float = 0.0  # [s] heartbeat consumer; 0 = 3 heartbeat periods + JITTER_MARGIN
    telemetry_timeout: float = 0.0  # [s] no TPDO1 this long = fault; 0 = 3 control periods + JITTER_MARGIN
    sdo_timeout: float = 0.1  # [s] per SDO request
    sdo_retries: int = 3
    state_timeout: float = 0.5  # [s] per CiA 402 state transition
    eds_path: str = ""

    def __post_init__(self):
        check_int("node_id", self.node_id, ob.NODE_ID_MIN, ob.NODE_ID_MAX)
        check_int("counts_per_rev", self.counts_per_rev, 0, 2**31 - 1)
        check_real("gear_ratio", self.gear_ratio, 0.0, unit="motor rev / joint rev")
        check_real("lead", self.lead, 0.0, unit="m/rev")
        check_real("rated_torque", self.rated_torque, 0.0, unit="N*m")
        check_real("rated_current", self.rated_current, 0.0, unit="A")
        check_real("max_torque", self.max_torque, 0.0, unit="N*m")
        check_int("heartbeat_ms", self.heartbeat_ms, 1, 65535)
        check_real("heartbeat_timeout", self.heartbeat_timeout, 0.0, 60.0, unit="s (0 = automatic)")
        check_real("telemetry_timeout", self.telemetry_timeout, 0.0, 60.0, unit="s (0 = automatic)")
        check_real("sdo_timeout", self.sdo_timeout, 0.0, 10.0, lo_open=True, unit="s")
        check_int("sdo_retries", self.sdo_retries, 0, 100)
        check_real("state_timeout", self.state_timeout, 0.0, 60.0, lo_open=True, unit="s")
        if self.direction not in (1, -1):
            raise ParameterError(f"direction = {self.direction!r} is not allowed: must be one of 1, -1")
        if self.lead > 0 and self.gear_ratio not in (0.0, 1.0):
            raise ParameterError(
                f"gear_ratio = {self.gear_ratio:g} with lead = {self.lead:g} [m/rev]: a prismatic axis takes "
                "the travel per motor turn (screw lead / gear ratio) as lead; leave gear_ratio at 0 or 1"
            )

    @property
    def consumer_timeout(self) -> float:
        """Heartbeat consumer time [s]: the parameter, or 3 producer periods + JITTER_MARGIN."""
        return self.heartbeat_timeout or 3e-3 * self.heartbeat_ms + JITTER_MARGIN

    def stale_after(self, control_period: float) -> float:
        """Stale-telemetry timeout [s]: the parameter, or 3 control periods + JITTER_MARGIN."""
        return self.telemetry_timeout or 3 * control_period + JITTER_MARGIN


def eds_defaults(path: str) -> dict[str, float]:
    """Unit-related defaults of an EDS: counts_per_rev, gear_ratio, rated_torque, rated_current.

    A missing object is left out; an EDS that does not load raises ParameterError naming the file.
    """
    import canopen

    try:
        od = canopen.import_od(path)
    except Exception as exc:
        raise ParameterError(f"eds_path = {path!r} does not load as an EDS: {exc}") from None

    def default(index: int, sub: int | None = None):
        try:
            obj = od[index] if sub is None else od[index][sub]
        except KeyError:
            return None
        return obj.default

    out: dict[str, float] = {}
    inc, revs = default(ob.OD_ENCODER_RESOLUTION, 1), default(ob.OD_ENCODER_RESOLUTION, 2)
    if inc and revs:
        out["counts_per_rev"] = inc // revs
    motor, shaft = default(ob.OD_GEAR_RATIO, 1), default(ob.OD_GEAR_RATIO, 2)
    if motor and shaft:
        out["gear_ratio"] = motor / shaft
    if default(ob.OD_RATED_TORQUE):
        out["rated_torque"] = default(ob.OD_RATED_TORQUE) / 1000.0
    if default(ob.OD_RATED_CURRENT):
        out["rated_current"] = default(ob.OD_RATED_CURRENT) / 1000.0
    return out
