"""LocalBus: a python-can bus shared by the processes of one machine, over Unix datagram sockets.

For machines without SocketCAN or ``vcan`` (containers, CI runners, this project's test VM):
python-can's ``virtual`` bus only connects buses of one process, so a drive emulator and the
``drive_interface`` node could not run as separate processes the way a drive and its node do on a
robot. With this bus they can::

    drive_emulator --interface friction_local --channel joint1
    drive_interface --ros-args -p interface:=friction_local -p channel:=joint1 ...

Semantics are those of a CAN bus: every frame one member sends is received by every other member
(not by the sender), in order. Each member binds a datagram socket
``<dir>/<channel>/<pid>-<n>`` (``<dir>`` = ``$FRICTION_CAN_DIR`` or ``/tmp/friction_can``); a send
is one non-blocking ``send`` per peer on a socket connected to it, a receive one ``recv``, and frames travel as SocketCAN's
16-byte classic ``struct can_frame`` (``can_id`` with the EFF/RTR/ERR flags, ``len``, 8 data bytes),
so the per-frame cost is close to a SocketCAN raw socket's. Peers are found by listing the channel
folder at most every ``refresh_period`` (a new member is heard within 0.2 s); a dead member's
socket is removed on the first refused send. A receive queue holds only
``net.unix.max_dgram_qlen`` frames (10 by default), so a send to a full queue is retried until the
send timeout (2 ms without one) before that member loses the frame (``frames_dropped``), as an
overflowing SocketCAN receiver would; it then gets no waiting for 0.1 s (a stalled member cannot
stall the bus). CAN FD, bit timing and bus errors are not
emulated; ``bitrate`` is accepted and ignored. Registered with python-can as ``friction_local``.

Receive filters (``can_filters``) act like SocketCAN's kernel filters: on the raw ``can_id`` before
a Message is built (``id & mask == can_id & mask``, standard or extended as the filter says), an
exact 11/29-bit filter by one set lookup. Measured reason (``bench/can_decode.py``, the node's bus
link, 3 CiA 402 drives = 15 exact filters): python-can's own loop over the filters for every frame
cost 1.1 us per axis and period (ODrive, one masked filter per drive: 0.2). A ``sendto`` naming the
peer's path resolves that path in the kernel on every frame: 2.7 us CPU per 16-byte datagram here,
1.4 us on a socket connected once (per frame sent; ``bench/can_decode.py``'s send cost).
"""

from __future__ import annotations

import contextlib
import errno
import itertools
import os
import select
import socket
import struct
import time
from pathlib import Path

import can

CAN_EFF_FLAG = 0x80000000
CAN_RTR_FLAG = 0x40000000
CAN_ERR_FLAG = 0x20000000
CAN_EFF_MASK = 0x1FFFFFFF
_FRAME = struct.Struct("=IB3x8s")  # struct can_frame (classic CAN, 16 bytes)
_CAN_ID = struct.Struct("=I")  # the can_id at the start of a struct can_frame
_ID_BITS = CAN_EFF_FLAG | CAN_EFF_MASK  # the can_id without the RTR and ERR flags
_ids = itertools.count()


class RawFilter:
    """python-can ``can_filters`` as a test of a raw SocketCAN ``can_id`` (with the EFF/RTR/ERR
    flags): exact filters (full mask) in one set, the others tested in turn. No filters: all pass."""

    def __init__(self, filters) -> None:
        self.exact: set[int] = set()  # can_id with the EFF flag as the frame carries it
        self.masked: list[tuple[int, int, bool | None]] = []  # (id & mask, mask, extended or None)
        self.all = not filters
        for f in filters or ():
            can_id, mask, ext = f["can_id"], f["can_mask"], f.get("extended")
            full = CAN_EFF_MASK if ext else 0x7FF
            if ext is not None and mask & full == full:
                self.exact.add((can_id & full) | (CAN_EFF_FLAG if ext else 0))
            else:
                self.masked.append((can_id & mask, mask, ext))

    def passes(self, cid: int) -> bool:
        """Whether a frame with raw ``cid`` passes (by its id, as python-can filters do)."""
        if self.all or (cid & _ID_BITS) in self.exact:
            return True
        ext = bool(cid & CAN_EFF_FLAG)
        arb = cid & (CAN_EFF_MASK if ext else 0x7FF)
        for i, m, e in self.masked:
            if arb & m == i and (e is None or e == ext):
                return True
        return False


def default_dir() -> Path:
    return Path(os.environ.get("FRICTION_CAN_DIR", "/tmp/friction_can"))


