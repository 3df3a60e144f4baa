"""The CAN bus of drive_interface (python-can I/O): open, send, drain received frames, reopen.

The control period reads the bus itself (no python-can Notifier, no reader thread): at each
deadline :meth:`CanBusLink.receive` drains the frames received since the last period
(``bus.recv(0)`` until empty) and feeds each to its axis. Frames are time-stamped with their
receive time (``Message.timestamp``, the kernel's on SocketCAN) mapped onto the monotonic clock and
clamped to [previous drain, now]: exact with sane timestamps, never off by more than one period
whatever the interface reports, so stale-telemetry detection keeps its accuracy.

On ``friction_local`` the link moves raw ``struct can_frame`` bytes (``LocalBus.recv_raw`` /
``send_raw``, :class:`RawFrames`), received at the drain time (the time that bus stamps anyway).
Measured reason (1 CPU core of this 2-core VM, per frame): a python-can ``recv`` cost 3.3 us of
which 1.3 us is the system call, a send 2.3 us of which 1.4 us; through the link
(``bench/can_decode.py``, CPU us per axis and 1 kHz period, 1 / 3 axes) ODrive 22.0 / 19.6 ->
20.1 / 16.6, CiA 402 25.3 / 21.9 -> 21.5-22.5 / 18.3 (its SYNC, a constant, is packed once).

The drives' start-up frames (their protocol's, often none) are sent when the bus opens or reopens.
Bus errors are counted; a dead bus (bus-off error frame, reader failure, ``error_limit``
consecutive send failures) latches a bus fault on every drive and is reopened every
``recovery_period`` until it works again (each axis then logs that its drive stays disabled until
``~/enable``).
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable

import can

from friction_ros.can_bus.local_bus import (
    CAN_EFF_FLAG,
    CAN_EFF_MASK,
    CAN_ERR_FLAG,
    CAN_RTR_FLAG,
    LocalBus,
    pack_raw,
    raw_can_id,
)
from friction_ros.core.can.axis import DriveAxis
from friction_ros.core.can.frame import Frame
from friction_ros.core.validation import ParameterError

CAN_ERR_BUSOFF = 0x40  # SocketCAN error class bit in the id of an error frame
RX_BATCH_MAX = 256  # frames read per period at most (a 1 Mbit/s bus carries ~8 per ms)


#: python-can interfaces whose ``send`` serialises the Message before it returns (SocketCAN packs it,
#: ``virtual`` deep-copies it, ``friction_local`` packs it): one Message per id can be refilled
SERIALISING_INTERFACES = frozenset({"socketcan", "virtual", "friction_local"})


class FrameMessages:
    """The python-can Message of each Frame to send.

    A frame without payload (CiA 402 SYNC, an RTR request) is a constant: its Message is built once.
    With ``reuse`` (an interface of :data:`SERIALISING_INTERFACES`) a data frame's Message is built
    once per (id, length) and refilled in place: safe because that ``send`` is done with it before it
    returns and ``CanBusLink.send`` sends one batch at a time, under its lock. Measured reason
    (``bench/can_decode.py``, CPU us per axis and 1 kHz period without / through the bus link,
    3 axes): a new ``can.Message`` per frame cost ~0.7 us per data frame; ODrive 10.4 / 22.8 ->
    9.8 / 22.2, CiA 402 12.0 / 27.1 -> 11.4 / 25.4 (with the raw-id receive filters of
    ``friction_local``).
    """

    def __init__(self, reuse: bool = False) -> None:
        self._constant: dict[Frame, can.Message] = {}
        self._by_id: dict[tuple[int, bool, int], can.Message] | None = {} if reuse else None

    def message(self, f: Frame) -> can.Message:
        arb, data, remote, extended, dlc = f  # one unpack, not five attribute reads
        if data:
            by_id = self._by_id
            if by_id is None or remote or dlc is not None:
                return self._build(f)
            key = (arb, extended, len(data))
            msg = by_id.get(key)
            if msg is None:
                msg = by_id[key] = self._build(f)
            else:
                msg.data[:] = data
            return msg
        msg = self._constant.get(f)
        if msg is None:
            msg = self._constant[f] = can.Message(
                arbitration_id=arb, is_extended_id=extended, is_remote_frame=remote, dlc=f.length
            )
        return msg

    @staticmethod
    def _build(f: Frame) -> can.Message:
        return can.Message(
            arbitration_id=f.arbitration_id,
            data=f.data,
            is_extended_id=f.is_extended,
            is_remote_frame=f.is_remote,
            dlc=f.dlc,  # None: len(data)
        )


class RawFrames:
    """The ``struct can_frame`` bytes of each Frame to send on ``friction_local`` (no python-can
    Message): packed per frame, once for a frame without payload (the CiA 402 SYNC, an RTR request).
    Measured reason: see the module docstring."""

    def __init__(self) -> None:
        self._constant: dict[Frame, bytes] = {}

    def raw(self, f: Frame) -> bytes:
        arb, data, remote, extended, dlc = f
        if data:
            return pack_raw(raw_can_id(arb, extended, remote), len(data) if dlc is None else dlc, data)
        b = self._constant.get(f)
        if b is None:
            b = self._constant[f] = pack_raw(raw_can_id(arb, extended, remote), f.length, b"")
        return b


def bus_filters(axes: list[DriveAxis]) -> list[dict]:
    """Kernel receive filters for every drive on the bus (each filter once), from their protocols."""
    out: list[dict] = []
    for a in axes:
        out += [f for f in a.protocol.receive_filters() if f not in out]
    return out


def open_bus(interface: str, channel: str, bitrate: int, filters: list[dict]) -> can.BusABC:
    """Open a python-can bus; a failure becomes one clear ValueError line."""
    try:
        return can.Bus(interface=interface, channel=channel, bitrate=bitrate, can_filters=filters)
    except Exception as exc:
        hint = ""
        if interface == "socketcan":
            hint = f"; bring the interface up first: sudo ip link set {channel} up type can bitrate {bitrate}"
        raise ParameterError(
            f"cannot open CAN bus interface={interface} channel={channel}: {type(exc).__name__}: {exc}{hint}"
        ) from None


class CanBusLink:
    """One python-can bus shared by the ``axes`` of a node (frames routed by ``route``)."""

    def __init__(
        self,
        interface: str,
        channel: str,
        bitrate: int,
        axes: list[DriveAxis],
        route: Callable[[int, bytes], DriveAxis],
        error_limit: int,
        recovery_period: float,
        logger,
    ):
        self.interface, self.channel, self.bitrate = interface, channel, bitrate
        self.axes, self.route, self.logger = axes, route, logger
        self.error_limit = error_limit  # consecutive failed sends before the bus counts as dead
        self.recovery_period = recovery_period  # wait before reopening a dead bus [s]
        self.filters = bus_filters(axes)
        self.error_frames = 0
        self.send_errors = 0
        self.reopens = 0
        self.dead_since: float | None = None
        self._consecutive_send_errors = 0
        self._lock = threading.Lock()
        self._message = FrameMessages(reuse=interface in SERIALISING_INTERFACES).message
        self._raw = RawFrames().raw
        self._attach(open_bus(interface, channel, bitrate, self.filters))
        self._rx_ok = True  # False after a read failure until the bus is reopened
        self._rx_prev = time.monotonic()  # start of the previous drain (lower bound of receive times)
        self.send(self.startup_frames())

    def _attach(self, bus: can.BusABC) -> None:
        """Use ``bus``; with ``friction_local`` frames go in and out as raw ``struct can_frame``
        (:class:`RawFrames`), skipping python-can's Message."""
        self.bus = bus
        raw = isinstance(bus, LocalBus)
        self._recv_raw = bus.recv_raw if raw else None
        self._send_raw = bus.send_raw if raw else None

    def startup_frames(self) -> list[Frame]:
        """What the drives' protocols send when the bus opens or reopens (often nothing)."""
        return [f for a in self.axes for f in a.startup_frames()]

    def send(self, frames: list[Frame]) -> bool:
        """Send ``frames``; False if any failed (counted; too many in a row: the bus is dead)."""
        ok = True
        with self._lock:  # once per batch (the bus is replaced only under it)
            if self._send_raw is not None:
                send, message = self._send_raw, self._raw
            else:
                send, message = self.bus.send, self._message
            for f in frames:
                try:
                    send(message(f), 0.001)
                    self._consecutive_send_errors = 0
                except Exception as exc:  # can.CanError, OSError (ENOBUFS), closed bus ...
                    ok = False
                    self.send_errors += 1
                    self._consecutive_send_errors += 1
                    if self._consecutive_send_errors >= self.error_limit:
                        self.dead(f"{self._consecutive_send_errors} consecutive send failures: {exc}")
        return ok

    def send_final(self, frames: list[Frame], attempts: int = 3) -> bool:
        """Send the frames that leave the drives safe before closing: up to ``attempts`` tries 10 ms
        apart, then 5 ms for them to leave the socket. False if every try failed."""
        for attempt in range(attempts):
            if self.send(frames):
                time.sleep(0.005)
                return True
            if attempt + 1 < attempts:
                time.sleep(0.01)
        return False

    def dead(self, reason: str) -> None:
        """Latch a bus fault on every drive (logged by each axis' fault log) and reopen the bus."""
        if self.dead_since is None:
            self.dead_since = time.monotonic()
            reason += f"; reopening the bus every {self.recovery_period:g} s"
        for a in self.axes:
            a.report_bus_fault(reason)

    def receive(self, now: float) -> float:
        """Reopen a dead bus when it is time, then feed every frame received since the previous
        call to its axis. Returns the time of the previous call (the lower bound of this period)."""
        if self.dead_since is not None:
            self._recover(now)
        lo, self._rx_prev = self._rx_prev, now
        self._drain(now, lo, now - time.time())  # wall clock -> monotonic, for receive stamps
        return lo

    def _recover(self, now: float) -> None:
        if now - self.dead_since < self.recovery_period:
            return
        try:
            with self._lock:
                self.bus.shutdown()
                self._attach(open_bus(self.interface, self.channel, self.bitrate, self.filters))
            self._rx_ok = True
            self._rx_prev = now
            self.reopens += 1
            self._consecutive_send_errors = 0
            self.dead_since = None
            for a in self.axes:  # each axis logs "bus cleared ...; drive stays disabled until ~/enable"
                a.clear_bus_fault()
            self.send(self.startup_frames())
        except Exception as exc:
            self.dead_since = now
            self.logger.error(f"reopening the CAN bus failed: {exc}", throttle_duration_sec=5.0)

    def _drain(self, now: float, lo: float, off: float) -> None:
        """Feed every frame received since the previous period to its axis.

        Receive time = the frame's own timestamp (wall clock in python-can, the kernel's on
        SocketCAN) on the monotonic clock (``+ off``), clamped to [``lo`` = previous period, now].
        """
        if not self._rx_ok:
            return
        if self._recv_raw is not None:
            self._drain_raw(now)
            return
        bus, route = self.bus, self.route
        try:
            for _ in range(RX_BATCH_MAX):
                msg = bus.recv(0.0)
                if msg is None:
                    return
                if msg.is_error_frame:
                    self.error_frames += 1
                    if msg.arbitration_id & CAN_ERR_BUSOFF:
                        self.dead("bus-off error frame received")
                    continue
                t = msg.timestamp + off
                arb, data = msg.arbitration_id, msg.data
                route(arb, data).on_frame(
                    arb,
                    data,
                    msg.is_remote_frame,
                    msg.is_extended_id,
                    False,
                    now if t > now else lo if t < lo else t,
                )
        except Exception as exc:  # can.CanOperationError, OSError, closed bus ...
            self._rx_ok = False
            self.dead(f"CAN reader failed: {type(exc).__name__}: {exc}")

    def _drain_raw(self, now: float) -> None:
        """:meth:`_drain` on ``friction_local``: raw frames, received at ``now`` (the bus stamps a
        frame with the time it is read, i.e. during this drain)."""
        recv, route = self._recv_raw, self.route
        try:
            for _ in range(RX_BATCH_MAX):
                r = recv()
                if r is None:
                    return
                cid, data = r
                if cid & CAN_ERR_FLAG:
                    self.error_frames += 1
                    if cid & CAN_ERR_BUSOFF:
                        self.dead("bus-off error frame received")
                    continue
                ext = cid & CAN_EFF_FLAG
                arb = cid & (CAN_EFF_MASK if ext else 0x7FF)
                route(arb, data).on_frame(arb, data, bool(cid & CAN_RTR_FLAG), bool(ext), False, now)
        except Exception as exc:  # closed bus, OSError ...
            self._rx_ok = False
            self.dead(f"CAN reader failed: {type(exc).__name__}: {exc}")

    def counts(self) -> dict:
        """Diagnostics values of the bus: failed sends, error frames, reopens and its state."""
        return {
            "send_errors": self.send_errors,
            "error_frames": self.error_frames,
            "bus_reopens": self.reopens,
            "bus_state": self.state(),
        }

    def state(self) -> str:
        """The bus state for diagnostics (python-can's, or ``dead (reopening)``)."""
        if self.dead_since is not None:
            return "dead (reopening)"
        try:
            return self.bus.state.name.lower()
        except Exception:
            return "unknown"

    def close(self) -> None:
        try:
            self.bus.shutdown()
        except Exception as exc:
            self.logger.warning(f"closing the CAN bus: {exc}")
