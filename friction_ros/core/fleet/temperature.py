"""The temperature of a run: mean, min and max [degC] from a CSV column or a bag topic.

CSV: the column named by the user, else the first of :data:`TEMPERATURE_COLUMNS` in the header.
Bag: a ``sensor_msgs/msg/Temperature`` topic (its ``temperature`` field, degC), the one named by the
user or the first of that type in the bag. NaN when the run has none. Pure: no rclpy.
"""

from __future__ import annotations

import csv
import math
from pathlib import Path

import numpy as np

from friction_ros.core.validation import ParameterError

#: CSV columns read as the run's temperature [degC], first found wins
TEMPERATURE_COLUMNS = ("temperature", "drive_temperature", "winding_temperature")
TEMPERATURE_TYPE = "sensor_msgs/msg/Temperature"
NONE = (math.nan, math.nan, math.nan)


def stats(values) -> tuple[float, float, float]:
    """(mean, min, max) of the finite values; NaN each when there is none."""
    x = np.asarray(values, float)
    x = x[np.isfinite(x)]
    if x.size == 0:
        return NONE
    return float(np.mean(x)), float(np.min(x)), float(np.max(x))


def csv_temperature(path, column: str | None = None) -> tuple[float, float, float]:
    """(mean, min, max) of the temperature column of a CSV log (``#`` lines are comments).
    ``column`` given and missing: ParameterError naming the columns there are."""
    with Path(path).open(newline="", errors="replace") as f:
        rows = csv.reader(line for line in f if not line.lstrip().startswith("#"))
        header = [h.strip() for h in next(rows, [])]
        low = [h.lower() for h in header]
        if column is not None:
            if column not in header:
                raise ParameterError(
                    f"{path}: no temperature column {column!r}: columns are {', '.join(header)}"
                )
            j = header.index(column)
        else:
            j = next((low.index(c) for c in TEMPERATURE_COLUMNS if c in low), None)
            if j is None:
                return NONE
        values = []
        for row in rows:
            try:
                values.append(float(row[j]))
            except (IndexError, ValueError):
                continue
    return stats(values)


def bag_temperature(path, topic: str | None = None) -> tuple[float, float, float]:
    """(mean, min, max) of a bag's sensor_msgs/Temperature topic (``topic``, else the first of that
    type); ``topic`` given and missing: ParameterError naming the temperature topics there are."""
    from friction_ros.core.bag.reader import bag_info, read_bag

    info = bag_info(path).info
    found = sorted(t for t, i in info.items() if i.msgtype == TEMPERATURE_TYPE)
    if topic is not None and topic not in info:
        raise ParameterError(
            f"{path}: no temperature topic {topic!r}: {TEMPERATURE_TYPE} topics are {', '.join(found) or 'none'}"
        )
    topic = topic or (found[0] if found else None)
    if topic is None:
        return NONE
    data = read_bag(path, [topic])[topic]
    return stats(data.fields.get("temperature", []))


def run_temperature(path, column: str | None = None, topic: str | None = None) -> tuple[float, float, float]:
    """The run's (mean, min, max) temperature [degC] from a CSV column or a bag topic."""
    if Path(path).suffix.lower() == ".csv":
        return csv_temperature(path, column)
    return bag_temperature(path, topic)
