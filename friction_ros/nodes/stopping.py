"""SIGINT/SIGTERM of a node process: the process ends within :data:`STOP_WITHIN_S` at any moment.

Phases of a node process and what a signal does in each (``python -m friction_ros.nodes.X`` or
the console script of a node):

* **importing** (rclpy, numba, the node's modules; ~0.5 s): nothing exists yet, the process exits
  at once with code 0 (:func:`install_early`, run by ``friction_ros/nodes/__init__.py``);
* **starting** (parameter-file check, ``rclpy.init``): the work is interrupted at once
  (:class:`StopRequested` is raised into it), rclpy is shut down, exit code 0;
* **building / spinning**: the stop event is set; the node finishes the callback it is in, leaves
  its loop and runs ``on_shutdown()`` (zero torque, drive idle). A callback or a constructor
  still busy after :data:`ESCALATE_S` (a first-run JIT compilation, a slow computation) is
  interrupted by :class:`StopRequested`, and ``on_shutdown()`` still runs;
* **shutting down**: the signal only sets the event; ``on_shutdown()`` is never interrupted.

:class:`StopRequested` derives from BaseException, so no ``except Exception`` on the way (the
subscription guard of :mod:`.safe_subscription` included) swallows it. It is raised only where
:func:`interruptible` allows it, and at most once per such section, so the code that catches it
(``run_node``, ``spin_until_stopped``) cannot itself be interrupted.
"""

from __future__ import annotations

import contextlib
import os
import signal
import sys
import threading

STOP_WITHIN_S = 1.0  # the promise: a node process ends this soon after SIGINT/SIGTERM
ESCALATE_S = 0.3  # a stop not seen by the loop within this is raised into the main thread

STOP = threading.Event()  # set by SIGINT, SIGTERM or request_stop(): the node process ends


class StopRequested(BaseException):
    """SIGINT/SIGTERM interrupted start-up or a callback that did not return in time."""


class _State:
    interruptible = False  # StopRequested may be raised into the main thread now
    immediate = False  # ... at once (starting), not after ESCALATE_S (building, spinning)
    overdue = False  # the escalation timer fired: the next signal raises
    timer: threading.Timer | None = None


def _escalate() -> None:
    """Timer thread: the main thread did not leave its work in time; signal it again so the handler
    raises StopRequested there (a real signal also interrupts a sleep)."""
    _State.overdue = True
    if _State.interruptible:
        with contextlib.suppress(ProcessLookupError, ValueError):
            signal.pthread_kill(threading.main_thread().ident, signal.SIGTERM)


def _on_signal(_signum, _frame) -> None:
    STOP.set()
    if not _State.interruptible:
        return
    if _State.immediate or _State.overdue:
        _State.interruptible = False
        raise StopRequested
    if _State.timer is None:
        _State.timer = threading.Timer(ESCALATE_S, _escalate)
        _State.timer.daemon = True
        _State.timer.start()


def install() -> threading.Event:
    """Handle SIGINT/SIGTERM in this process (main thread) as described in the module docstring;
    returns the (cleared) stop event."""
    STOP.clear()
    _State.interruptible = _State.immediate = _State.overdue = False
    _State.timer = None
    signal.signal(signal.SIGTERM, _on_signal)
    signal.signal(signal.SIGINT, _on_signal)
    return STOP


@contextlib.contextmanager
def interruptible(immediate: bool = False):
    """Inside: a signal raises :class:`StopRequested` here, at once (``immediate``) or if the work
    is still running :data:`ESCALATE_S` after the first signal. Catch it outside the ``with``."""
    _State.immediate = immediate
    _State.interruptible = True
    try:
        if STOP.is_set() and immediate:
            _State.interruptible = False
            raise StopRequested
        yield
    finally:
        _State.interruptible = False
        _State.immediate = False


def _exit_now(_signum, _frame) -> None:
    os._exit(0)


def install_early() -> None:
    """Exit at once (code 0) on SIGINT/SIGTERM while a node process imports its modules.

    Only when this process runs a node (``python -m friction_ros.nodes.X`` or a node's console
    script); a program that imports the nodes (tests, tools) keeps its own signal handling.
    """
    argv = list(getattr(sys, "orig_argv", []))
    target = argv[argv.index("-m") + 1] if "-m" in argv[:-1] else ""
    script = os.path.basename(sys.argv[0]) if sys.argv and sys.argv[0] else ""
    here = os.path.dirname(os.path.abspath(__file__))
    is_node = target.startswith("friction_ros.nodes.") or (
        script not in ("", "__init__.py")
        and not script.endswith(".py")
        and os.path.isfile(os.path.join(here, script + ".py"))
    )
    if is_node and threading.current_thread() is threading.main_thread():
        signal.signal(signal.SIGTERM, _exit_now)
        signal.signal(signal.SIGINT, _exit_now)
