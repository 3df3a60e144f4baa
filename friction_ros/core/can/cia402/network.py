"""Several CiA 402 axes on one python-can bus, one SYNC per control period (CiA 301 7.2.5).

Per period ``step(t)``: read every received frame and hand it to its axis (a dict from COB-ID to
the axis's ``handle``), send each axis's RPDO (or start-up frames), then one SYNC for all
drives: synchronous RPDOs received before a SYNC are applied at it, and the drives answer with
their synchronous TPDOs (transmission type 1). ``close()`` sends the exit sequence of every axis
(quick stop, disable voltage, NMT pre-operational), each followed by a SYNC.
"""

from __future__ import annotations

import time

import can

from friction_ros.core.can.cia402 import frames as fr
from friction_ros.core.can.cia402.master import Cia402Master
from friction_ros.core.can.frame import Frame


class SyncProducer:
    """The SYNC producer of a bus: one frame (COB-ID 0x080, no counter) per control period."""

    def __init__(self, period: float):
        self.period = period
        self.count = 0
        self.frame = fr.SYNC_FRAME

    def next(self) -> Frame:
        self.count += 1
        return self.frame


def _msg(f: Frame) -> can.Message:
    return can.Message(arbitration_id=f.arbitration_id, data=f.data, is_extended_id=False, check=False)


class Cia402Network:
    """The master side of one bus: axes, one SYNC producer, frame dispatch."""

    def __init__(
        self, bus: can.BusABC, masters: list[Cia402Master], period: float = 1e-3, clock=time.monotonic
    ):
        self.bus = bus
        self.masters = list(masters)
        self.sync = SyncProducer(period)
        self.clock = clock
        self.period = period
        self.send_errors = 0
        self.frames_rx = 0
        for m in self.masters:
            m.control_period = period
        self._dispatch = {cob: m.handle for m in self.masters for cob in m.cob_ids}
        self._sync_msg = _msg(self.sync.frame)

    def send(self, f: Frame) -> None:
        try:
            self.bus.send(_msg(f))
        except can.CanError:
            self.send_errors += 1

    def receive(self, t: float) -> None:
        recv, dispatch = self.bus.recv, self._dispatch
        msg = recv(0.0)
        while msg is not None:
            self.frames_rx += 1
            h = dispatch.get(msg.arbitration_id)
            if h is not None and not msg.is_remote_frame and not msg.is_error_frame:
                h(msg.arbitration_id, msg.data, t)
            msg = recv(0.0)

    def start(self) -> None:
        t = self.clock()
        for m in self.masters:
            for f in m.start(t):
                self.send(f)

    def step(self, t: float | None = None) -> None:
        """One control period: receive, per-axis frames, one SYNC."""
        t = self.clock() if t is None else t
        self.receive(t)
        for m in self.masters:
            for f in m.frames(t):
                self.send(f)
        if any(m.phase == "operational" for m in self.masters):
            self.sync.next()
            try:
                self.bus.send(self._sync_msg)
            except can.CanError:
                self.send_errors += 1

    def run_until(self, predicate, timeout: float) -> bool:
        """Step every ``period`` until ``predicate()`` is true or ``timeout`` [s] passes."""
        end = self.clock() + timeout
        nxt = self.clock()
        while self.clock() < end:
            self.step()
            if predicate():
                return True
            nxt += self.period
            delay = nxt - self.clock()
            if delay > 0:
                time.sleep(delay)
            else:
                nxt = self.clock()
        return False

    def close(self) -> None:
        """Exit sequence of every operational axis, one SYNC after each round."""
        rounds = [m.exit_frames() for m in self.masters]
        for k in range(max((len(r) for r in rounds), default=0)):
            for r in rounds:
                for f in r[k] if k < len(r) else ():
                    self.send(f)
            self.send(self.sync.next())
            time.sleep(self.period)
