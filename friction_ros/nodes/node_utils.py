"""Shared rclpy plumbing for the friction_ros nodes: QoS, diagnostics, loop, main() (parameters: :mod:`.parameters`).

QoS choices (documented in README "Interfaces"):

* ``COMMAND_QOS``: reliable, keep-last **1**. A queued stale torque command is a safety bug
  (ros_odrive #32): the newest command is the only one that matters.
* ``STATE_QOS``: reliable, keep-last 10. Joint states, controller/estimator states and events are
  recorded for identification, so they must not be dropped under load; the depth absorbs bursts.
* ``RECORDED_QOS``: reliable, keep-last 5000, for the *publishers* of topics that are recorded or
  evaluated (joint states, controller state, estimates, events). A reliable keep-last writer drops
  what a slow reader has not acknowledged once its history is full, so the writer's depth is what
  decides whether a recorder or an evaluator that falls behind (CPU contention, a burst) loses
  samples: 5000 periods is 5 s at 1 kHz. Subscribers that control keep STATE_QOS (a controller
  must not work through a backlog of stale states).
* ``SENSOR_QOS``: best effort, keep-last 5 (rclpy's sensor-data profile) for high-rate telemetry
  that may be lost (raw drive state).
* ``LATCHED_QOS``: reliable, transient-local depth 1 for coefficients that late joiners need.
"""

from __future__ import annotations

import gc
import math
import signal
import sys
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import rclpy
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rclpy.node import Node
from rclpy.qos import (
    DurabilityPolicy,
    HistoryPolicy,
    QoSProfile,
    ReliabilityPolicy,
    qos_profile_sensor_data,
)
from rclpy.signals import SignalHandlerOptions

from friction_ros.core.validation import ParameterError
from friction_ros.core.wire import JointStateEncoder

