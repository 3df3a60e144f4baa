"""Master (driver) side of one CiA 402 axis in cyclic synchronous torque mode: pure frame logic.

Start-up (CiA 301 boot-up, like ros2_canopen's ``canopen_402_driver``): NMT enter pre-operational,
SDO reads of the units the parameters leave open, SDO writes 0x6060 = 10 (cyclic synchronous
torque), 0x1017 heartbeat producer time, 0x6072 max torque, the PDO mappings of :mod:`.frames`
(RPDO1, TPDO1, TPDO2, all synchronous: transmission type 1), then NMT start.

Each control period ``frames(t)`` gives RPDO1 (controlword + target torque); the SYNC that makes
the drive apply it and answer with TPDO1/TPDO2 comes from one :class:`~.network.SyncProducer` per
bus. ``handle(cob_id, data, t)`` takes TPDOs, EMCY, heartbeat and SDO answers.

Faults latch (``fault`` holds one line of text) and make the axis quick stop, then disable
voltage: an EMCY (its error code text), the statusword fault bit, a missing heartbeat (consumer
time :attr:`Cia402Config.consumer_timeout`), the drive leaving OPERATIONAL, no TPDO1 for
``telemetry_timeout``, a state transition not done within ``state_timeout``, an SDO abort/timeout.
``enable()`` clears the latch and walks the drive to OPERATION ENABLED (fault reset first).

The cyclic path is hand-made for speed (the ``canopen`` library stays for start-up, EDS and the
conformance tests): :meth:`effort_report` / :meth:`motion_report` unpack TPDO1 / TPDO2 with pre-built
structs and the unit factors folded into four constants (``Cia402Scaling.factors``), allocate no
object per frame and are called directly by DriveAxis' fast path; :meth:`step` only supervises when
there is something to check. Measured reason (``bench/can_decode.py``: drive_interface's CAN work
per 1 kHz period, CPU us per axis, 1 / 3 axes): 17.4 / 16.6 through the general decoder (a report
object and a telemetry tuple per TPDO, supervision every period) -> 12.2 / 11.9; ODrive CANSimple
10.2 / 10.1 (its float fast path), MIT 13.5 / 13.4.
"""

from __future__ import annotations

from typing import NamedTuple

from friction_ros.core.can.cia402 import frames as fr
from friction_ros.core.can.cia402 import objects as ob
from friction_ros.core.can.cia402.config import Cia402Config, eds_defaults
from friction_ros.core.can.cia402.sdo_script import SdoScript, SdoStep
from friction_ros.core.can.cia402.state_machine import (
    CW_DISABLE_VOLTAGE,
    CW_ENABLE_OPERATION,
    STATE_NAMES,
    State,
    master_controlword,
    state_from_statusword,
)
from friction_ros.core.can.cia402.units import Cia402Scaling
from friction_ros.core.can.frame import Frame
from friction_ros.core.can.joint import JointConversion

_RPDO1 = fr.RPDO1.pack
_TPDO1 = fr.TPDO1.unpack_from
_TPDO2 = fr.TPDO2.unpack_from
_HALF, _MASK = 1 << 31, (1 << 32) - 1
_new_frame = tuple.__new__  # Frame(...) without NamedTuple.__new__'s defaults: a third of the cost
_ENABLED, _QUICK_STOP = State.OPERATION_ENABLED, State.QUICK_STOP_ACTIVE
_UNIT_OBJECTS = {  # parameter -> objects read from the drive when neither parameter nor EDS gives it
    "counts_per_rev": ((ob.OD_ENCODER_RESOLUTION, 1), (ob.OD_ENCODER_RESOLUTION, 2)),
    "gear_ratio": ((ob.OD_GEAR_RATIO, 1), (ob.OD_GEAR_RATIO, 2)),
    "rated_torque": ((ob.OD_RATED_TORQUE, 0),),
    "rated_current": ((ob.OD_RATED_CURRENT, 0),),
}


class Cia402Telemetry(NamedTuple):
    t: float  # receive time of the TPDO1
    position: float  # joint [rad or m]
    velocity: float  # joint [rad/s or m/s]
    torque: float  # joint [N*m or N] from 0x6077
    current: float  # motor [A] from 0x6078
    statusword: int
    state: State


