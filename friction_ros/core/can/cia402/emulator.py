"""An emulated CiA 402 servo drive: the ``canopen`` library's LocalNode (slave) with an EDS, a plant behind it.

The LocalNode provides the CiA 301 services: SDO server on the object dictionary of the EDS, NMT
slave (boot-up message, PRE-OPERATIONAL / OPERATIONAL / STOPPED), heartbeat producer (0x1017),
EMCY producer. This class adds what a CiA 402 drive does in cyclic synchronous torque mode:

* PDOs as configured in 0x1400/0x1600 (RPDO1) and 0x1800-0x1801/0x1A00-0x1A01 (TPDO1-2), re-read
  after every change and at NMT start; exchanged only in OPERATIONAL. A received synchronous RPDO
  is applied at the next SYNC; at each SYNC the plant is advanced to now and the TPDOs are sent.
* The CiA 402 state machine (:class:`~.state_machine.DriveStateMachine`) in the statusword; torque is
  applied only in OPERATION ENABLED with 0x6060 = 10, zero otherwise (the command is refused).
* A target torque above max torque 0x6072 raises EMCY 0x8311 (excess torque) and the drive goes
  to FAULT; the fault reset (rising edge of controlword bit 7) works once the target is within it.

The plant is the project's plant model, stepped like the frame-level emulator does
(:func:`friction_ros.core.can.emulator.plant_from_preset`: joint torque in, joint measurement out),
in fixed ``1 / physics_rate_hz`` steps up to the SYNC time (plant frozen while no SYNC arrives).
"""

from __future__ import annotations

import struct
import threading
import time
from dataclasses import dataclass
from pathlib import Path

import canopen
from canopen.objectdictionary import datatypes as dt

from friction_ros.core.can.cia402 import objects as ob
from friction_ros.core.can.cia402.state_machine import DriveStateMachine, State
from friction_ros.core.can.cia402.units import Cia402Scaling
from friction_ros.core.can.joint import JointConversion
from friction_ros.core.validation import check_int, check_real

DEFAULT_EDS = str(Path(__file__).resolve().parents[4] / "params" / "cia402_generic.eds")
_FMT = {
    dt.INTEGER8: "b",
    dt.UNSIGNED8: "B",
    dt.INTEGER16: "h",
    dt.UNSIGNED16: "H",
    dt.INTEGER32: "i",
    dt.UNSIGNED32: "I",
}
_PDO_CONFIG = range(0x1400, 0x1C00)


@dataclass(frozen=True)
class Cia402EmulatorConfig:
    node_id: int = 1
    eds_path: str = DEFAULT_EDS
    counts_per_rev: int = 131072  # written to 0x608F
    rated_torque: float = 1.0  # motor N*m, written to 0x6076 (mN*m)
    max_torque_permille: int = 3000  # 0x6072
    physics_rate_hz: float = 1000.0

    def __post_init__(self):
        check_int("emulator.node_id", self.node_id, ob.NODE_ID_MIN, ob.NODE_ID_MAX)
        check_int("emulator.counts_per_rev", self.counts_per_rev, 1, 2**31 - 1)
        check_real("emulator.rated_torque", self.rated_torque, 0.0, 4e6, lo_open=True, unit="N*m")
        check_int("emulator.max_torque_permille", self.max_torque_permille, 0, 65535)
        check_real("emulator.physics_rate_hz", self.physics_rate_hz, 0.0, 100_000.0, lo_open=True, unit="Hz")


class _Pdo:
    """One PDO as mapped: COB-ID, struct of its entries, the object index of each entry."""

    def __init__(self, cob: int, fmt: str, indices: list[int], sync: bool):
        self.cob, self.st, self.indices, self.sync = cob, struct.Struct("<" + fmt), indices, sync


