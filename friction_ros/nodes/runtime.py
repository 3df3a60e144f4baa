"""Process runtime of a node: rclpy start-up, ``main()``, executor, real-time scheduling.

Stopping (SIGINT/SIGTERM within 1 s at any moment, start-up included) is :mod:`.stopping`.
"""

from __future__ import annotations

import argparse
import gc
import os
import sys
import tempfile
import threading
from collections.abc import Callable
from typing import Any

import rclpy
import rclpy.executors
from rclpy.node import Node
from rclpy.signals import SignalHandlerOptions

from friction_ros.core.validation import ParameterError
from friction_ros.nodes import stopping
from friction_ros.nodes.loops import DeadlineLoop
from friction_ros.nodes.node_help import exit_if_help
from friction_ros.nodes.stopping import StopRequested, interruptible

#: Fast DDS writer defaults for this package's nodes (a 0.1 s heartbeat: a node waiting for its last
#: messages to be confirmed before exiting waits ~0.1 s, not Fast DDS's 3 s period)
WRITER_PROFILE = os.path.join(os.path.dirname(__file__), "fastdds_writer_profile.xml")
#: the environment variables and file by which a user gives Fast DDS profiles of their own
USER_PROFILE_VARS = (
    "FASTRTPS_DEFAULT_PROFILES_FILE",
    "FASTDDS_DEFAULT_PROFILES_FILE",
    "RMW_FASTRTPS_USE_QOS_FROM_XML",
)
USER_PROFILE_FILE = "DEFAULT_FASTRTPS_PROFILES.xml"


def use_writer_profile(environ=os.environ) -> bool:
    """Point Fast DDS at :data:`WRITER_PROFILE` before rclpy starts, unless the user configures
    Fast DDS profiles (an environment variable of :data:`USER_PROFILE_VARS` or the default profile
    file in the working directory): theirs win, untouched. Other middlewares ignore it."""
    if any(environ.get(v) for v in USER_PROFILE_VARS) or os.path.exists(USER_PROFILE_FILE):
        return False
    environ["FASTRTPS_DEFAULT_PROFILES_FILE"] = WRITER_PROFILE
    return True


#: executor callbacks between two checks of rclpy.ok() in :func:`spin_until_stopped` (a stop
#: request is checked after every callback)
OK_CHECK_EVERY = 64


def set_realtime_priority(priority: int, logger=None) -> bool:
    """Run every thread of this process (rclpy executor, DDS receive threads) with SCHED_FIFO ``priority``.

    Threads started later inherit the policy from the thread that starts them. 0 leaves the normal
    scheduler. Needs CAP_SYS_NICE (root, or ``rtprio`` in /etc/security/limits.conf); without it a
    warning is logged and the node runs on as before. Linux RT throttling (sched_rt_runtime_us,
    95 % by default) still leaves the rest of the system some CPU if a node spins.
    """
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
    """Apply the ``realtime_priority`` / ``cpu_affinity`` parameters (:data:`SCHEDULING_PARAMS`)."""
    set_cpu_affinity(values.get("cpu_affinity", -1), node.get_logger())
    set_realtime_priority(values.get("realtime_priority", 0), node.get_logger())


def make_executor():
    """The executor of every node: rclpy's EventsExecutor when available (several times less
    overhead per callback than SingleThreadedExecutor, which is what lets the lockstep graph run
    faster than real time), else SingleThreadedExecutor. FRICTION_ROS_EXECUTOR=single forces the latter."""
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


def init_ros(args: list[str] | None = None, node_args: list[list[str]] = ()) -> str | None:
    """``rclpy.init`` for a node process; returns None, or one line saying why it cannot start.

    Parameter files are checked first (exists, YAML, node -> ``ros__parameters`` mappings:
    :func:`~friction_ros.core.yaml_files.check_parameter_file`); anything rcl still refuses is
    reported from rcl's own message, with rcl's log output held back so the reason is the one line
    the user sees. ``node_args``: the arguments of nodes built later in this process (composition),
    whose parameter files are checked too. SIGINT/SIGTERM are left to the caller (rclpy installs
    no handlers).
    """

    from friction_ros.core.yaml_files import check_parameter_file

    args = list(sys.argv if args is None else args)
    try:
        for f in [f for a in (args, *node_args) for f in _parameter_files(a)]:
            if f is None:
                raise ParameterError("--params-file needs a file name")
            check_parameter_file(f)
    except ParameterError as exc:
        return str(exc)
    use_writer_profile()
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


def request_stop() -> None:
    """End this node process from inside the node, as SIGTERM would: :func:`run_node` leaves its
    loop, calls the node's ``on_shutdown()`` and returns its exit code."""
    stopping.STOP.set()


def start_process(
    args: list[str] | None = None,
    node_args: list[list[str]] = (),
    about: Any = None,
    parser: argparse.ArgumentParser | None = None,
) -> threading.Event | None:
    """Start a node process: ``--help``/``-h`` first (:func:`.node_help.exit_if_help`: the purpose
    and parameters of the node ``about``, its class or module, and the options of its ``parser``;
    exit code 0, nothing started), then SIGINT/SIGTERM handlers (:func:`.stopping.install`), then
    :func:`init_ros`.

    Returns the stop event (set by SIGINT, SIGTERM or :func:`request_stop`), or None after printing
    the one line that says why rclpy cannot start (the caller exits with code 2). A signal during
    :func:`init_ros` (a large parameter file being checked) ends the process at once with code 0
    (SystemExit). Our own signal handling (rclpy installs none) keeps the context alive until the
    node has zeroed its outputs.
    """
    exit_if_help(list(sys.argv if args is None else args), about, parser)
    stop = stopping.install()
    try:
        with interruptible(immediate=True):
            reason = init_ros(args, node_args)
    except StopRequested:
        rclpy.try_shutdown()
        raise SystemExit(0) from None
    if reason is not None:
        print(f"error: {reason}", file=sys.stderr)
        return None
    return stop