def _pdo_steps(comm: int, mapping: int, cob: int, entries: tuple[int, ...]) -> list[SdoStep]:
    """CiA 301 7.5.2.36 mapping procedure: disable the PDO, clear, map, set count, enable."""
    return [
        SdoStep(comm, 1, cob | ob.PDO_COB_INVALID),
        SdoStep(comm, 2, ob.SYNC_TRANSMISSION, 1),
        SdoStep(mapping, 0, 0, 1),
        *(SdoStep(mapping, i + 1, e) for i, e in enumerate(entries)),
        SdoStep(mapping, 0, len(entries), 1),
        SdoStep(comm, 1, cob),
    ]


class Cia402Master:
    """One drive axis; not thread-safe (call from the bus thread only)."""

    def __init__(self, config: Cia402Config | None = None):
        self.cfg = cfg = config or Cia402Config()
        n = cfg.node_id
        self.node_id = n
        self.cob_tpdo1, self.cob_tpdo2 = ob.COB_TPDO1 + n, ob.COB_TPDO2 + n
        self.cob_rpdo1 = ob.COB_RPDO1 + n
        self.cob_emcy, self.cob_sdo_tx, self.cob_heartbeat = (
            ob.COB_EMCY + n,
            ob.COB_SDO_TX + n,
            ob.COB_HEARTBEAT + n,
        )
        self.cob_ids = (self.cob_tpdo1, self.cob_tpdo2, self.cob_emcy, self.cob_sdo_tx, self.cob_heartbeat)
        self.phase = "idle"  # idle -> units -> configure -> operational | failed
        self.units: dict[str, float] = {k: getattr(cfg, k) for k in _UNIT_OBJECTS if getattr(cfg, k)}
        if cfg.eds_path:
            for k, v in eds_defaults(cfg.eds_path).items():
                self.units.setdefault(k, v)
        self.scaling = None  # Cia402Scaling once the units are known
        self.sdo: SdoScript | None = None
        self.statusword = 0
        self.state = State.UNKNOWN
        self._state_code = int(State.UNKNOWN)
        self.now = 0.0  # time of the current period (the driver sets it; TPDOs are stamped with it)
        self.target = State.SWITCH_ON_DISABLED
        self.controlword = CW_DISABLE_VOLTAGE
        self.torque_permille = 0
        self.max_permille = 32767
        self.fault = ""  # latched fault text ("" = none)
        self.fault_code = 0  # its CiA error code: the EMCY's, 0x8130 heartbeat, 0x8100 stale, else 0x1000
        self._t_fault = 0.0
        self._fault_from_statusword = False  # an EMCY arriving just after replaces the text
        self.emcy_log: list[tuple[float, fr.EmcyMessage]] = []
        self.nmt_state: int | None = None  # from the heartbeat
        self._pos = 0.0
        self._tau = 0.0
        self._vel = 0.0
        self._cur = 0.0
        self._t_state = 0.0  # when the state last changed (or the target was set)
        self._t_heartbeat = 0.0
        self._t_tpdo1 = 0.0
        self._t_operational = 0.0
        self.tpdo1_count = 0
        self._counts = 0  # position actual unwrapped across int32 overflow (multi-turn joints)
        self._last_counts: int | None = None
        self._consumer_timeout = cfg.consumer_timeout
        self.control_period = 1e-3  # set by the network; sizes the automatic stale timeout

    @property
    def scaling(self) -> Cia402Scaling | None:
        return self._scaling

    @scaling.setter
    def scaling(self, sc: Cia402Scaling | None) -> None:
        self._scaling = sc
        self._k_pos, self._zero, self._k_tau, self._k_cur = sc.factors() if sc else (0.0,) * 4

    @property
    def control_period(self) -> float:
        return self._control_period

    @control_period.setter
    def control_period(self, period: float) -> None:
        self._control_period = period
        self._stale_after = self.cfg.stale_after(period)

    @property
    def telemetry(self) -> Cia402Telemetry | None:
        """The newest reports (None before the first TPDO1): TPDO1's and the newest TPDO2's."""
        if not self.tpdo1_count:
            return None
        return Cia402Telemetry(
            self._t_tpdo1, self._pos, self._vel, self._tau, self._cur, self.statusword, self.state
        )

    # ---- commands -------------------------------------------------------------------------------------
    def start(self, t: float) -> list[Frame]:
        """Begin the start-up; returns the NMT frame to send now."""
        steps = [SdoStep(*obj) for k, objs in _UNIT_OBJECTS.items() if k not in self.units for obj in objs]
        self.sdo = SdoScript(self.node_id, steps, self.cfg.sdo_timeout, self.cfg.sdo_retries)
        self.phase = "units"
        self._t_state = t
        return [fr.nmt(ob.NMT_PRE_OPERATIONAL, self.node_id)]

    def enable(self, t: float) -> None:
        """Clear a latched fault and walk the drive to OPERATION ENABLED (fault reset first)."""
        self.fault, self.fault_code = "", 0
        self._set_target(State.OPERATION_ENABLED, t)
        if self.phase == "operational":
            self._t_heartbeat = self._t_tpdo1 = max(self._t_tpdo1, t - self.stale_after / 2)

    def disable(self, t: float) -> None:
        self._set_target(State.SWITCH_ON_DISABLED, t)

    def quick_stop(self, t: float) -> None:
        self._set_target(State.QUICK_STOP_ACTIVE, t)

    def set_torque(self, joint_torque: float) -> None:
        """Joint torque [N*m or N] for the next RPDO, clamped to the configured max torque."""
        if self._scaling is None:
            return
        p = round(joint_torque / self._k_tau)  # Cia402Scaling.torque_permille, with the int16 and
        lo, hi = self._p_range  # max torque bounds in one clamp
        self.torque_permille = lo if p < lo else hi if p > hi else p

    @property
    def max_permille(self) -> int:
        """Max torque 0x6072 [per mille of the rated torque]; commands are clamped to it."""
        return self._max_permille

    @max_permille.setter
    def max_permille(self, m: int) -> None:
        self._max_permille = m
        self._p_range = (max(-m, fr.I16_MIN), min(m, fr.I16_MAX))

    @property
    def stale_after(self) -> float:
        return self._stale_after

    @property
    def enabled(self) -> bool:
        return self.state == State.OPERATION_ENABLED and not self.fault

    # ---- per period -------------------------------------------------------------------------------------
    def frames(self, t: float) -> list[Frame]:
        """Frames to send this period, before the SYNC: :meth:`step` and, once operational, the RPDO."""
        out = self.step(t)
        if self.phase == "operational":
            out.append(self.rpdo_frame())
        return out

    def step(self, t: float) -> list[Frame]:
        """Supervision and the state machine walk of one period; start-up frames (SDO, NMT) while
        configuring. The period's RPDO is :meth:`rpdo_frame` (separate for drivers that send the
        command themselves)."""
        if self.phase == "operational":
            self.hold(t)
            return []
        if self.phase in ("units", "configure"):
            return self._configure(t)
        return []

    def hold(self, t: float) -> None:
        """:meth:`step` once operational: supervise only when there is something to check or do
        (a state walk, a quick stop, a late TPDO1 or heartbeat), then the controlword of the walk."""
        state, target = self.state, self.target
        if (
            state != target
            or target == _QUICK_STOP
            or t - self._t_tpdo1 > self._stale_after
            or t - self._t_heartbeat > self._consumer_timeout
        ):
            self._supervise(t)
            state, target = self.state, self.target
        if state == target == _ENABLED:
            self.controlword = CW_ENABLE_OPERATION
        else:
            self.controlword = master_controlword(state, target, self.controlword)

    def rpdo_frame(self) -> Frame:
        """RPDO1: the controlword of this period and the target torque (zero unless OPERATION ENABLED
        is both the state and the target)."""
        on = self.state == _ENABLED and self.target == _ENABLED
        return Frame(self.cob_rpdo1, _RPDO1(self.controlword, self.torque_permille if on else 0))

    def torque_rpdo(self, joint_torque: float) -> Frame:
        """:meth:`set_torque` then :meth:`rpdo_frame` in one call (an enabled axis' every period):
        ``permille = clamp(round(tau / k_tau))``, RPDO1 = controlword | permille (0 unless enabled)."""
        if self._scaling is not None:
            p = round(joint_torque / self._k_tau)
            lo, hi = self._p_range
            self.torque_permille = p = lo if p < lo else hi if p > hi else p
        else:
            p = self.torque_permille
        if self.state != _ENABLED or self.target != _ENABLED:
            p = 0
        return _new_frame(Frame, (self.cob_rpdo1, _RPDO1(self.controlword, p), False, False, None))

    def exit_frames(self) -> list[list[Frame]]:
        """Frames of the last periods, one list per SYNC: quick stop, disable voltage, NMT pre-operational."""
        if self.phase != "operational":
            return []
        self.target = State.SWITCH_ON_DISABLED
        return [
            [Frame(self.cob_rpdo1, _RPDO1(0x02, 0))],
            [Frame(self.cob_rpdo1, _RPDO1(CW_DISABLE_VOLTAGE, 0))],
            [fr.nmt(ob.NMT_PRE_OPERATIONAL, self.node_id)],
        ]

    def effort_report(self, data: bytes) -> tuple[float, int, int] | None:
        """TPDO1 at :attr:`now`: statusword (state machine), torque, position (unwrapped across int32);
        returns (torque, state, fault code), or None (nothing done) when short or before the units."""
        if len(data) < 8 or self._scaling is None:
            return None
        sw, tq, pos = _TPDO1(data)
        t = self._t_tpdo1 = self.now
        self.tpdo1_count += 1
        if sw != self.statusword:
            self._on_statusword(sw, t)
        self._tau = tau = self._k_tau * tq
        last = self._last_counts
        self._counts = c = pos if last is None else self._counts + ((pos - last + _HALF) & _MASK) - _HALF
        self._last_counts = pos
        self._pos = self._k_pos * c - self._zero
        return tau, self._state_code, self.fault_code

    def motion_report(self, data: bytes) -> tuple[float, float, float] | None:
        """TPDO2: velocity, current; returns (position of the TPDO1 before, velocity, current), or
        None when short or before the units (nothing done) or before the first TPDO1."""
        if len(data) < 6 or self._scaling is None:
            return None
        vel, cur = _TPDO2(data)
        self._vel = v = self._k_pos * vel
        self._cur = i = self._k_cur * cur
        return (self._pos, v, i) if self.tpdo1_count else None

    def handle(self, cob: int, data: bytes, t: float) -> None:
        if cob == self.cob_tpdo1:
            self.now = t
            self.effort_report(data)
        elif cob == self.cob_tpdo2:
            self.motion_report(data)
        elif cob == self.cob_heartbeat:
            self._t_heartbeat = t
            state = data[0] & 0x7F if data else -1
            if (
                self.phase == "operational"
                and state != ob.NMT_OPERATIONAL
                and self.nmt_state == ob.NMT_OPERATIONAL
            ):
                name = ob.NMT_STATE_NAMES.get(state, f"0x{state:02X}")
                self._latch(f"drive node {self.node_id} left NMT OPERATIONAL (heartbeat reports {name})", t)
            self.nmt_state = state
        elif cob == self.cob_emcy:
            msg = fr.decode_emcy(data)
            self.emcy_log.append((t, msg))
            if msg.code & 0xFF00:
                self._latch(f"drive node {self.node_id} {msg.text}", t, msg.code, emcy=True)
        elif cob == self.cob_sdo_tx and self.sdo is not None:
            self.sdo.on_response(data)

    # ---- internals ---------------------------------------------------------------------------------------
    def _set_target(self, target: State, t: float) -> None:
        if target != self.target:
            self.target = target
            self._t_state = t

    def _latch(self, text: str, t: float, code: int = ob.ERROR_GENERIC, emcy: bool = False) -> None:
        if not self.fault or (emcy and self._fault_from_statusword and t - self._t_fault < 0.2):
            self.fault = text
            self.fault_code = code
            self._t_fault = t
            self._fault_from_statusword = False
        if self.target == State.OPERATION_ENABLED:
            self._set_target(
                State.QUICK_STOP_ACTIVE
                if self.state == State.OPERATION_ENABLED
                else State.SWITCH_ON_DISABLED,
                t,
            )
        self.torque_permille = 0

    def _on_statusword(self, sw: int, t: float) -> None:
        self.statusword = sw
        state = state_from_statusword(sw)
        if state != self.state:
            self.state, self._state_code = state, int(state)
            self._t_state = t
            if (
                state in (State.FAULT, State.FAULT_REACTION_ACTIVE)
                and self.target != State.SWITCH_ON_DISABLED
            ):
                if not self.fault:
                    self._latch(f"drive node {self.node_id} reports FAULT in the statusword (0x{sw:04X})", t)
                    self._fault_from_statusword = True
                elif self.target == State.OPERATION_ENABLED:
                    self._set_target(State.SWITCH_ON_DISABLED, t)

    def _supervise(self, t: float) -> None:
        cfg = self.cfg
        if t - self._t_heartbeat > self._consumer_timeout:
            self._t_heartbeat = t  # one report per missing episode
            self._latch(
                f"heartbeat of drive node {self.node_id} missing for more than {self._consumer_timeout * 1e3:.0f} ms",
                t,
                ob.ERROR_HEARTBEAT,
            )
        if t - self._t_tpdo1 > self._stale_after:
            self._t_tpdo1 = t
            self._latch(
                f"telemetry of drive node {self.node_id} stale: no TPDO1 for more than "
                f"{self._stale_after * 1e3:.0f} ms",
                t,
                ob.ERROR_COMMUNICATION,
            )
        if self.target == State.QUICK_STOP_ACTIVE and self.state == State.QUICK_STOP_ACTIVE:
            self._set_target(State.SWITCH_ON_DISABLED, t)
        elif self.state != self.target and t - self._t_state > cfg.state_timeout:
            if self.target == State.QUICK_STOP_ACTIVE:
                self._set_target(State.SWITCH_ON_DISABLED, t)
            elif self.target == State.OPERATION_ENABLED:
                self._latch(
                    f"drive node {self.node_id} did not reach OPERATION ENABLED: stayed in "
                    f"{STATE_NAMES[self.state]} for {cfg.state_timeout:g} s",
                    t,
                )
            else:
                self._t_state = t  # disable: keep commanding it

    def _configure(self, t: float) -> list[Frame]:
        sdo = self.sdo
        if sdo.error:
            self.phase = "failed"
            self.fault = sdo.error
            return []
        if sdo.done and self.phase == "units":
            self._resolve_units(sdo.values)
            self.phase = "configure"
            sdo.extend(self._configuration_steps())
        if sdo.done and self.phase == "configure":
            self.phase = "operational"
            self._t_heartbeat = self._t_tpdo1 = self._t_operational = self._t_state = t
            return [fr.nmt(ob.NMT_START, self.node_id)]
        f = sdo.poll(t)
        return [f] if f is not None else []

    def _resolve_units(self, values: dict[tuple[int, int], int]) -> None:
        u = self.units
        v = values.get
        if "counts_per_rev" not in u:
            u["counts_per_rev"] = v((ob.OD_ENCODER_RESOLUTION, 1), 0) // max(
                v((ob.OD_ENCODER_RESOLUTION, 2), 1), 1
            )
        if "gear_ratio" not in u:
            u["gear_ratio"] = v((ob.OD_GEAR_RATIO, 1), 1) / max(v((ob.OD_GEAR_RATIO, 2), 1), 1)
        if "rated_torque" not in u:
            u["rated_torque"] = v((ob.OD_RATED_TORQUE, 0), 0) / 1000.0
        if "rated_current" not in u:
            u["rated_current"] = v((ob.OD_RATED_CURRENT, 0), 0) / 1000.0
        cfg = self.cfg
        conv = JointConversion(
            gear_ratio=1.0 if cfg.lead > 0 else u["gear_ratio"],
            direction=cfg.direction,
            zero_offset=cfg.zero_offset,
            lead=cfg.lead,
        )
        self.scaling = Cia402Scaling(
            int(u["counts_per_rev"]), u["rated_torque"], u["rated_current"] or 1.0, conv
        )
        if cfg.max_torque:
            self.max_permille = min(abs(self.scaling.torque_permille(cfg.max_torque)), 65535)

    def _configuration_steps(self) -> list[SdoStep]:
        n, cfg = self.node_id, self.cfg
        steps = [
            SdoStep(ob.OD_MODES_OF_OPERATION, 0, ob.MODE_CYCLIC_SYNC_TORQUE, 1, True),
            SdoStep(ob.OD_HEARTBEAT_PRODUCER, 0, cfg.heartbeat_ms, 2),
        ]
        if cfg.max_torque:
            steps.append(SdoStep(ob.OD_MAX_TORQUE, 0, self.max_permille, 2))
        steps += _pdo_steps(ob.OD_RPDO1_COMM, ob.OD_RPDO1_MAP, ob.COB_RPDO1 + n, fr.RPDO1_MAP)
        steps += _pdo_steps(ob.OD_TPDO1_COMM, ob.OD_TPDO1_MAP, ob.COB_TPDO1 + n, fr.TPDO1_MAP)
        steps += _pdo_steps(ob.OD_TPDO2_COMM, ob.OD_TPDO2_MAP, ob.COB_TPDO2 + n, fr.TPDO2_MAP)
        return steps