COMMAND_QOS = QoSProfile(
    history=HistoryPolicy.KEEP_LAST,
    depth=1,
    reliability=ReliabilityPolicy.RELIABLE,
    durability=DurabilityPolicy.VOLATILE,
)
STATE_QOS = QoSProfile(
    history=HistoryPolicy.KEEP_LAST,
    depth=10,
    reliability=ReliabilityPolicy.RELIABLE,
    durability=DurabilityPolicy.VOLATILE,
)
RECORDED_QOS = QoSProfile(
    history=HistoryPolicy.KEEP_LAST,
    depth=5000,
    reliability=ReliabilityPolicy.RELIABLE,
    durability=DurabilityPolicy.VOLATILE,
)
SENSOR_QOS = qos_profile_sensor_data
LATCHED_QOS = QoSProfile(
    history=HistoryPolicy.KEEP_LAST,
    depth=1,
    reliability=ReliabilityPolicy.RELIABLE,
    durability=DurabilityPolicy.TRANSIENT_LOCAL,
)


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
    """

    def __init__(self, period: float, callback: Callable[[], None]):
        if not period > 0:
            raise ParameterError(f"loop period = {period} must be > 0 s")
        self.period = period
        self.callback = callback
        self.stats = LoopStats()
        self._next: float | None = None

    def stop(self, timeout: float = 0.0) -> None:
        self._next = None

    def run_once(self, executor, max_wait: float = 0.05) -> None:
        """Process callbacks until the next deadline (at most ``max_wait``), then tick if it is due."""
        now = time.monotonic()
        if self._next is None:
            self._next = now
        remaining = self._next - now
        if remaining > 0:
            executor.spin_once(timeout_sec=min(remaining, max_wait))
            if time.monotonic() < self._next:
                return
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

    def __init__(self):
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


class DiagnosticsPublisher:
    """Publish one ``diagnostic_msgs/DiagnosticArray`` status for a node on ``diagnostics``."""

    def __init__(self, node: Node, name: str, hardware_id: str = ""):
        self.node = node
        self.name = name
        self.hardware_id = hardware_id
        self.pub = node.create_publisher(DiagnosticArray, "diagnostics", STATE_QOS)

    def publish(self, level: int, message: str, values: dict[str, Any]) -> DiagnosticStatus:
        status = DiagnosticStatus(
            level=level if isinstance(level, bytes) else bytes([level]),
            name=f"{self.node.get_namespace().rstrip('/')}/{self.name}",
            message=message,
            hardware_id=self.hardware_id,
            values=[KeyValue(key=k, value=_fmt(v)) for k, v in values.items()],
        )
        msg = DiagnosticArray(status=[status])
        msg.header.stamp = self.node.get_clock().now().to_msg()
        self.pub.publish(msg)
        return status


def _fmt(v: Any) -> str:
    if isinstance(v, float):
        return f"{v:.6g}"
    return str(v)


OK = DiagnosticStatus.OK
WARN = DiagnosticStatus.WARN
ERROR = DiagnosticStatus.ERROR
STALE = DiagnosticStatus.STALE


def set_realtime_priority(priority: int, logger=None) -> bool:
    """Run every thread of this process (rclpy executor, DDS receive threads) with SCHED_FIFO ``priority``.

    Threads started later inherit the policy from the thread that starts them. 0 leaves the normal
    scheduler. Needs CAP_SYS_NICE (root, or ``rtprio`` in /etc/security/limits.conf); without it a
    warning is logged and the node runs on as before. Linux RT throttling (sched_rt_runtime_us,
    95 % by default) still leaves the rest of the system some CPU if a node spins.
    """
    import os

    if priority <= 0 or not hasattr(os, "sched_setscheduler"):
        return False
    param = os.sched_param(priority)
    try:
        for tid in os.listdir("/proc/self/task"):
            try:
                os.sched_setscheduler(int(tid), os.SCHED_FIFO, param)
            except ProcessLookupError:
                pass  # thread ended meanwhile
    except (PermissionError, OSError) as exc:
        if logger is not None:
            logger.warning(
                f"realtime_priority {priority}: SCHED_FIFO not permitted ({exc}); normal scheduling"
            )
        return False
    return True


def set_cpu_affinity(cpu: int, logger=None) -> bool:
    """Pin every thread of this process to CPU ``cpu`` (-1: leave the affinity as it is).

    On a small VM a wake-up across cores (DDS delivery to a process on the other core) costs an
    inter-processor interrupt and VM exits: a JointState round trip between two rclpy processes
    measured ~130 us across cores and ~60 us on one core (bench/loop.py docstring). Pinning plant
    and controller to one core and the estimator to the other keeps the latency chain on one core.
    """
    import os

    if cpu < 0:
        return False
    try:
        for tid in os.listdir("/proc/self/task"):
            try:
                os.sched_setaffinity(int(tid), {cpu})
            except ProcessLookupError:
                pass
    except OSError as exc:
        if logger is not None:
            logger.warning(f"cpu_affinity {cpu} not applied ({exc})")
        return False
    return True


def apply_scheduling(node: Node, values: dict[str, Any]) -> None:
    """Apply the ``realtime_priority`` / ``cpu_affinity`` parameters (``parameters.SCHEDULING``)."""
    set_cpu_affinity(values.get("cpu_affinity", -1), node.get_logger())
    set_realtime_priority(values.get("realtime_priority", 0), node.get_logger())


def make_executor():
    """The executor of every node: rclpy's EventsExecutor when available (several times less
    overhead per callback than SingleThreadedExecutor, which is what lets the lockstep graph run
    faster than real time), else SingleThreadedExecutor. FRICTION_ROS_EXECUTOR=single forces the latter."""
    import os

    if os.environ.get("FRICTION_ROS_EXECUTOR", "events") == "events":
        try:
            from rclpy.experimental import EventsExecutor

            return EventsExecutor()
        except ImportError:
            pass
    return rclpy.executors.SingleThreadedExecutor()


def _parameter_files(args: list[str]) -> list[str | None]:
    """The ``--params-file`` arguments inside ``--ros-args`` sections (None for a missing name)."""
    files: list[str | None] = []
    in_ros = False
    it = iter(args)
    for a in it:
        if a == "--ros-args":
            in_ros = True
        elif a == "--":
            in_ros = False
        elif in_ros and a == "--params-file":
            files.append(next(it, None))
    return files


def init_ros(args: list[str] | None = None) -> str | None:
    """``rclpy.init`` for a node process; returns None, or one line saying why it cannot start.

    Parameter files are checked first (exists, YAML, node -> ``ros__parameters`` mappings:
    :func:`~friction_ros.core.yaml_files.check_parameter_file`); anything rcl still refuses is
    reported from rcl's own message, with rcl's log output held back so the reason is the one line
    the user sees. SIGINT/SIGTERM are left to the caller (rclpy installs no handlers).
    """
    import os
    import tempfile

    from friction_ros.core.yaml_files import check_parameter_file

    args = list(sys.argv if args is None else args)
    try:
        for f in _parameter_files(args):
            if f is None:
                raise ParameterError("--params-file needs a file name")
            check_parameter_file(f)
    except ParameterError as exc:
        return str(exc)
    saved = os.dup(2)
    with tempfile.TemporaryFile() as held:
        os.dup2(held.fileno(), 2)
        try:
            rclpy.init(args=args, signal_handler_options=SignalHandlerOptions.NO)
            failure = None
        except Exception as exc:  # noqa: BLE001 - rclpy raises RCLError (not exported) for bad arguments
            failure = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        finally:
            os.dup2(saved, 2)
            os.close(saved)
        if failure is None:
            held.seek(0)
            text = held.read()
            if text:
                sys.stderr.write(text.decode(errors="replace"))
            return None
    for prefix in ("failed to initialize rcl: ",):
        failure = failure.removeprefix(prefix)
    return f"ROS arguments refused: {failure.split(', at ')[0]}"


def run_node(factory: Callable[[], Node], args: list[str] | None = None) -> int:
    """Standard ``main()`` of a friction_ros node.

    Starts rclpy (:func:`init_ros`: a bad parameter file prints one line, exit code 2), builds the
    node (a ParameterError/ValueError there prints one clear line and exits with code 2: the node
    refuses to start), spins until Ctrl-C/SIGTERM, then calls the node's ``on_shutdown()`` (which
    must leave actuators safe: zero torque, drive idle) before destroying it. SIGINT/SIGTERM are
    handled from before rclpy starts: a stop that arrives while the node is being built ends it
    quietly once it is built (on_shutdown() runs, no KeyboardInterrupt traceback).
    """
    stop = threading.Event()

    def _on_signal(signum, _frame):
        stop.set()

    # Our own SIGINT/SIGTERM handling keeps the context alive until on_shutdown() has zeroed outputs.
    signal.signal(signal.SIGTERM, _on_signal)
    signal.signal(signal.SIGINT, _on_signal)
    reason = init_ros(args)
    if reason is not None:
        print(f"error: {reason}", file=sys.stderr)
        return 2
    node = None
    try:
        node = factory()
    except (ParameterError, ValueError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        rclpy.try_shutdown()
        return 2
    # Everything built so far (modules, node, core objects) lives for the whole run: keep it out of
    # the cyclic collector so a full collection does not scan it (multi-ms pauses in the loop).
    gc.collect()
    gc.freeze()
    executor = make_executor()
    executor.add_node(node)
    loop = getattr(node, "loop", None)
    try:
        if isinstance(loop, DeadlineLoop):
            while not stop.is_set() and rclpy.ok():
                loop.run_once(executor)
        while not stop.is_set() and rclpy.ok():
            executor.spin_once(timeout_sec=0.05)
    except rclpy.executors.ExternalShutdownException:
        pass
    finally:
        shutdown = getattr(node, "on_shutdown", None)
        if shutdown is not None:
            try:
                shutdown()
            except Exception as exc:  # last line of defence: report, still tear down
                print(f"error during shutdown of {node.get_name()}: {exc}", file=sys.stderr)
        executor.remove_node(node)
        node.destroy_node()
        rclpy.try_shutdown()
    return 0


class CommandPublisher:
    """``joint_commands`` publisher of one joint (sensor_msgs/JointState effort, COMMAND_QOS).

    Every command answers a joint state and carries its stamp (lockstep and latency measurement);
    the last command is kept so a duplicate state (a lockstep re-send) gets the same answer again
    without recomputing. Commands are serialised by :class:`~friction_ros.core.wire.JointStateEncoder` and published as
    bytes (same wire type; no message object per command).
    """

    def __init__(self, node: Node, joint: str, topic: str = "joint_commands"):
        from sensor_msgs.msg import JointState

        self.joint = joint
        self.pub = node.create_publisher(JointState, topic, COMMAND_QOS)
        self._encoder = JointStateEncoder([joint], ("effort",))
        self.last: bytes | None = None

    def publish(self, stamp, torque: float) -> None:
        """Publish ``torque`` [N*m] with header stamp ``stamp`` (builtin_interfaces/Time)."""
        self.publish_stamp(stamp.sec, stamp.nanosec, torque)

    def publish_stamp(self, sec: int, nanosec: int, torque: float) -> None:
        """Publish ``torque`` with the stamp given as (sec, nanosec) (hot path)."""
        self.last = self._encoder.pack(sec, nanosec, float(torque))
        self.pub.publish(self.last)

    def republish(self) -> bool:
        """Send the last command again; False if there is none yet."""
        if self.last is None:
            return False
        self.pub.publish(self.last)
        return True


def stamp_to_ns(stamp) -> int:
    """builtin_interfaces/Time -> integer nanoseconds."""
    return int(stamp.sec) * 1_000_000_000 + int(stamp.nanosec)


def select_effort(msg, joint: str) -> float | None:
    """Effort of ``joint`` in a JointState command (an unnamed single effort also counts); None if absent."""
    if msg.name:
        try:
            i = list(msg.name).index(joint)
        except ValueError:
            return None
        return float(msg.effort[i]) if i < len(msg.effort) else None
    return float(msg.effort[0]) if len(msg.effort) == 1 else None


def select_joint(msg, joint: str) -> tuple[float, float | None, float | None] | None:
    """(position, velocity|None, effort|None) of ``joint`` in a JointState; None if it is absent."""
    names = list(msg.name)
    if names:
        if joint not in names:
            return None
        i = names.index(joint)
    elif len(msg.position) == 1:
        i = 0
    else:
        return None
    if i >= len(msg.position):
        return None
    vel = float(msg.velocity[i]) if i < len(msg.velocity) else None
    eff = float(msg.effort[i]) if i < len(msg.effort) else None
    return float(msg.position[i]), vel, eff