def run_node(factory: Callable[[], Node], args: list[str] | None = None) -> int:
    """Standard ``main()`` of a friction_ros node.

    ``--help``/``-h`` prints the node's purpose and parameters (the schema of ``factory``'s module:
    :mod:`.node_help`) and exits 0 without starting rclpy. Starts rclpy (:func:`init_ros`: a bad parameter file prints one line, exit code 2), builds the
    node (a ParameterError/ValueError there prints one clear line and exits with code 2: the node
    refuses to start), spins until Ctrl-C/SIGTERM, then calls the node's ``on_shutdown()`` (which
    must leave actuators safe: zero torque, drive idle) before destroying it. SIGINT/SIGTERM are
    handled from before rclpy starts: a stop that arrives while the node is being built ends it
    quietly once it is built (on_shutdown() runs, no KeyboardInterrupt traceback), or, if building
    takes longer than :data:`.stopping.ESCALATE_S` more, interrupts the constructor (exit code 0;
    a constructor commands no actuator before it returns).
    """
    stop = start_process(args, about=factory)
    if stop is None:
        return 2
    node = None
    try:
        with interruptible():
            node = factory()
    except StopRequested:
        rclpy.try_shutdown()
        return 0
    except (ParameterError, ValueError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        rclpy.try_shutdown()
        return 2
    return spin_until_stopped([node], stop)


#: how long a node that ends waits for its recorded topics' readers to confirm every message
DELIVERY_TIMEOUT_S = 15.0


def wait_delivered(publisher, what: str, logger, timeout_s: float = DELIVERY_TIMEOUT_S) -> bool:
    """Before a node that published a recorded stream exits: wait until every matched reader (the
    bag recorder) has confirmed every message (reliable QoS), so a reader that fell behind on a busy
    machine still gets the run's last messages from this writer's history. Fast DDS confirms on its
    periodic heartbeat, so this takes ~2-3 s with a reader in another process. Not confirmed in time:
    one warning naming the topic (the recording may miss its last messages), never silence."""
    from rclpy.duration import Duration

    if publisher.get_subscription_count() == 0:
        return True
    if publisher.wait_for_all_acked(Duration(seconds=timeout_s)):
        return True
    logger.warning(
        f"{what}: a reader had not confirmed the last messages after {timeout_s:g} s: a recording of "
        f"{what} may miss the end of the run"
    )
    return False


def exit_code_of(nodes: list[Node]) -> int:
    """The process exit code the nodes ask for: the first non-zero ``exit_code`` attribute (a node
    whose run has a result, e.g. identification_experiment's 3 or 4), else 0."""
    return next((c for c in (getattr(n, "exit_code", 0) for n in nodes) if c), 0)


def needs_message_info(nodes: list[Node]) -> bool:
    """Whether a node's callbacks take the middleware's message info (class attribute
    ``TAKES_MESSAGE_INFO``, e.g. bag_recorder's receive stamps): rclpy's EventsExecutor cannot
    serve them (SystemError for a two-argument callback, rclpy 7.1)."""
    return any(getattr(n, "TAKES_MESSAGE_INFO", False) for n in nodes)


def spin_until_stopped(nodes: list[Node], stop: threading.Event) -> int:
    """Spin ``nodes`` on one executor until ``stop`` (a real-time plant's deadline loop paces it),
    then call each node's ``on_shutdown()`` in the given order (torque commanders first) and destroy
    them; rclpy is shut down at the end. A callback still running :data:`.stopping.ESCALATE_S`
    after the stop signal is interrupted; ``on_shutdown()`` runs all the same. Returns
    :func:`exit_code_of` the nodes."""
    # Everything built so far (modules, nodes, core objects) lives for the whole run: keep it out of
    # the cyclic collector so a full collection does not scan it (multi-ms pauses in the loop).
    gc.collect()
    gc.freeze()
    executor = rclpy.executors.SingleThreadedExecutor() if needs_message_info(nodes) else make_executor()
    for node in nodes:
        executor.add_node(node)
    loops = [n.loop for n in nodes if isinstance(getattr(n, "loop", None), DeadlineLoop)]
    try:
        with interruptible():
            if loops:
                while not stop.is_set() and rclpy.ok():
                    loops[0].run_once(executor)
            while not stop.is_set() and rclpy.ok():
                # rclpy.ok() takes the context's lock: once per OK_CHECK_EVERY callbacks, not per callback
                for _ in range(OK_CHECK_EVERY):
                    executor.spin_once(timeout_sec=0.05)
                    if stop.is_set():
                        break
    except (rclpy.executors.ExternalShutdownException, StopRequested):
        pass
    finally:
        for node in nodes:
            shutdown = getattr(node, "on_shutdown", None)
            if shutdown is not None:
                try:
                    shutdown()
                except Exception as exc:  # last line of defence: report, still tear down
                    print(f"error during shutdown of {node.get_name()}: {exc}", file=sys.stderr)
        for node in nodes:
            executor.remove_node(node)
            node.destroy_node()
        rclpy.try_shutdown()
    return exit_code_of(nodes)


def log_events(logger, events) -> None:
    """Log the core's events ``(level, text)`` (levels of :mod:`friction_ros.core.joint_channel`:
    0 info, 1 warning, 2 error); one call site per severity (rclpy refuses a severity change at one)."""
    for level, text in events:
        if level >= 2:
            logger.error(text)
        elif level == 1:
            logger.warning(text)
        else:
            logger.info(text)
