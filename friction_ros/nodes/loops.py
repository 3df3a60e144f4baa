"""Fixed-rate control loops of the nodes and their timing statistics."""

from __future__ import annotations

import math
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from friction_ros.core.validation import ParameterError


@dataclass
class LoopStats:
    """Timing statistics of a fixed-rate loop (periods in seconds)."""

    cycles: int = 0
    overruns: int = 0
    max_lateness: float = 0.0
    total_lateness: float = 0.0
    last_exec: float = 0.0
    exec_times: list[float] = field(default_factory=list)


class FixedRateLoop:
    """Run ``callback()`` at a fixed period on a dedicated thread, counting overruns.

    rclpy timers drift at 1 kHz (anchors: rcl#289, rclpy#1452); this loop sleeps to absolute
    deadlines on the monotonic clock. It does not busy-wait: a Python spin holds the GIL and would
    delay the executor thread (command callbacks) by up to the interpreter's switch interval;
    ``spin`` > 0 re-enables a final busy-wait for timing accuracy at that cost. A cycle that starts
    more than one period late counts as an overrun and the schedule is re-anchored (no burst of
    catch-up cycles).
    """

    def __init__(
        self, period: float, callback: Callable[[], None], name: str = "control_loop", spin: float = 0.0
    ):
        if not period > 0:
            raise ParameterError(f"loop period = {period} must be > 0 s")
        self.SPIN_S = spin
        self.period = period
        self.callback = callback
        self.stats = LoopStats()
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name=name, daemon=True)

    def start(self) -> None:
        self._thread.start()

    def stop(self, timeout: float = 2.0) -> None:
        self._stop.set()
        if self._thread.is_alive() and threading.current_thread() is not self._thread:
            self._thread.join(timeout)

    def _run(self) -> None:
        next_t = time.monotonic()
        while not self._stop.is_set():
            now = time.monotonic()
            remaining = next_t - now
            if remaining > self.SPIN_S:
                time.sleep(remaining - self.SPIN_S)
            while self.SPIN_S and time.monotonic() < next_t:
                pass
            start = time.monotonic()
            lateness = start - next_t
            self.stats.max_lateness = max(self.stats.max_lateness, lateness)
            if lateness > self.period:
                self.stats.overruns += 1
                next_t = start
            self.callback()
            self.stats.cycles += 1
            self.stats.last_exec = time.monotonic() - start
            next_t += self.period


class DeadlineLoop:
    """Fixed-rate loop run by the node's own executor thread (no second Python thread).

    Between deadlines the executor processes callbacks (``spin_once`` with the time left as the
    timeout); at each deadline ``callback()`` runs. Compared with :class:`FixedRateLoop` there is no
    GIL hand-over between a loop thread and the executor thread, which otherwise delays command
    callbacks by up to the interpreter's switch interval (5 ms). :func:`run_node` drives it when a
    node's ``loop`` attribute is a DeadlineLoop. Same statistics and overrun rule as FixedRateLoop.

    ``wake_on_events=False``: the thread sleeps to each deadline instead of waiting in the executor,
    so a message arriving mid-period does not wake it; what arrived is handled just before the tick
    (up to :data:`READY_BEFORE_TICK` callbacks per period), which is when a node that applies
    commands at its tick uses them anyway. One period in :data:`EVENT_WAIT_EVERY` waits in the
    executor as before and so drains whatever queued meanwhile (rclpy's executor queues one event
    per message, even for a keep-last-1 topic: a publisher faster than READY_BEFORE_TICK messages a
    period would otherwise grow the queue without end and delay every later request). Measured reason
    (drive_interface, 1 drive at 1 kHz, ``bench/can_protocols.py``'s set-up): a command that
    arrived before the deadline cost a wake-up plus a second wait, ~80 us of CPU, in 56-87 % of
    the periods depending on the controller's timing (CiA 402 0.70-0.88 a period, ODrive
    0.56-0.71 in the same runs); the thread's wake-ups per period 4.0-4.4 -> 2.2, node CPU per axis
    (quiet 2-core VM) 29.6-31.4 % -> 24.0-26.9 %, for both protocols.
    """

    def __init__(self, period: float, callback: Callable[[], None], wake_on_events: bool = True):
        if not period > 0:
            raise ParameterError(f"loop period = {period} must be > 0 s")
        self.period = period
        self.callback = callback
        self.wake_on_events = wake_on_events
        self.stats = LoopStats()
        self._next: float | None = None

    def stop(self, timeout: float = 0.0) -> None:
        self._next = None

    #: callbacks already waiting that are run before a tick (see :meth:`run_once`)
    READY_BEFORE_TICK = 2
    #: without ``wake_on_events``, one period in this many still waits in the executor (drains a queue)
    EVENT_WAIT_EVERY = 10

    def run_once(self, executor, max_wait: float = 0.05) -> None:
        """Process callbacks (or sleep, see ``wake_on_events``) until the next deadline (at most
        ``max_wait``), then tick if it is due.

        Before the tick, up to :data:`READY_BEFORE_TICK` callbacks that are already waiting run
        (``spin_once(0)``): a command that arrived before the step is applied by it, as a drive
        applies what is in its receive buffer when its cycle runs. Without this, a command queued
        while the previous callback overran the deadline waited a whole period behind the tick.
        """
        now = time.monotonic()
        if self._next is None:
            self._next = now
        remaining = self._next - now
        if remaining > 0:
            if self.wake_on_events or self.stats.cycles % self.EVENT_WAIT_EVERY == 0:
                executor.spin_once(timeout_sec=min(remaining, max_wait))
            else:
                time.sleep(min(remaining, max_wait))
            if time.monotonic() < self._next:
                return
        for _ in range(self.READY_BEFORE_TICK):
            executor.spin_once(timeout_sec=0.0)
        start = time.monotonic()
        lateness = start - self._next
        self.stats.max_lateness = max(self.stats.max_lateness, lateness)
        self.stats.total_lateness += lateness
        if lateness > self.period:
            self.stats.overruns += 1
            self._next = start
        self.callback()
        self.stats.cycles += 1
        self.stats.last_exec = time.monotonic() - start
        self._next += self.period


class LatencyHistogram:
    """Constant-memory latency statistics: 10 us bins up to 100 ms (+ overflow), exact max.

    A soak of hours must not grow memory (a list of samples did: ~30 MB per 10 minutes at 1 kHz).
    Percentiles are resolved to one bin (10 us).
    """

    BIN_S = 1e-5
    BINS = 10_000

    def __init__(self, bin_s: float = BIN_S, bins: int = BINS):
        self.BIN_S, self.BINS = bin_s, bins
        self.counts = np.zeros(self.BINS + 1, dtype=np.int64)
        self.n = 0
        self.max = 0.0

    def add(self, seconds: float) -> None:
        i = int(seconds / self.BIN_S) if seconds > 0 else 0
        self.counts[min(i, self.BINS)] += 1
        self.n += 1
        if seconds > self.max:
            self.max = seconds

    def percentile(self, q: float) -> float:
        """Upper edge of the bin holding the q-th percentile (s); NaN without samples."""
        if self.n == 0:
            return math.nan
        k = int(np.searchsorted(np.cumsum(self.counts), q / 100.0 * self.n))
        return min((k + 1) * self.BIN_S, self.max) if k < self.BINS else self.max
