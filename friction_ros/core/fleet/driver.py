"""Fit a fleet's runs on Dask distributed and add their rows to the fleet table.

Each (run, joint) task (:mod:`.discovery`) is one Dask task running :func:`.run_fit.run_rows` on a
worker; this process writes each result as soon as it arrives as its own Parquet file of the
table's dataset folder (:func:`.table.write_part`, atomic). So:

* a (run, joint) whose rows are in the table is skipped (idempotent, resumable); one that failed
  is fitted again with ``refit_failed`` (its file replaced), one whose worker died always;
* a killed driver loses only the runs in flight, a killed worker only its own run: that run gets
  an error row saying so and the next run of the command fits it again;
* the table is the same for any number of workers (fits are seeded; rows sorted on reading).

Cluster: an embedded ``LocalCluster`` (processes, one thread each, ``NUMBA_NUM_THREADS=1`` in the
workers, as many workers as cores unless ``workers`` is given) or an existing scheduler
(``scheduler``: its address). Pure: no rclpy.
"""

from __future__ import annotations

import os
import resource
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

from friction_ros.core.fleet import table as fleet_table
from friction_ros.core.fleet.discovery import RunTask
from friction_ros.core.fleet.run_fit import error_rows, run_rows
from friction_ros.core.validation import ParameterError

KILLED = "the worker fitting this run died (killed or out of memory): run the command again to fit it"


@dataclass
class FleetResult:
    """What one ``fit_fleet`` did: tasks fitted, skipped (already in the table), failed (error rows)."""

    fitted: int = 0
    skipped: int = 0
    failed: int = 0
    seconds: float = 0.0
    workers: int = 0
    messages: list[str] = field(default_factory=list)
    #: per worker (address -> value): peak resident memory [MB] and CPU time [s] of its process
    worker_peak_mb: dict[str, float] = field(default_factory=dict)
    worker_cpu_s: dict[str, float] = field(default_factory=dict)


def worker_usage() -> tuple[float, float]:
    """(peak resident memory [MB], CPU time [s]) of the calling process (``getrusage``; Linux
    reports ``ru_maxrss`` in KiB)."""
    u = resource.getrusage(resource.RUSAGE_SELF)
    return u.ru_maxrss / 1024.0, u.ru_utime + u.ru_stime


def pending_tasks(tasks: list[RunTask], table_path, refit_failed: bool = False) -> tuple[list[RunTask], int]:
    """(tasks to fit, number skipped): a (run, joint) in the table is skipped unless its row says
    its worker died (or it failed and ``refit_failed``); a task whose run has no identity is never
    skipped (its sidecar may have been added since)."""
    t = fleet_table.read_table(table_path).select(["source_sha256", "joint", "error"]).to_pylist()
    done = {
        (r["source_sha256"], r["joint"])
        for r in t
        if not r["error"] or not (r["error"] == KILLED or refit_failed)
    }
    todo = [k for k in tasks if k.problem or k.key not in done]
    return todo, len(tasks) - len(todo)


def check_table_path(path) -> Path:
    """``path`` as the table's dataset folder; refused (ParameterError) when it is a file or a folder
    holding anything but the table's Parquet files (it is never a user's data folder)."""
    path = Path(path)
    if path.exists() and not path.is_dir():
        raise ParameterError(f"--table {path} is a file: must name the table's folder (created if missing)")
    if path.is_dir():
        other = [p.name for p in path.iterdir() if p.suffix != ".parquet" and not p.name.endswith(".tmp")]
        if other:
            raise ParameterError(
                f"--table {path} holds other files ({', '.join(sorted(other)[:3])}): "
                "choose a new folder or an existing fleet table"
            )
    return path


def _client(workers: int | None, scheduler: str | None):
    import dask
    from distributed import Client, LocalCluster

    if scheduler:
        try:
            return Client(scheduler, timeout="10s"), None
        except (OSError, TimeoutError) as exc:
            raise ParameterError(f"--scheduler {scheduler}: cannot connect ({exc})") from None
    n = workers or os.cpu_count() or 1
    # a dying worker's task is tried once more elsewhere (at most)
    retries = min(int(dask.config.get("distributed.scheduler.allowed-failures", 1)), 1)
    dask.config.set({"distributed.scheduler.allowed-failures": retries})
    cluster = LocalCluster(
        n_workers=n,
        threads_per_worker=1,
        processes=True,
        dashboard_address=None,
        silence_logs=50,
        env={"NUMBA_NUM_THREADS": "1", "OMP_NUM_THREADS": "1"},
    )
    return Client(cluster), cluster


