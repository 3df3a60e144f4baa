"""``terms_file``: every control period's terms written by the controller itself, to a CSV file.

A subscriber of ``controller_state`` that falls behind (a busy machine, a slow reader) loses
messages once the publisher's history is full; the controller's own file cannot: one row per
computed period (a lockstep re-send of a duplicate state is not a new period), written through a
buffer and flushed when the node ends. Columns: ``stamp_ns``, ``joint``, the float fields of
friction_msgs/ControllerState (SI units) and ``compensation_fallback`` (1 once the compensation
watch switched compensation off). Used by ``friction-demo`` for figures that do not depend
on the machine's load.
"""

from __future__ import annotations

from friction_ros.core.wire import CONTROLLER_STATE_FLOATS

COLUMNS = ("stamp_ns", "joint", *CONTROLLER_STATE_FLOATS, "compensation_fallback")


class TermsFile:
    """Append one row per period; :meth:`close` flushes (called from the node's shutdown)."""

    def __init__(self, path: str):
        self._fh = open(path, "w", encoding="utf-8", buffering=1 << 20)  # noqa: SIM115 (closed in close)
        self._fh.write(",".join(COLUMNS) + "\n")

    def add(self, stamp_ns: int, joint: str, terms) -> None:
        values = ",".join(repr(float(getattr(terms, k))) for k in CONTROLLER_STATE_FLOATS)
        self._fh.write(f"{stamp_ns},{joint},{values},{int(terms.compensation_fallback)}\n")

    def close(self) -> None:
        if not self._fh.closed:
            self._fh.close()


def read_terms_file(path: str) -> dict[str, list]:
    """The columns of a terms file (``stamp_ns`` int, ``joint`` str, the others float)."""
    with open(path, encoding="utf-8") as fh:
        header = fh.readline().strip().split(",")
        cols: dict[str, list] = {k: [] for k in header}
        for line in fh:
            parts = line.rstrip("\n").split(",")
            if len(parts) != len(header):
                continue  # a row cut by an abrupt end
            for k, v in zip(header, parts):
                cols[k].append(int(v) if k == "stamp_ns" else v if k == "joint" else float(v))
    return cols
