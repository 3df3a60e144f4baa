"""CiA 402 as a :class:`~friction_ros.core.can.protocol.DriveProtocol` (host side), registered as ``cia402``.

One :class:`~.master.Cia402Master` per axis does the CANopen work (start-up by SDO, state machine,
EMCY, heartbeat consumer) and reports motor-side SI (its gear ratio is 1: DriveAxis' JointConversion
takes the axis to the joint). Per period, in DriveAxis' order: ``torque_frame`` (enabled) or
``poll_frames`` (disabled) give RPDO1 with the controlword of the state machine walk; then
``cycle_frames`` gives the start-up frames and, from the last CiA 402 axis of the period, the one
SYNC for all of them. Reports: TPDO1 -> torque + state (the CiA 402 state; closed loop = OPERATION
ENABLED) + error (the master's latched CiA error code: EMCY, heartbeat 0x8130, ...); TPDO2 ->
position (of the TPDO1 before it) + velocity + current. Units come from the axis' ``cia402.*``
parameters (or :func:`set_axis_parameters`), else the EDS, else the drive (SDO reads of 0x608F,
0x6076, 0x6075).

Limits: one CiA 402 bus per process (the SYNC group counts every CiA 402 axis); a disable or
shutdown sends quick stop and disable voltage each followed by a SYNC of its own.
"""

from __future__ import annotations

import dataclasses
import time

from friction_ros.core.can.cia402 import frames as fr
from friction_ros.core.can.cia402 import objects as ob
from friction_ros.core.can.cia402.config import Cia402Config
from friction_ros.core.can.cia402.emulated import Cia402EmulatedDrive
from friction_ros.core.can.cia402.master import Cia402Master
from friction_ros.core.can.cia402.state_machine import (
    CW_DISABLE_VOLTAGE,
    CW_QUICK_STOP,
    STATE_NAMES,
    State,
)
from friction_ros.core.can.frame import Frame, SafeDecoder
from friction_ros.core.can.protocol import EFFORT_REPORT, MOTION_REPORT, DriveProtocol, DriveTelemetry
from friction_ros.core.can.telemetry_gate import EFFORT, MOTION
from friction_ros.core.validation import check_int

_params: dict[int, Cia402Config] = {}


def set_axis_parameters(node_id: int, **params) -> Cia402Config:
    """CiA 402 parameters (see :class:`~.config.Cia402Config`: eds_path, counts_per_rev, rated_torque,
    rated_current, max_torque, heartbeat_ms, timeouts) of the axis with ``node_id``, used when its
    protocol is built. gear ratio, lead, direction and zero offset belong to the axis' JointConversion."""
    cfg = Cia402Config(node_id=node_id, **params)
    _params[node_id] = cfg
    return cfg


class _SyncGroup:
    """One SYNC per period for the CiA 402 axes of the process: sent with the frames of the axis that
    completes the period, i.e. once every axis that took part in the previous period has been called
    (an axis that is gone costs one period without SYNC; a new one joins from its second period).

    ``missing`` counts the previous period's axes not yet called in this one (no set comparison per
    call); the two sets are swapped, not rebuilt, at each new period."""

    def __init__(self):
        self.t: float | None = None
        self.prev: set[int] = set()
        self.cur: set[int] = set()
        self.missing = 0
        self.sent = False

    def due(self, t: float, key: int, operational: bool) -> bool:
        if t != self.t:
            prev = self.prev
            prev.clear()
            self.prev, self.cur, self.t, self.sent = self.cur, prev, t, False
            prev.add(key)
            self.missing = len(self.prev) - (key in self.prev)
        elif key not in self.cur:
            self.cur.add(key)
            if key in self.prev:
                self.missing -= 1
        if self.sent or self.missing or not operational:
            return False
        self.sent = True
        return True


SYNC_GROUP = _SyncGroup()
_SYNC = (fr.SYNC_FRAME,)


class Cia402Decoder(SafeDecoder):
    """Frames of one drive -> the master; returns the DriveTelemetry of TPDO1 / TPDO2, else None."""

    def __init__(self, protocol: Cia402Protocol):
        super().__init__()
        self.p = protocol
        self.m = protocol.master

    def _decode(self, arb_id, data, is_remote, is_extended, is_error):
        m = self.m
        if is_remote or is_extended or is_error or arb_id not in m.cob_ids:
            self.stats.ignored += 1
            return None
        if (
            arb_id == m.cob_tpdo1
            and len(data) < fr.TPDO1.size
            or arb_id == m.cob_tpdo2
            and len(data) < fr.TPDO2.size
        ):
            self._reject(f"CiA 402 PDO 0x{arb_id:03X}: length {len(data)} is too short")
            return None
        if m.scaling is None and arb_id in (m.cob_tpdo1, m.cob_tpdo2):
            self.stats.ignored += 1  # PDOs before our start-up finished (units not known yet)
            return None
        self.stats.decoded += 1
        m.handle(arb_id, data, m.now)
        if arb_id == m.cob_tpdo1:
            return DriveTelemetry(None, None, m._tau, None, None, None, None, m.fault_code, m._state_code)
        if arb_id == m.cob_tpdo2 and m.tpdo1_count:
            return DriveTelemetry(m._pos, m._vel, None, None, m._cur)
        if arb_id == m.cob_emcy and m.fault_code:
            return DriveTelemetry(error=m.fault_code)
        return None