def pack_frame(msg: can.Message) -> bytes:
    """python-can Message -> SocketCAN ``struct can_frame`` bytes."""
    cid = raw_can_id(msg.arbitration_id, msg.is_extended_id, msg.is_remote_frame)
    if msg.is_error_frame:
        cid |= CAN_ERR_FLAG
    return _FRAME.pack(cid, msg.dlc, msg.data)  # bytes or bytearray: no copy


def raw_can_id(arbitration_id: int, extended: bool, remote: bool) -> int:
    """SocketCAN ``can_id``: the 11/29-bit id with the EFF and RTR flags."""
    cid = (arbitration_id & CAN_EFF_MASK) | CAN_EFF_FLAG if extended else arbitration_id & 0x7FF
    return cid | CAN_RTR_FLAG if remote else cid


def pack_raw(cid: int, dlc: int, data: bytes) -> bytes:
    """``struct can_frame`` bytes of a raw ``can_id`` (:func:`raw_can_id`), length and payload."""
    return _FRAME.pack(cid, dlc, data)


def unpack_frame(raw: bytes, timestamp: float, channel: str) -> can.Message | None:
    """``struct can_frame`` bytes -> Message, or None for a datagram that is not one."""
    if len(raw) != _FRAME.size:
        return None
    cid, dlc, data = _FRAME.unpack(raw)
    if dlc > 8:
        return None
    ext = bool(cid & CAN_EFF_FLAG)
    rtr = bool(cid & CAN_RTR_FLAG)
    return can.Message(
        timestamp=timestamp,
        arbitration_id=cid & (CAN_EFF_MASK if ext else 0x7FF),
        is_extended_id=ext,
        is_remote_frame=rtr,
        is_error_frame=bool(cid & CAN_ERR_FLAG),
        dlc=dlc,
        data=None if rtr else data[:dlc],
        channel=channel,
    )


