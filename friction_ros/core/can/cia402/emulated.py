"""CiA 402 drive side for the frame-level :class:`~friction_ros.core.can.emulator.DriveEmulator`
(``drive_emulator --protocol cia402``, ``simulated_drive``): the canopen-based
:class:`~.emulator.Cia402DriveEmulator` behind a canopen Network without a bus.

canopen's custom-backend hooks carry the frames (canopen ``Network.notify`` in, an overridden
``send_message`` out): every received frame for this node (NMT, SYNC, RPDO1, SDO) goes through the
LocalNode and the CiA 402 logic, and what they send is returned as the replies. The DriveEmulator
owns the plant, time, latency, loss and silence. The heartbeat is a cyclic frame at the EDS rate
(a 0x1017 written later changes what the LocalNode would send, not this rate).
"""

from __future__ import annotations

import canopen

from friction_ros.core.can.cia402 import objects as ob
from friction_ros.core.can.cia402.emulator import Cia402DriveEmulator, Cia402EmulatorConfig
from friction_ros.core.can.cia402.state_machine import State
from friction_ros.core.can.frame import Frame, SafeDecoder
from friction_ros.core.can.protocol import EmulatedDriveProtocol
from friction_ros.core.validation import check_int


class _Task:
    """A periodic send of canopen (heartbeat): nothing runs; the emulator's cyclic frame stands in."""

    def __init__(self, data):
        self.data = data

    def update(self, data) -> None:
        self.data = data

    def stop(self) -> None:
        pass


class FrameNetwork(canopen.Network):
    """A canopen Network without a bus: sent frames collect in ``out``."""

    def __init__(self):
        super().__init__(None)
        self.out: list[Frame] = []

    def send_message(self, can_id: int, data, remote: bool = False) -> None:
        self.out.append(Frame(can_id, bytes(data), remote))

    def send_periodic(self, can_id, data, period, remote=False):
        return _Task(data)

    def take(self) -> list[Frame]:
        out, self.out = self.out, []
        return out


class _Decoder(SafeDecoder):
    def __init__(self, node_id: int):
        super().__init__()
        self.ids = {ob.COB_NMT, ob.COB_SYNC, ob.COB_RPDO1 + node_id, ob.COB_SDO_RX + node_id}

    def _decode(self, arb_id, data, is_remote, is_extended, is_error):
        if arb_id not in self.ids or is_remote or is_extended or is_error:
            self.stats.ignored += 1
            return None
        self.stats.decoded += 1
        return arb_id, bytes(data)


class Cia402EmulatedDrive(EmulatedDriveProtocol):
    def __init__(self, drive):
        super().__init__(drive)
        cfg = drive.cfg
        self.network = FrameNetwork()
        self.cia = Cia402DriveEmulator(
            self.network, None, cfg.conversion, Cia402EmulatorConfig(node_id=cfg.node_id)
        )
        self.cia.host = drive
        self.decoder = _Decoder(cfg.node_id)
        self.cia.boot()
        self._heartbeat_ms = self.cia.get(ob.OD_HEARTBEAT_PRODUCER)

    @classmethod
    def check_config(cls, cfg) -> None:
        check_int("emulator.node_id", cfg.node_id, ob.NODE_ID_MIN, ob.NODE_ID_MAX)

    def cyclic(self):
        return [(1000.0 / self._heartbeat_ms, "heartbeat")] if self._heartbeat_ms else []

    def telemetry_frame(self, key) -> Frame:
        return Frame(ob.COB_HEARTBEAT + self.drive.cfg.node_id, bytes((self.cia.node.nmt._state,)))

    def handle(self, msg, t: float) -> list[Frame]:
        arb_id, data = msg
        was_fault = self.cia.sm.state == State.FAULT
        self.network.notify(arb_id, data, t)
        if was_fault and self.cia.sm.state != State.FAULT:
            self.drive.axis_error = 0  # fault reset (controlword bit 7) clears an injected error too
        if arb_id == ob.COB_RPDO1 + self.drive.cfg.node_id:
            self.drive.stats.commands += 1
        return self.network.take()

    @property
    def armed(self) -> bool:
        return self.cia.sm.state == State.OPERATION_ENABLED and not self.drive.axis_error

    def motor_torque(self) -> float:
        return self.cia.motor_torque() if not self.drive.axis_error else 0.0

    def fault(self) -> None:
        """An injected error: FAULT with EMCY 0x1000 (generic), reported with the next replies."""
        with self.cia.lock:
            self.cia.error_code = ob.ERROR_GENERIC
            self.cia.sm.fault()
            self.cia.sm.apply(self.cia.controlword)
            self.cia._log_state()
            self.cia._emcy(ob.ERROR_GENERIC)
