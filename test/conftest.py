"""Shared test set-up: every pytest process (each xdist worker too) owns one ROS domain.

ROS graphs of different domains never see each other. The domain is deterministic: worker ``gwN``
of a run asks for ``base + N`` (``base`` = ``$FRICTION_TEST_DOMAIN_BASE``, default 10) and holds an
exclusive lock on ``<tmp>/friction_ros_test_domains/<id>.lock`` for its lifetime, so a second test
run on the same machine (another engineer's, another worktree's) takes the next free ids instead of
sharing one. Discovery stays on this machine (``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST``). Node
processes the tests start inherit the domain through the environment. The local CAN bus folder is
per domain too.
"""

from __future__ import annotations

import fcntl
import os
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
VENV_BIN = Path(sys.executable).parent

DOMAIN_MAX = 101  # the highest domain id whose DDS ports do not collide on Linux (ROS 2 docs)
_LOCK_DIR = Path(tempfile.gettempdir()) / "friction_ros_test_domains"
_held: list = []  # the open lock file: released when the process ends


def _worker_index() -> tuple[int, int]:
    """(this worker's index, number of workers); (0, 1) without xdist."""
    name = os.environ.get("PYTEST_XDIST_WORKER", "")
    count = int(os.environ.get("PYTEST_XDIST_WORKER_COUNT", "1") or 1)
    return (int(name[2:]), count) if name.startswith("gw") and name[2:].isdigit() else (0, 1)


def claim_domain(base: int, index: int, stride: int) -> int:
    """The first free domain id of ``base + index``, ``base + index + stride``, ... (wrapping to 1),
    locked for this process; every id is tried once."""
    _LOCK_DIR.mkdir(parents=True, exist_ok=True)
    first = base + index
    candidates = list(range(first, DOMAIN_MAX + 1, stride)) + list(range(1 + index % stride, first, stride))
    candidates += [d for d in range(1, DOMAIN_MAX + 1) if d not in candidates]
    for domain in candidates:
        f = open(_LOCK_DIR / f"{domain}.lock", "a")
        try:
            fcntl.flock(f, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            f.close()
            continue
        _held.append(f)
        return domain
    raise RuntimeError(f"no free ROS domain id in 1..{DOMAIN_MAX}: {_LOCK_DIR} holds a lock on each")


def release_domain(domain: int) -> None:
    """Give back a domain id :func:`claim_domain` locked for this process."""
    for f in list(_held):
        if f.name == str(_LOCK_DIR / f"{domain}.lock"):
            _held.remove(f)
            f.close()


def pytest_configure(config) -> None:
    if getattr(config.option, "numprocesses", None) and not hasattr(config, "workerinput"):
        return  # the xdist controller runs no test: its workers claim their own domains
    index, count = _worker_index()
    base = int(os.environ.get("FRICTION_TEST_DOMAIN_BASE", "10"))
    domain = claim_domain(base, index, max(count, 1))
    os.environ["ROS_DOMAIN_ID"] = str(domain)
    os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
    os.environ["FRICTION_CAN_DIR"] = str(Path(tempfile.gettempdir()) / "friction_can_tests" / f"d{domain}")
    if count > 1:
        pin_worker(index, count)


def pin_worker(index: int, count: int) -> None:
    """Each parallel worker (and every process it starts) on its own CPU, when there are enough;
    with more workers than CPUs, worker ``i`` on CPU ``i mod n`` (``make test`` runs two per CPU: one
    computes while the other waits for a graph's discovery or a wall-clock run).

    The ROS graphs of the tests run in lockstep or at 1 kHz: a message between two processes on one
    core costs about half the CPU of a wake-up across cores, and a worker's graph then never waits
    for the other worker's CPU-bound fit to yield its core. ``FRICTION_TEST_PIN=0`` turns it off."""
    if os.environ.get("FRICTION_TEST_PIN", "1") == "0" or not hasattr(os, "sched_setaffinity"):
        return
    cpus = sorted(os.sched_getaffinity(0))
    if len(cpus) < count:  # more workers than CPUs: worker i on CPU i mod n (one waits, one runs)
        os.sched_setaffinity(0, {cpus[index % len(cpus)]})
        return
    share = len(cpus) // count
    os.sched_setaffinity(0, set(cpus[index * share : (index + 1) * share]))


os.environ.setdefault("RCUTILS_COLORIZED_OUTPUT", "0")
os.environ.setdefault("MPLBACKEND", "Agg")


#: seconds per file on one worker of `make test` on a 2-core VM, for the files that take longest: the
#: order in which workers take them (longest first, so no long file starts last). Only the order
#: depends on it; a file missing here ranks by its markers.
FILE_SECONDS = {
    # realtime phase
    "test/test_demo_can.py": 100, "test/test_can_local_bus.py": 60, "test/test_can_e2e.py": 40,
    "test/test_arm_example.py": 28, "test/test_node_stop_ros.py": 18, "test/test_command_owner_ros.py": 9,
    # main phase (four workers on two CPUs)
    "test/test_demo_presets_xyz.py": 155, "test/test_demo_presets_other.py": 137, "test/test_demo.py": 140,
    "test/test_experiment_ros.py": 90, "test/test_identification_fit.py": 85, "test/test_demo_arm.py": 55,
    "test/test_foundation.py": 50,
}  # fmt: skip


def _rank(item) -> int:
    return 0 if item.get_closest_marker("slow") else 1 if item.get_closest_marker("ros") else 2


def pytest_collection_modifyitems(config, items) -> None:
    """Slowest files first (xdist hands a free worker the next whole file): the files of
    :data:`FILE_SECONDS`, longest first, then files with a ``slow`` test, then files with a ``ros``
    test, then the rest, each in collection order (stable sort)."""
    rank: dict[str, tuple[int, float]] = {}
    for item in items:
        path = item.nodeid.split("::", 1)[0]
        known = FILE_SECONDS.get(path)
        r = (-1, -known) if known is not None else (_rank(item), 0.0)
        rank[path] = min(rank.get(path, r), r)
    items.sort(key=lambda item: rank[item.nodeid.split("::", 1)[0]])