class Cia402Protocol(DriveProtocol):
    def __init__(self, cfg):
        super().__init__(cfg)
        own = _params.get(cfg.node_id) or Cia402Config(node_id=cfg.node_id, **dict(cfg.cia402))
        if not own.max_torque:  # the axis' torque limit is the drive's max torque 0x6072 (written at
            # start): a command within the node's limit never trips the drive's excess-torque fault
            own = dataclasses.replace(own, max_torque=abs(cfg.conversion.motor_torque(cfg.torque_limit)))
        # motor side: the axis' JointConversion does gear ratio, lead, direction and zero offset
        mcfg = dataclasses.replace(own, gear_ratio=1.0, lead=0.0, direction=1, zero_offset=0.0)
        self.master = Cia402Master(mcfg)
        self.master.control_period = cfg.telemetry_period
        self.decoder = Cia402Decoder(self)
        self.t = time.monotonic()
        self._key = id(self)  # in the SYNC group
        self.torque_frame = self.master.torque_rpdo  # DriveAxis' per-period call, one level less

    @property
    def t(self) -> float:
        """Time of the current period, the master's ``now`` (receive times are not passed to decode)."""
        return self.master.now

    @t.setter
    def t(self, t: float) -> None:
        self.master.now = t

    @classmethod
    def check_config(cls, cfg) -> None:
        check_int("node_id", cfg.node_id, ob.NODE_ID_MIN, ob.NODE_ID_MAX)

    def decode(self, arb_id, data, is_remote, is_extended, is_error):
        return self.decoder.decode(arb_id, data, is_remote, is_extended, is_error)

    def receive_filters(self) -> list[dict]:
        return [{"can_id": c, "can_mask": 0x7FF, "extended": False} for c in self.master.cob_ids]

    def gated_ids(self) -> dict[int, str]:
        return {self.master.cob_tpdo2: MOTION, self.master.cob_tpdo1: EFFORT}

    def fast_reports(self):
        m = self.master
        return {m.cob_tpdo1: (EFFORT_REPORT, m.effort_report), m.cob_tpdo2: (MOTION_REPORT, m.motion_report)}

    def route_key(self, arb_id: int, data: bytes) -> int | None:
        return arb_id & 0x7F if arb_id >= 0x100 else None  # not NMT (0x000), SYNC (0x080)

    def closed_loop(self, state: int) -> bool:
        return state == State.OPERATION_ENABLED

    def state_name(self, state: int) -> str:
        try:
            return STATE_NAMES[State(state)]
        except ValueError:
            return str(state)

    def error_text(self, code: int) -> str:
        return ob.emcy_text(code)

    def startup_frames(self) -> list[Frame]:
        return self.master.start(self.t)

    def enable_frames(self) -> list[Frame]:
        self.master.enable(self.t)
        return []  # the controlword walk runs in the following periods' RPDOs

    def disable_frames(self) -> list[Frame]:
        m = self.master
        m.disable(self.t)
        if m.phase != "operational":
            return []
        rpdo = m.cob_rpdo1
        return [
            Frame(rpdo, fr.RPDO1.pack(CW_QUICK_STOP, 0)),
            fr.SYNC_FRAME,
            Frame(rpdo, fr.RPDO1.pack(CW_DISABLE_VOLTAGE, 0)),
            fr.SYNC_FRAME,
        ]

    def torque_frame(self, motor_torque: float) -> Frame:
        return self.master.torque_rpdo(motor_torque)  # bound straight to the master in __init__

    def poll_frames(self, enabled: bool) -> tuple[Frame, ...]:
        if enabled or self.master.phase != "operational":
            return ()
        self.master.torque_permille = 0
        return (self.master.rpdo_frame(),)

    def cycle_frames(self, t: float) -> list[Frame] | tuple[Frame, ...]:
        m = self.master
        m.now = t
        if m.phase == "operational":  # every period: the state machine walk and the SYNC, no list
            m.hold(t)
            return _SYNC if SYNC_GROUP.due(t, self._key, True) else ()
        out = m.step(t)
        if SYNC_GROUP.due(t, self._key, m.phase == "operational"):
            out.append(fr.SYNC_FRAME)
        return out


Cia402Protocol.emulated = Cia402EmulatedDrive
