"""One entry point for every log a user may have: a ``.csv`` file or a rosbag2 bag (MCAP or SQLite3).

:func:`load_log` sends a ``.csv`` file to :func:`~friction_ros.core.identification.data.csv_loading.load_csv`
and anything else (rosbag2 directory, ``.mcap`` or ``.db3`` file) to
:func:`~friction_ros.core.identification.data.bag_loading.load_bag`; both return the same
:class:`~friction_ros.core.identification.data.records.JointData`.
"""

from __future__ import annotations

from pathlib import Path

from friction_ros.core.identification.data.records import JointData

#: bag options that have no meaning for a CSV log (they name topics/fields of a bag)
_BAG_ONLY = ("events_topic", "current_topic", "current_field")


def is_csv(path) -> bool:
    """True when ``path`` names a CSV log (by its ``.csv`` suffix, any case)."""
    return Path(path).suffix.lower() == ".csv"


def load_log(
    path,
    topic: str = "/joint_states",
    joint: str | None = None,
    *,
    columns: dict | None = None,
    time_scale: float = 1.0,
    **bag_options,
) -> JointData:
    """Load one joint from a CSV log or a bag into :class:`JointData`.

    ``columns`` (role -> column name) and ``time_scale`` [s per time unit] apply to CSV logs (a
    bag's record gets a warning that they were ignored); ``topic`` and the bag options
    (``events_topic``, ``current_topic``, ``current_field``) to bags. ``torque_constant``, ``gear_ratio``, ``velocity_window``,
    ``acceleration_window`` and ``torque_delay`` apply to both.
    """
    if is_csv(path):
        from friction_ros.core.identification.data.csv_loading import load_csv

        opts = {k: v for k, v in bag_options.items() if k not in _BAG_ONLY}
        return load_csv(path, joint, columns, time_scale=time_scale, **opts)
    from friction_ros.core.identification.data.bag_loading import load_bag

    data = load_bag(path, topic, joint, **bag_options)
    ignored = [n for n, used in (("columns", bool(columns)), ("time_scale", time_scale != 1.0)) if used]
    if ignored:
        data.meta["warnings"] = [
            f"{path}: {' and '.join(ignored)} apply to .csv logs only: ignored for this bag"
        ] + data.meta.get("warnings", [])
    return data
