"""The fleet table: one row per (run, joint, model), stored as Parquet (pyarrow).

Storage: ``--table OUT.parquet`` names a *dataset folder* of Parquet files, one file per fitted
(run, joint) written atomically (temporary file + rename), so a killed fit loses only the runs in
flight and never leaves a half-written table. :func:`read_table` reads such a folder or a single
Parquet file (e.g. one written by :func:`write_table`) and returns the rows sorted by
:data:`SORT_KEYS`. A (run, joint) is identified by ``(source_sha256, joint)`` (:data:`RUN_KEY`).

Units follow the joint (REP-103): ``effort_unit`` is ``N*m`` on a revolute joint, ``N`` on a
prismatic one; ``validation_rms`` and ``load_rms`` are in that unit, ``speed_rms`` in rad/s or m/s.
``fitted_at`` is the only wall-clock column (:data:`WALL_CLOCK_COLUMNS`): two fits of the same
inputs give equal tables once it is dropped.
"""

from __future__ import annotations

import json
import os
import tempfile
from pathlib import Path

import pyarrow as pa
import pyarrow.parquet as pq

_TS = pa.timestamp("us", tz="UTC")

#: the fleet table's schema: the one contract between the fitting and the trend side
FLEET_SCHEMA = pa.schema(
    [
        ("robot", pa.string()),
        ("joint", pa.string()),
        ("run_time", _TS),  # start of the run, UTC
        ("model", pa.string()),
        ("recommended", pa.bool_()),  # the model friction-fit recommends for this run
        ("coef_names", pa.list_(pa.string())),
        ("coef_values", pa.list_(pa.float64())),  # SI, units of the joint (friction-fit's summary)
        ("coef_stderr", pa.list_(pa.float64())),  # NaN = not determined
        ("joint_type", pa.string()),  # revolute | prismatic
        ("effort_unit", pa.string()),  # N*m | N
        ("validation_rms", pa.float64()),  # [effort_unit]
        ("validation_nmse_percent", pa.float64()),  # [%]
        ("explains", pa.string()),  # verdict text: what the model explains of the data
        ("compensate", pa.bool_()),  # the verdict allows compensating with this model
        ("verdict", pa.string()),
        ("error", pa.string()),  # '' when fitted, else why not
        ("temperature_mean", pa.float64()),  # [degC], NaN when the run has none
        ("temperature_min", pa.float64()),  # [degC]
        ("temperature_max", pa.float64()),  # [degC]
        ("load_rms", pa.float64()),  # RMS of the measured effort of the run [effort_unit]
        ("speed_rms", pa.float64()),  # RMS of the velocity of the run [rad/s or m/s]
        ("samples", pa.int64()),
        ("duration_s", pa.float64()),  # [s]
        ("software_version", pa.string()),  # friction_ros version that fitted the row
        ("source_path", pa.string()),  # the run's file or bag as given to the fit
        ("source_sha256", pa.string()),  # of the run's file(s): the identity of the run
        ("fitted_at", _TS),  # wall clock of the fit, UTC (the one non-deterministic column)
    ]
)

#: (source, joint): a run already in the table under this key is not fitted again
RUN_KEY = ("source_sha256", "joint")
#: the deterministic row order of every table read or written
SORT_KEYS = ("robot", "joint", "run_time", "source_sha256", "model")
#: columns that differ between two fits of the same inputs: leave them out of equality tests
WALL_CLOCK_COLUMNS = ("fitted_at",)


def empty_table() -> pa.Table:
    """A table with :data:`FLEET_SCHEMA` and no rows."""
    return FLEET_SCHEMA.empty_table()


def rows_to_table(rows: list[dict]) -> pa.Table:
    """``rows`` (dicts with every column of :data:`FLEET_SCHEMA`) as a table, sorted."""
    missing = [n for n in FLEET_SCHEMA.names if rows and n not in rows[0]]
    if missing:
        raise ValueError(f"fleet row lacks column(s) {', '.join(missing)}")
    return sort_table(pa.Table.from_pylist(rows, schema=FLEET_SCHEMA))


def sort_table(table: pa.Table) -> pa.Table:
    """``table`` in the order of :data:`SORT_KEYS` (the same whatever order rows were written)."""
    return table.sort_by([(k, "ascending") for k in SORT_KEYS])


def read_table(path) -> pa.Table:
    """The fleet table at ``path`` (a dataset folder or one Parquet file), sorted; empty with
    :data:`FLEET_SCHEMA` when ``path`` does not exist yet. Temporary files of writes in flight
    (``.*.tmp``) are not read."""
    path = Path(path)
    if not path.exists():
        return empty_table()
    if path.is_file():
        return sort_table(pq.read_table(path, schema=FLEET_SCHEMA))
    parts = sorted(p for p in path.glob("*.parquet") if not p.name.startswith("."))
    if not parts:
        return empty_table()
    tables = [pq.read_table(p, schema=FLEET_SCHEMA) for p in parts]
    return sort_table(pa.concat_tables(tables))


def done_keys(path) -> set[tuple[str, str]]:
    """The ``(source_sha256, joint)`` of every (run, joint) already in the table at ``path``."""
    t = read_table(path).select(list(RUN_KEY))
    return set(zip(t.column(0).to_pylist(), t.column(1).to_pylist(), strict=True))


def part_name(source_sha256: str, joint: str) -> str:
    """File name of one (run, joint) in a dataset folder: ``<sha256[:24]>-<joint>.parquet``."""
    safe = "".join(c if c.isalnum() or c in "-_" else "_" for c in joint)
    return f"{source_sha256[:24]}-{safe}.parquet"


def write_part(folder, rows: list[dict]) -> Path:
    """Write the rows of one (run, joint) into dataset ``folder`` atomically; returns the file.

    The file appears complete or not at all (written to a hidden temporary file, then renamed).
    """
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    table = rows_to_table(rows)
    first = rows[0]
    target = folder / part_name(first["source_sha256"], first["joint"])
    fd, tmp = tempfile.mkstemp(prefix=".", suffix=".tmp", dir=folder)
    os.close(fd)
    try:
        pq.write_table(table, tmp)
        os.replace(tmp, target)
    finally:
        if os.path.exists(tmp):
            os.unlink(tmp)
    return target


def write_table(table: pa.Table, path) -> Path:
    """Write ``table`` (sorted) as one Parquet file at ``path``, atomically."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    os.close(fd)
    try:
        pq.write_table(sort_table(table.cast(FLEET_SCHEMA)), tmp)
        os.replace(tmp, path)
    finally:
        if os.path.exists(tmp):
            os.unlink(tmp)
    return path


def comparable(table: pa.Table) -> pa.Table:
    """``table`` sorted and without :data:`WALL_CLOCK_COLUMNS`: equal for equal inputs."""
    return sort_table(table).drop_columns([c for c in WALL_CLOCK_COLUMNS if c in table.column_names])


def same_rows(a: pa.Table, b: pa.Table) -> bool:
    """True when ``a`` and ``b`` hold the same rows but for :data:`WALL_CLOCK_COLUMNS` (NaN equal to NaN)."""

    def text(t: pa.Table) -> str:
        return json.dumps(comparable(t).to_pylist(), default=str, sort_keys=True)

    return text(a) == text(b)