class LocalBus(can.BusABC):
    """A CAN bus between processes of one machine (see the module docstring)."""

    FULL_QUEUE_WAIT = 0.002  # [s] longest wait for a full receive queue when send() has no timeout
    CONGESTED_HOLD = 0.1  # [s] a member whose queue stayed full gets no waiting for this long

    def __init__(
        self,
        channel: str = "can0",
        can_filters=None,
        directory: str | os.PathLike | None = None,
        refresh_period: float = 0.2,
        receive_own_messages: bool = False,
        **kwargs,
    ):
        name = str(channel)
        if not name or "/" in name or name in (".", ".."):
            raise ValueError(f"friction_local channel must be a plain name (no '/'), got {channel!r}")
        if receive_own_messages:
            raise ValueError(
                "friction_local: receive_own_messages is not supported (a CAN node does not hear itself)"
            )
        self.channel = name
        self.channel_info = f"friction_local channel {name}"
        self._dir = Path(directory) if directory is not None else default_dir() / name
        self._dir.mkdir(parents=True, exist_ok=True)
        self._path = str(self._dir / f"{os.getpid()}-{next(_ids)}")
        if len(self._path.encode()) > 107:
            raise ValueError(f"friction_local socket path too long for AF_UNIX (max 107 bytes): {self._path}")
        with contextlib.suppress(FileNotFoundError):
            os.unlink(self._path)
        self._sock = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
        self._sock.bind(self._path)
        self._sock.setblocking(False)
        self._refresh_period = refresh_period
        self._peers: dict[str, socket.socket] = {}  # peer path -> a socket connected to it
        self._targets: tuple[tuple[str, socket.socket], ...] = ()  # the same, iterated per send
        self._refreshed = -1e9
        self.frames_dropped = 0
        self._congested: dict[str, float] = {}
        self._closed = False
        self._filter = RawFilter(None)
        super().__init__(channel=name, can_filters=can_filters, **kwargs)

    # ---- peers ------------------------------------------------------------------------------------
    def _refresh(self, now: float) -> None:
        self._refreshed = now
        try:
            names = os.listdir(self._dir)
        except FileNotFoundError:
            names = []
        paths = {str(self._dir / n) for n in names} - {self._path}
        for gone in [p for p in self._peers if p not in paths]:
            self._peers.pop(gone).close()  # left (its socket file removed)
        for peer in paths - self._peers.keys():
            self._connect(peer)
        self._targets = tuple(self._peers.items())

    def _connect(self, peer: str) -> None:
        """A socket connected to ``peer`` (sends skip the path lookup of ``sendto``); a path nobody
        is bound to is removed (a member that died without shutdown())."""
        sock = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
        sock.setblocking(False)
        try:
            sock.connect(peer)
        except (ConnectionRefusedError, FileNotFoundError):
            sock.close()
            with contextlib.suppress(OSError):
                os.unlink(peer)
            return
        except OSError:
            sock.close()  # not a socket we can use (e.g. no permission): skipped
            return
        self._peers[peer] = sock

    def _forget(self, peer: str) -> None:
        """A send to ``peer`` was refused: its member is gone, or a new one is bound to that path
        (connected to again)."""
        sock = self._peers.pop(peer, None)
        if sock is not None:
            sock.close()
        self._connect(peer)
        self._targets = tuple(self._peers.items())

    # ---- BusABC -----------------------------------------------------------------------------------
    def send(self, msg: can.Message, timeout: float | None = None) -> None:
        """Send to every other member.

        A receive queue holds only ``net.unix.max_dgram_qlen`` (10) frames, less than a burst such
        as the enable sequences of several drives. A member whose queue is full is retried every
        50 us until ``timeout`` (None: :attr:`FULL_QUEUE_WAIT`); if it stays full it loses the frame
        (``frames_dropped``) and counts as congested for :attr:`CONGESTED_HOLD`: frames for it are
        dropped at once meanwhile, so a member that does not read cannot stall the bus.
        """
        self.send_raw(pack_frame(msg), timeout)

    def send_raw(self, raw: bytes, timeout: float | None = None) -> None:
        """:meth:`send` of a frame already packed as ``struct can_frame`` (:func:`pack_raw`)."""
        if self._closed:
            raise can.CanOperationError("friction_local bus is shut down")
        now = time.monotonic()
        if now - self._refreshed > self._refresh_period:
            self._refresh(now)
        deadline = None
        congested = self._congested
        for peer, sock in self._targets:
            while True:
                try:
                    sock.send(raw)
                    break
                except (ConnectionRefusedError, FileNotFoundError):
                    self._forget(peer)
                    break
                except OSError as exc:
                    if exc.errno not in (errno.EAGAIN, errno.EWOULDBLOCK, errno.ENOBUFS):
                        raise can.CanOperationError(f"friction_local send failed: {exc}", exc.errno) from exc
                    t = time.monotonic()
                    if congested.get(peer, -1.0) > t:
                        self.frames_dropped += 1
                        break
                    if deadline is None:
                        wait = self.FULL_QUEUE_WAIT if timeout is None else max(float(timeout), 0.0)
                        deadline = t + wait
                    if t >= deadline:
                        self.frames_dropped += 1  # its queue stayed full: it loses the frame
                        congested[peer] = t + self.CONGESTED_HOLD
                        break
                    time.sleep(5e-5)

    def _apply_filters(self, filters) -> None:
        self._filter = RawFilter(filters)

    def _recv_internal(self, timeout: float | None):
        """The next frame that passes the filters (frames that do not are read and dropped)."""
        if self._closed:
            raise can.CanOperationError("friction_local bus is shut down")
        sock, f = self._sock, self._filter
        deadline = None
        while True:
            try:
                raw = sock.recv(64)
            except BlockingIOError:
                if timeout == 0:
                    return None, True
                if deadline is None and timeout is not None:
                    deadline = time.monotonic() + timeout
                left = None if deadline is None else deadline - time.monotonic()
                if left is not None and left <= 0:
                    return None, True
                ready, _, _ = select.select([sock], [], [], left)
                if not ready:
                    return None, True
                continue
            if len(raw) != _FRAME.size or not f.passes(_CAN_ID.unpack_from(raw)[0]):
                continue  # not a frame, or filtered out
            msg = unpack_frame(raw, time.time(), self.channel)
            if msg is not None:
                return msg, True

    def recv_raw(self) -> tuple[int, bytes] | None:
        """The next received frame that passes the filters as (raw ``can_id`` with the EFF/RTR/ERR
        flags, payload), or None when none is waiting; never waits and builds no Message.

        What the node's bus link drains each period (it takes the drain time as the receive time:
        ``recv`` stamps a frame with the time it was read, which is the same)."""
        if self._closed:
            raise can.CanOperationError("friction_local bus is shut down")
        recv, f = self._sock.recv, self._filter
        while True:
            try:
                raw = recv(64)
            except BlockingIOError:
                return None
            if len(raw) != 16:
                continue  # not a frame
            cid, dlc, data = _FRAME.unpack(raw)
            if dlc <= 8 and f.passes(cid):
                return cid, b"" if cid & CAN_RTR_FLAG else data[:dlc]

    def fileno(self) -> int:
        return self._sock.fileno()

    def shutdown(self) -> None:
        if self._closed:
            return
        self._closed = True
        super().shutdown()
        self._sock.close()
        for sock in self._peers.values():
            sock.close()
        self._peers.clear()
        self._targets = ()
        with contextlib.suppress(FileNotFoundError):
            os.unlink(self._path)