def fit_fleet(
    tasks: list[RunTask],
    table_path,
    *,
    workers: int | None = None,
    scheduler: str | None = None,
    options: dict | None = None,
    refit_failed: bool = False,
    on_start: Callable[[int, int], None] | None = None,
    on_task: Callable[[RunTask, list[dict], float], None] | None = None,
) -> FleetResult:
    """Fit ``tasks`` not yet in the table at ``table_path`` (see module doc); ``options``:
    :data:`.run_fit.QUICK_OPTIONS` overrides; ``on_start(todo, skipped)`` once,
    ``on_task(task, rows, seconds)`` per written task."""
    table_path = check_table_path(table_path)
    t0 = time.perf_counter()
    todo, skipped = pending_tasks(tasks, table_path, refit_failed)
    out = FleetResult(skipped=skipped)
    if on_start:
        on_start(len(todo), skipped)
    for task in [k for k in todo if k.problem]:  # nothing to fit: its error row is written here
        _record(out, table_path, task, error_rows(task, task.problem), 0.0, on_task)
    todo = [k for k in todo if not k.problem]
    if not todo:
        out.seconds = time.perf_counter() - t0
        return out
    from distributed import as_completed
    from distributed.client import FutureCancelledError

    client, cluster = _client(workers, scheduler)
    try:
        out.workers = len(client.scheduler_info().get("workers", {}))
        # as many tasks in flight as worker threads: a worker holds one run, so one that dies
        # takes no other run with it
        slots = max(1, sum(w.get("nthreads", 1) for w in client.scheduler_info()["workers"].values()))
        queue, futures, running = list(enumerate(todo)), {}, as_completed()

        def submit() -> None:
            i, task = queue.pop(0)
            fut = client.submit(run_rows, task, options, pure=False, key=f"fleet-fit-{i}-{task.key[0][:16]}")
            futures[fut] = (task, time.perf_counter())
            running.add(fut)

        for _ in range(min(slots, len(queue))):
            submit()
        for fut in running:
            if queue:
                submit()
            task, started = futures.pop(fut)  # released: the worker may drop the result
            try:
                rows = fut.result()
            except FutureCancelledError:
                rows = error_rows(task, "cancelled")
            except Exception as exc:  # KilledWorker, a lost connection: the run alone is lost
                name = type(exc).__name__
                rows = error_rows(task, KILLED if name == "KilledWorker" else f"{name}: {exc}")
            _record(out, table_path, task, rows, time.perf_counter() - started, on_task)
        _usage(client, out)
    finally:
        client.close()
        if cluster is not None:
            cluster.close()
    out.seconds = time.perf_counter() - t0
    return out


def _usage(client, out: FleetResult) -> None:
    """Each worker's peak memory and CPU time, asked before the cluster closes (a worker that
    cannot answer is left out)."""
    try:
        usage = client.run(worker_usage)
    except Exception:  # noqa: BLE001 - a report only: never fails the fit
        return
    for addr, (mb, cpu) in sorted(usage.items()):
        out.worker_peak_mb[addr] = float(mb)
        out.worker_cpu_s[addr] = float(cpu)


def _record(
    out: FleetResult, table_path: Path, task: RunTask, rows: list[dict], seconds: float, on_task
) -> None:
    _write(table_path, task, rows)
    if any(r["error"] and not r["model"] for r in rows):
        out.failed += 1
    else:
        out.fitted += 1
    if on_task:
        on_task(task, rows, seconds)


def _write(table_path: Path, task: RunTask, rows: list[dict]) -> None:
    """One task's rows as its own file; a stale error file of the whole run (no joint) goes."""
    fleet_table.write_part(table_path, rows)
    if task.joint:
        stale = table_path / fleet_table.part_name(task.source_sha256, "")
        if stale.exists():
            stale.unlink()
