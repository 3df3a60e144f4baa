"""Shared rclpy plumbing for the friction_ros nodes: QoS, parameters, diagnostics, loop, main().

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
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import rclpy
import rclpy.exceptions
import rclpy.parameter
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rcl_interfaces.msg import (
    FloatingPointRange,
    IntegerRange,
    ParameterDescriptor,
    ParameterType,
    SetParametersResult,
)
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

_TYPES = {
    bool: ParameterType.PARAMETER_BOOL,
    int: ParameterType.PARAMETER_INTEGER,
    float: ParameterType.PARAMETER_DOUBLE,
    str: ParameterType.PARAMETER_STRING,
    list: ParameterType.PARAMETER_DOUBLE_ARRAY,
}


@dataclass
class Param:
    """One declared ROS parameter: default value, description, optional range/choices."""

    name: str
    default: Any
    description: str
    lo: float | None = None
    hi: float | None = None
    choices: tuple[str, ...] = ()
    read_only: bool = False
    unit: str = ""

    @property
    def ptype(self) -> int:
        if isinstance(self.default, list):
            if self.default and isinstance(self.default[0], str):
                return ParameterType.PARAMETER_STRING_ARRAY
            return ParameterType.PARAMETER_DOUBLE_ARRAY
        return _TYPES[type(self.default)]

    def descriptor(self) -> ParameterDescriptor:
        text = self.description + (f" [{self.unit}]" if self.unit else "")
        constraints = ""
        if self.choices:
            constraints = "one of: " + ", ".join(self.choices)
        d = ParameterDescriptor(
            name=self.name,
            type=self.ptype,
            description=text,
            additional_constraints=constraints,
            read_only=self.read_only,
        )
        if self.lo is not None or self.hi is not None:
            lo = -sys.float_info.max if self.lo is None else self.lo
            hi = sys.float_info.max if self.hi is None else self.hi
            if isinstance(self.default, bool):
                pass
            elif isinstance(self.default, int):
                d.integer_range = [IntegerRange(from_value=int(lo), to_value=int(hi), step=0)]
            elif isinstance(self.default, float):
                d.floating_point_range = [
                    FloatingPointRange(from_value=float(lo), to_value=float(hi), step=0.0)
                ]
        return d

    def check(self, value: Any) -> Any:
        """Validate ``value``; raise ParameterError naming this parameter and the allowed values."""
        if isinstance(self.default, float) and isinstance(value, int) and not isinstance(value, bool):
            value = float(value)
        if isinstance(self.default, list):
            if not isinstance(value, (list, tuple)):
                raise ParameterError(f"{self.name} = {value!r} must be a list")
            value = list(value)
            if self.ptype == ParameterType.PARAMETER_DOUBLE_ARRAY:
                value = [float(v) for v in value]
                if any(math.isnan(v) for v in value):
                    raise ParameterError(f"{self.name} = {value!r} must not contain NaN")
            return value
        if type(value) is not type(self.default):
            want = type(self.default).__name__
            raise ParameterError(f"{self.name} = {value!r} has type {type(value).__name__}: must be {want}")
        if isinstance(value, float) and math.isnan(value):
            raise ParameterError(f"{self.name} = nan is not a number")
        if self.choices and value not in self.choices:
            raise ParameterError(
                f"{self.name} = {value!r} is not allowed: must be one of {', '.join(self.choices)}"
            )
        if isinstance(value, (int, float)) and not isinstance(value, bool):
            if (self.lo is not None and value < self.lo) or (self.hi is not None and value > self.hi):
                lo = "-inf" if self.lo is None else f"{self.lo:g}"
                hi = "inf" if self.hi is None else f"{self.hi:g}"
                rng = f"[{lo}, {hi}]"
                unit = f" {self.unit}" if self.unit else ""
                raise ParameterError(f"{self.name} = {value:g} is out of range: must be in {rng}{unit}")
        return value


class ParameterNode(Node):
    """A Node that knows which parameters it was given (parameter files, ``-p``, ``parameter_overrides``).

    rclpy keeps those "overrides" to itself until a parameter of the same name is declared, but the
    nodes need them earlier: to find the keys a nested YAML section has (:func:`section_specs`), to
    choose defaults from a given value (the experiment's ``profile``) and to report given parameters
    that no node declares (:func:`declare`). Public rclpy API only: the node is created with
    ``automatically_declare_parameters_from_overrides``, reads the parameters rclpy declared that
    way into :attr:`given_parameters` (name -> rclpy ``Parameter``) and undeclares them again, so
    that :func:`declare` declares each one with its own descriptor (type, range, read-only) and the
    given value, exactly as without the automatic declaration. The parameters rclpy declares for
    itself (``use_sim_time``, the read-only ``start_type_description_service``) stay declared and
    are not listed.
    """

    def __init__(self, node_name: str, **kwargs):
        super().__init__(node_name, automatically_declare_parameters_from_overrides=True, **kwargs)
        self.given_parameters: dict[str, rclpy.parameter.Parameter] = {}
        for name in self.list_parameters([], 0).names:  # depth 0: every name
            if name == "use_sim_time" or self.describe_parameter(name).read_only:
                continue  # rclpy's own (time source, start_type_description_service)
            self.given_parameters[name] = self.get_parameter(name)
            self.undeclare_parameter(name)


def declare(node: ParameterNode, params: Iterable[Param], check_unknown: bool = True) -> dict[str, Any]:
    """Declare ``params`` with descriptors and return their validated values.

    Raises ParameterError (the node refuses to start) when a value from a parameter file is invalid.
    Parameters given in the file but not declared are reported too, so typos do not pass silently.
    """
    values: dict[str, Any] = {}
    specs = list(params)
    given = node.given_parameters
    for p in specs:
        g = given.get(p.name)
        given_value = p.default if g is None else g.value
        try:
            if g is not None and isinstance(p.default, float) and g.type_ == g.Type.INTEGER:
                # YAML "gain: 3" for a double parameter: accept it as 3.0 instead of a type error.
                given_value = float(g.value)
                node.declare_parameter(p.name, given_value, p.descriptor(), ignore_override=True)
            else:  # rclpy applies the given value (checked against the default's type)
                node.declare_parameter(p.name, p.default, p.descriptor(), ignore_override=False)
        except (
            rclpy.exceptions.InvalidParameterValueException,
            rclpy.exceptions.InvalidParameterTypeException,
        ) as exc:
            allowed = p.descriptor()
            rng = ""
            if allowed.floating_point_range:
                r = allowed.floating_point_range[0]
                rng = f"; allowed range [{r.from_value:g}, {r.to_value:g}]"
            elif allowed.integer_range:
                r = allowed.integer_range[0]
                rng = f"; allowed range [{r.from_value}, {r.to_value}]"
            raise ParameterError(
                f"{node.get_name()}: parameter {p.name} = {given_value!r} is invalid "
                f"(expected {type(p.default).__name__}{rng}): {p.description}"
            ) from exc
    for p in specs:
        value = node.get_parameter(p.name).value
        values[p.name] = p.check(value)
    if not check_unknown:
        return values
    declared = set(node.list_parameters([], 0).names) | {"use_sim_time"}
    unknown = sorted(k for k in given if k not in declared and not k.startswith("qos_overrides"))
    if unknown:
        raise ParameterError(
            f"{node.get_name()}: unknown parameter(s) {', '.join(unknown)} in the parameter file; "
            f"declared parameters are: {', '.join(sorted(declared))}"
        )
    return values


def add_runtime_validation(
    node: Node, specs: Iterable[Param], apply: Callable[[dict[str, Any]], None] | None = None
) -> None:
    """Validate run-time parameter changes with the same rules; reject with a clear reason.

    ``apply`` receives ``{name: value}`` of an accepted change and may raise ParameterError (for
    cross-parameter checks done by the core); the change is then rejected and the node keeps its
    last good state.
    """
    by_name = {p.name: p for p in specs}

    def _callback(changes) -> SetParametersResult:
        accepted: dict[str, Any] = {}
        try:
            for c in changes:
                if c.name == "use_sim_time":
                    continue
                spec = by_name.get(c.name)
                if spec is None:
                    raise ParameterError(f"{c.name} is not a parameter of {node.get_name()}")
                if spec.read_only:
                    raise ParameterError(f"{c.name} is read-only (restart the node to change it)")
                accepted[c.name] = spec.check(c.value)
            if apply is not None and accepted:
                apply(accepted)
        except (ParameterError, ValueError) as exc:
            node.get_logger().warning(f"rejected parameter change: {exc}")
            return SetParametersResult(successful=False, reason=str(exc))
        return SetParametersResult(successful=True)

    node.add_on_set_parameters_callback(_callback)


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


SCHEDULING_PARAMS = [
    Param(
        "realtime_priority",
        0,
        "SCHED_FIFO priority of the node's threads (0: normal scheduling; needs CAP_SYS_NICE)",
        lo=0,
        hi=99,
        read_only=True,
    ),
    Param(
        "cpu_affinity", -1, "pin the node's threads to this CPU (-1: any CPU)", lo=-1, hi=4095, read_only=True
    ),
]


def gate_params() -> list[Param]:
    """``input_gate.*`` parameters of the joint-state plausibility gate (:mod:`friction_ros.core.input_gate`)."""
    from friction_ros.core.input_gate import GATE_DEFAULTS, GATE_DOCS

    return [
        Param(
            f"input_gate.{k}",
            v,
            GATE_DOCS[k][0],
            lo=1 if isinstance(v, int) else 0.0,
            unit=GATE_DOCS[k][1],
            read_only=True,
        )
        for k, v in GATE_DEFAULTS.items()
    ]


def apply_scheduling(node: Node, values: dict[str, Any]) -> None:
    """Apply the ``realtime_priority`` / ``cpu_affinity`` parameters (:data:`SCHEDULING_PARAMS`)."""
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


def flatten(config: dict[str, Any], prefix: str = "") -> dict[str, Any]:
    """Nested config dict -> dotted ROS parameter names (``{'pid': {'p': 1}} -> {'pid.p': 1}``)."""
    flat: dict[str, Any] = {}
    for key, value in config.items():
        name = f"{prefix}{key}"
        if isinstance(value, dict):
            flat.update(flatten(value, name + "."))
        else:
            flat[name] = value
    return flat


def unflatten(flat: dict[str, Any]) -> dict[str, Any]:
    """Dotted ROS parameter names -> nested config dict (inverse of :func:`flatten`)."""
    nested: dict[str, Any] = {}
    for name, value in flat.items():
        parts = name.split(".")
        d = nested
        for p in parts[:-1]:
            d = d.setdefault(p, {})
        d[parts[-1]] = value
    return nested


def override_values(node: ParameterNode, prefix: str) -> dict[str, Any]:
    """Values given for ``<prefix>.*`` in the node's parameter files / command line (dotted names)."""
    return {k: v.value for k, v in node.given_parameters.items() if k.startswith(prefix + ".")}


def section_specs(
    node: ParameterNode, prefix: str, defaults: dict[str, Any], doc: str, read_only: bool = False
) -> list[Param]:
    """Param specs for every ``<prefix>.<key>`` of a nested core section (defaults + keys given in files).

    Keys only present in the parameter file (e.g. the coefficients of the chosen friction model) are
    declared too, with their type taken from the given value; the core object built from the section
    then validates names and ranges and raises one ParameterError naming the key if anything is off.
    """
    flat = {f"{prefix}.{k}": v for k, v in flatten(defaults).items() if v is not None}
    for key, value in override_values(node, prefix).items():
        flat.setdefault(key, value)
    return [
        Param(
            key, list(v) if isinstance(v, tuple) else v, f"{doc}: {key.split('.', 1)[1]}", read_only=read_only
        )
        for key, v in flat.items()
    ]


def declare_section(
    node: ParameterNode, prefix: str, defaults: dict[str, Any], doc: str, read_only: bool = False
) -> dict[str, Any]:
    """Declare a section (see :func:`section_specs`) and return it as a nested dict."""
    values = declare(node, section_specs(node, prefix, defaults, doc, read_only), check_unknown=False)
    return unflatten(values).get(prefix, {})


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