class Cia402DriveEmulator:
    def __init__(
        self,
        network: canopen.Network,
        plant,
        conversion: JointConversion,
        config: Cia402EmulatorConfig | None = None,
        clock=time.monotonic,
    ):
        self.cfg = cfg = config or Cia402EmulatorConfig()
        self.network = network
        self.plant = plant
        self.conv = conversion
        self.clock = clock
        self.node = node = canopen.LocalNode(cfg.node_id, cfg.eds_path)
        self._od = node.object_dictionary
        self.sm = DriveStateMachine()
        self.lock = threading.RLock()
        self.silent = False
        self.error_code = 0
        self.controlword = 0
        self.target_torque = 0  # per mille, as received
        self._pending: dict[int, int] | None = None  # RPDO values waiting for the SYNC
        self.applied_torque = 0.0  # motor N*m
        self.dt = 1.0 / cfg.physics_rate_hz
        self._t_phys: float | None = None
        self.meas = plant.step(0.0, self.dt) if plant is not None else None
        self.host = None  # a DriveEmulator that owns the plant instead (see .emulated)
        self.syncs = 0
        self.tpdos_sent = 0
        self.emcy_sent: list[int] = []
        self.state_log: list[State] = [self.sm.state]  # every state the drive went through
        self._rpdos: dict[int, _Pdo] = {}
        self._tpdos: list[_Pdo] = []
        self._dirty = True
        self._put(ob.OD_ENCODER_RESOLUTION, 1, cfg.counts_per_rev)
        self._put(ob.OD_ENCODER_RESOLUTION, 2, 1)
        self._put(ob.OD_RATED_TORQUE, 0, round(cfg.rated_torque * 1000))
        self._put(ob.OD_RATED_CURRENT, 0, max(1, round(cfg.rated_torque / conversion.torque_constant * 1000)))
        self._put(ob.OD_MAX_TORQUE, 0, cfg.max_torque_permille)
        self.mode = self.get(ob.OD_MODES_OF_OPERATION)  # cached copies of 0x6060 / 0x6072 (hot path)
        self.max_torque = cfg.max_torque_permille
        gr = conversion.gear_ratio
        self._put(ob.OD_GEAR_RATIO, 1, round(gr * 1000))
        self._put(ob.OD_GEAR_RATIO, 2, 1000)
        self.scaling = Cia402Scaling(
            cfg.counts_per_rev, cfg.rated_torque, cfg.rated_torque / conversion.torque_constant, conversion
        )
        node.add_read_callback(self._on_read)
        node.add_write_callback(self._on_write)
        network.add_node(node)
        network.subscribe(ob.COB_SYNC, self._on_sync)
        network.subscribe(ob.COB_NMT, self._on_nmt)

    # ---- object dictionary --------------------------------------------------------------------------
    def _put(self, index: int, sub: int, value: int) -> None:
        obj = (
            self._od[index]
            if sub == 0 and not hasattr(self._od[index], "subindices")
            else self._od[index][sub]
        )
        self.node.data_store.setdefault(index, {})[sub] = obj.encode_raw(value)

    def get(self, index: int, sub: int = 0) -> int:
        obj = self._od[index] if not hasattr(self._od[index], "subindices") else self._od[index][sub]
        return obj.decode_raw(self.node.get_data(index, sub))

    def _live(self, index: int):
        """Values the drive computes (not stored): None for stored objects."""
        if index == ob.OD_STATUSWORD:
            return self.sm.statusword
        if index == ob.OD_POSITION_ACTUAL:
            return self.scaling.counts(self.motor_measurements()[0])
        if index == ob.OD_VELOCITY_ACTUAL:
            return self.scaling.counts(self.motor_measurements()[1])
        if index == ob.OD_TORQUE_ACTUAL:
            return self.scaling.motor_permille(self.motor_measurements()[2])
        if index == ob.OD_CURRENT_ACTUAL:
            return round(1000.0 * self.motor_measurements()[3] / self.scaling.rated_current)
        if index == ob.OD_MODES_DISPLAY:
            return self.mode
        if index == ob.OD_ERROR_CODE:
            return self.error_code
        if index == ob.OD_ERROR_REGISTER:
            return 0x01 if self.sm.state in (State.FAULT, State.FAULT_REACTION_ACTIVE) else 0
        return None

    def motor_measurements(self) -> tuple[float, float, float, float]:
        """Motor position [rad], velocity [rad/s], torque [N*m], current [A] of the plant now."""
        h = self.host
        if h is not None:
            return h.motor_position, h.motor_velocity, h.motor_torque_measured, h.meas.motor_current
        m, c = self.meas, self.conv
        return (
            c.motor_position(m.position),
            c.motor_velocity(m.velocity),
            c.motor_torque(m.effort),
            m.motor_current,
        )

    def _on_read(self, index, subindex, od):
        return self._live(index)

    def _on_write(self, index, subindex, od, data):
        if index in _PDO_CONFIG:
            self._dirty = True
        elif index == ob.OD_CONTROLWORD:  # an SDO write acts at once
            with self.lock:
                self.controlword = od.decode_raw(data)
                self._apply_controlword()
        elif index == ob.OD_TARGET_TORQUE:
            self.target_torque = od.decode_raw(data)
        elif index == ob.OD_MODES_OF_OPERATION:
            self.mode = od.decode_raw(data)
        elif index == ob.OD_MAX_TORQUE:
            self.max_torque = od.decode_raw(data)

    # ---- PDO configuration ------------------------------------------------------------------------------
    def _read_pdos(self) -> None:
        for cob in self._rpdos:
            self.network.unsubscribe(cob, self._on_rpdo)
        self._rpdos, self._tpdos = {}, []
        for comm, mapping, rx in ((0x1400, 0x1600, True), (0x1800, 0x1A00, False), (0x1801, 0x1A01, False)):
            if comm not in self._od:
                continue
            cob = self.get(comm, 1)
            if cob & ob.PDO_COB_INVALID:
                continue
            fmt, indices = "", []
            for k in range(1, self.get(mapping, 0) + 1):
                entry = self.get(mapping, k)
                index, sub, bits = entry >> 16, (entry >> 8) & 0xFF, entry & 0xFF
                obj = self._od[index] if not hasattr(self._od[index], "subindices") else self._od[index][sub]
                fmt += _FMT[obj.data_type]
                indices.append(index)
                assert bits == 8 * struct.calcsize("<" + _FMT[obj.data_type])
            pdo = _Pdo(cob & 0x7FF, fmt, indices, self.get(comm, 2) <= 240)
            if rx:
                self._rpdos[pdo.cob] = pdo
                self.network.subscribe(pdo.cob, self._on_rpdo)
            else:
                self._tpdos.append(pdo)
        self._dirty = False

    # ---- bus events (canopen's notifier thread) ------------------------------------------------------------
    @property
    def operational(self) -> bool:
        return self.node.nmt.state == "OPERATIONAL"

    def boot(self) -> None:
        """Power-up: boot-up message, then PRE-OPERATIONAL with the heartbeat producer running."""
        self.node.nmt.send_command(ob.NMT_RESET_NODE)
        self.node.nmt.send_command(ob.NMT_PRE_OPERATIONAL)

    def _on_nmt(self, can_id, data, timestamp):
        if len(data) < 2 or data[1] not in (0, self.cfg.node_id):
            return
        if data[0] in (ob.NMT_RESET_NODE, ob.NMT_RESET_COMMUNICATION):
            for index in [
                i for i in self.node.data_store if i in _PDO_CONFIG or i == ob.OD_HEARTBEAT_PRODUCER
            ]:
                del self.node.data_store[index]
            self.boot()
        with self.lock:
            self._read_pdos()

    def _on_rpdo(self, can_id, data, timestamp):
        pdo = self._rpdos.get(can_id)
        if pdo is None or not self.operational or len(data) < pdo.st.size:
            return
        values = dict(zip(pdo.indices, pdo.st.unpack_from(data)))
        with self.lock:
            if pdo.sync:
                self._pending = values
            else:
                self._apply_rpdo(values)

    def _apply_rpdo(self, values: dict[int, int]) -> None:
        for index, v in values.items():
            if index == ob.OD_CONTROLWORD:
                self.controlword = v
            elif index == ob.OD_TARGET_TORQUE:
                self.target_torque = v
            else:
                self.node.set_data(index, 0, self._od[index].encode_raw(v))
        self._apply_controlword()

    def _apply_controlword(self) -> None:
        before = self.sm.state
        self.sm.apply(self.controlword)
        self._log_state()
        if before == State.FAULT and self.sm.state != State.FAULT:
            self.error_code = 0
            self._emcy(0)  # error reset

    def _log_state(self) -> None:
        if self.sm.state != self.state_log[-1]:
            self.state_log.append(self.sm.state)

    def _emcy(self, code: int) -> None:
        if not self.silent:
            self.emcy_sent.append(code)
            self.node.emcy.send(code, 0x01 if code else 0)

    def _on_sync(self, can_id, data, timestamp):
        if can_id != ob.COB_SYNC:
            return
        with self.lock:
            self.syncs += 1
            if self._dirty:
                self._read_pdos()
            if self._pending is not None and self.operational:
                self._apply_rpdo(self._pending)
                self._pending = None
            self._check_torque()
            self.advance(self.clock())
            if self.operational and not self.silent:
                for pdo in self._tpdos:
                    if pdo.sync:
                        data = pdo.st.pack(*(self._value(i) for i in pdo.indices))
                        self.network.send_message(pdo.cob, data)
                        self.tpdos_sent += 1

    def _value(self, index: int) -> int:
        v = self._live(index)
        return self.get(index) if v is None else v

    def _check_torque(self) -> None:
        over = abs(self.target_torque) > self.max_torque
        if self.sm.fault_active and not over:
            self.sm.clear_fault()
        if over and self.sm.state == State.OPERATION_ENABLED:
            self.error_code = 0x8311
            self.sm.fault()
            self._log_state()
            self._emcy(0x8311)
        if self.sm.state == State.FAULT_REACTION_ACTIVE:
            self.sm.apply(self.controlword)  # reaction done: FAULT
            self._log_state()

    def motor_torque(self) -> float:
        """Motor torque the drive applies now [N*m]: the target in OPERATION ENABLED and mode 10, else 0."""
        if self.sm.state != State.OPERATION_ENABLED or self.mode != ob.MODE_CYCLIC_SYNC_TORQUE:
            return 0.0
        return self.target_torque * self.scaling.rated_torque / 1000.0

    def advance(self, t: float, max_backlog: float = 0.05) -> None:
        """Step the plant in fixed ``dt`` steps up to time ``t`` (skip, not replay, a longer pause)."""
        if self.host is not None:
            return  # the host steps the plant
        with self.lock:
            if self._t_phys is None or t - self._t_phys > max_backlog:
                self._t_phys = t - self.dt
            self.applied_torque = tau = self.motor_torque()
            while self._t_phys + self.dt <= t + 1e-9:
                self._t_phys += self.dt
                self.meas = self.plant.step(self.conv.joint_torque(tau), self.dt)

    # ---- faults for tests ------------------------------------------------------------------------------------
    def set_silent(self, silent: bool = True) -> None:
        """Stop (or resume) heartbeat, TPDOs and EMCY, like a drive that lost its CAN link."""
        self.silent = silent
        if silent:
            self.node.nmt.stop_heartbeat()
        else:
            self.node.nmt.start_heartbeat(self.get(ob.OD_HEARTBEAT_PRODUCER))

    def set_max_torque(self, permille: int) -> None:
        """Change 0x6072 on the drive side (e.g. a drive panel), without the master knowing."""
        self.node.set_data(ob.OD_MAX_TORQUE, 0, self._od[ob.OD_MAX_TORQUE].encode_raw(permille))

    def stop(self) -> None:
        self.node.nmt.stop_heartbeat()
        self.network.unsubscribe(ob.COB_SYNC, self._on_sync)
        self.network.unsubscribe(ob.COB_NMT, self._on_nmt)


def emulated_drives(bus, node_ids, preset: str = "abb_m19s", plant_factory=None, **config):
    """A canopen Network on ``bus`` (python-can ``virtual``, ``friction_local``, ...) with one booted
    emulated drive per node id, each with its own plant: ``plant_factory()`` -> (plant, conversion),
    by default the plant of ``preset``. Returns (network, drives)."""
    from friction_ros.core.can.emulator import plant_from_preset

    network = canopen.Network(bus)
    network.NOTIFIER_CYCLE = 0.05  # a prompt disconnect()
    network.connect()
    drives = []
    for n in node_ids:
        plant, conv = plant_factory() if plant_factory else plant_from_preset(preset)
        drives.append(Cia402DriveEmulator(network, plant, conv, Cia402EmulatorConfig(node_id=n, **config)))
    for d in drives:
        d.boot()
    return network, drives
