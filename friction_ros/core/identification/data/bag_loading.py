"""One joint of a bag (JointState topic and experiment event markers) as a prepared record.

An indexed MCAP bag is read chunk by chunk (:mod:`~friction_ros.core.bag.mcap_stream`): only the
joint's stamps, position, velocity and effort are kept, so an hour-long log costs tens of bytes per
sample while it is read. SQLite3 bags and damaged MCAP files are read whole by
:func:`~friction_ros.core.bag.read_bag` (which recovers what it can and says what was lost).
"""

from __future__ import annotations

from pathlib import Path
from typing import NamedTuple

import numpy as np

from friction_ros.core.experiment.events import Event, event_joint_matches
from friction_ros.core.identification.data.records import ExcitationError, JointData, prepare


class _JointColumns(NamedTuple):
    """What the fit needs from a bag, as arrays (one entry per joint-state message)."""

    joint: str
    stamps: np.ndarray
    position: np.ndarray
    velocity: np.ndarray
    effort: np.ndarray | None
    current: np.ndarray | None
    current_t: np.ndarray | None
    events: list[Event]
    warnings: list[str]


def _no_topic(path, topic, have) -> ExcitationError:
    return ExcitationError(
        f"bag {path} has no topic {topic} (topics: {', '.join(sorted(have))}): record the joint states "
        "(sensor_msgs/JointState) with the identification experiment, or pass --topic"
    )


def _no_effort(path, joint, topic) -> ExcitationError:
    return ExcitationError(
        f"bag {path}: joint {joint!r} on {topic} has no effort: pass the motor current with "
        "--current-topic/--current-field plus --torque-constant and --gear-ratio"
    )


def _events(ev, joint: str) -> list[Event]:
    """This joint's (and unnamed) experiment events of an ExperimentEvent TopicData."""
    from friction_ros.core.bag import BagError

    try:
        et = ev.stamp
    except BagError:
        et = ev.time
    # on an arm each event names its joint in header.frame_id: keep this joint's (and unnamed) ones
    frames = ev["header.frame_id"] if "header.frame_id" in ev else None
    out = []
    for i in range(len(ev)):
        if frames is not None and not event_joint_matches(str(frames[i]), joint):
            continue
        out.append(
            Event(
                float(et[i]),
                str(ev["program"][i]),
                str(ev["segment"][i]),
                int(ev["index"][i]),
                int(ev["event"][i]),
                float(ev["target"][i]),
                str(ev["note"][i]),
            )
        )
    return out


def _raw_stamps(series) -> np.ndarray:
    """``header.stamp`` [s], or NaN where the type has none."""
    from friction_ros.core.bag import BagError

    try:
        return np.asarray(series.stamp, dtype=float)
    except BagError:
        return np.full(len(series.time), np.nan)


def _choose_stamps(stamps: np.ndarray, log_time: np.ndarray) -> np.ndarray:
    """The header stamps, or the log times when the log has no usable stamps at all (some not
    finite, or every one zero). Decided over the whole log: a first chunk holding only the initial
    state stamped 0 s of a simulated clock is not an unstamped log."""
    if not np.all(np.isfinite(stamps)) or np.all(stamps == 0):
        return log_time
    return stamps


def _stamps(series) -> np.ndarray:
    return _choose_stamps(_raw_stamps(series), series.time)


# ------------------------------------------------------------------------------------ reading
def _read_full(path: Path, topic, joint, events_topic, current_topic, current_field) -> _JointColumns:
    """The whole bag in memory (SQLite3 bags, damaged MCAP files)."""
    from friction_ros.core.bag import BagError, read_bag

    try:
        bag = read_bag(path, topics=None)
    except BagError as exc:
        raise ExcitationError(f"bag {path}: {exc}") from None
    # the fitter names the source before each warning: a warning about the file itself need not repeat it
    own = f"{path}: "
    warnings = [str(w).removeprefix(own) for w in getattr(bag, "warnings", [])]
    if getattr(bag, "truncated", False) and not warnings:
        warnings.append(f"bag {path} is truncated: the messages after the cut are lost")
    if topic not in bag:
        raise _no_topic(path, topic, bag.topics if hasattr(bag, "topics") else ["?"])
    js = bag[topic]
    names = js.joint_names
    if joint is None:
        if len(names) != 1:
            raise ExcitationError(
                f"bag {path}: topic {topic} has joints {', '.join(names)}: choose one with --joint"
            )
        joint = names[0]
    try:
        series = js.joint(joint)
    except BagError as exc:
        raise ExcitationError(str(exc)) from None
    events = _events(bag[events_topic], joint) if events_topic and events_topic in bag else []
    current = current_t = None
    effort = series.effort
    if current_field:
        ct = bag[current_topic] if current_topic else js
        current = ct[current_field]
        if current.ndim > 1:
            current = current[:, names.index(joint) if ct is js else 0]
        current_t = ct.time
        effort = None
    return _JointColumns(
        joint, _stamps(series), series.position, series.velocity, effort, current, current_t, events, warnings
    )


def _joined(parts: list):
    """One TopicData of a topic's per-chunk parts, in log-time order."""
    from friction_ros.core.bag import TopicData
    from friction_ros.core.bag.reader import _concat_columns

    log = np.concatenate([p.log_time for p in parts])
    pub = np.concatenate([p.publish_time for p in parts])
    fields = _concat_columns([p.fields for p in parts])
    order = np.argsort(log, kind="stable")
    return TopicData(parts[0].info, log[order], pub[order], {k: v[order] for k, v in fields.items()})


class _Growing:
    """Per-chunk arrays of one quantity, joined once at the end."""

    def __init__(self):
        self.parts: list[np.ndarray] = []

    def add(self, a) -> None:
        self.parts.append(np.asarray(a, dtype=float).copy())

    def join(self) -> np.ndarray:
        out = np.concatenate(self.parts) if self.parts else np.zeros(0)
        self.parts = []
        return out


def _read_streamed(path: Path, topic, joint, events_topic, current_topic, current_field) -> _JointColumns:
    """One chunk at a time: only this joint's columns are kept (NotStreamable: read it whole)."""
    from friction_ros.core.bag import BagError
    from friction_ros.core.bag.mcap_stream import NotStreamable, stream_topics
    from friction_ros.core.bag.reader import bag_files

    cols = {k: _Growing() for k in ("time", "stamp", "position", "velocity", "effort", "current")}
    cur_t, cur = _Growing(), _Growing()
    names: dict[str, None] = {}
    ev_parts = []
    found = [False]

    def on_joint_states(td) -> None:
        here = td.joint_names
        names.update(dict.fromkeys(here))
        name = joint if joint is not None else (here[0] if len(here) == 1 else None)
        if name is None or name not in here:
            series = None
        else:
            found[0] = True
            series = td.joint(name)
        nan = np.full(len(td), np.nan)
        cols["time"].add(td.time)
        cols["stamp"].add(_raw_stamps(series) if series is not None else td.time)
        for k in ("position", "velocity", "effort"):
            cols[k].add(getattr(series, k) if series is not None else nan)
        if current_field and not current_topic:
            c = td[current_field]
            if c.ndim > 1:
                c = c[:, here.index(name)] if name in here else nan
            cols["current"].add(c)

    def on_current(td) -> None:
        c = td[current_field]
        cur.add(c[:, 0] if c.ndim > 1 else c)
        cur_t.add(td.time)

    wanted = {topic: on_joint_states}
    if events_topic and events_topic != topic:
        wanted[events_topic] = ev_parts.append
    if current_field and current_topic:
        wanted[current_topic] = on_current
    _, files = bag_files(path)
    try:
        topics, warnings = stream_topics(files, wanted)
    except BagError as exc:
        raise ExcitationError(f"bag {path}: {exc}") from None
    if topic not in topics:
        raise _no_topic(path, topic, topics)
    if not names:  # no joint-state message at all: the whole-bag reader says so as it always has
        raise NotStreamable(f"{topic}: no messages")
    if joint is None:
        if len(names) != 1:
            raise ExcitationError(
                f"bag {path}: topic {topic} has joints {', '.join(names)}: choose one with --joint"
            )
        joint = next(iter(names))
    if not found[0]:
        raise ExcitationError(f"topic {topic}: no joint named {joint!r}: joints are {', '.join(names)}")
    if current_field and current_topic and current_topic not in topics:
        raise ExcitationError(
            f"bag {path}: no current topic {current_topic} (topics: {', '.join(sorted(topics))})"
        )
    time = cols["time"].join()
    order = np.argsort(time, kind="stable") if np.any(np.diff(time) < 0) else None
    out = {k: g.join() for k, g in cols.items()}
    if order is not None:  # chunks out of log-time order (several files, a reordered recording)
        out = {k: v[order] if v.size else v for k, v in out.items()}
    events = _events(_joined(ev_parts), joint) if ev_parts else []
    current = current_t = None
    effort = out["effort"]
    if current_field:
        current, current_t = (cur.join(), cur_t.join()) if current_topic else (out["current"], out["time"])
        effort = None
    stamps = _choose_stamps(out["stamp"], out["time"])
    return _JointColumns(
        joint, stamps, out["position"], out["velocity"], effort, current, current_t, events, warnings
    )


# ------------------------------------------------------------------------------------ loading
def load_bag(
    path,
    topic: str = "/joint_states",
    joint: str | None = None,
    *,
    events_topic: str | None = "/experiment_events",
    current_topic: str | None = None,
    current_field: str | None = None,
    torque_constant: float | None = None,
    gear_ratio: float = 1.0,
    velocity_window: float = 0.021,
    acceleration_window: float = 0.041,
    torque_delay: float = 0.0,
) -> JointData:
    """Read a joint of a JointState topic (and event markers) from a bag into JointData."""
    from friction_ros.core.bag import storage_of
    from friction_ros.core.bag.mcap_stream import NotStreamable

    path = Path(path)
    if not path.exists():
        raise ExcitationError(f"bag {path}: no such file or directory")
    args = (path, topic, joint, events_topic, current_topic, current_field)
    c = None
    if storage_of(path) == "mcap":
        try:
            c = _read_streamed(*args)
        except NotStreamable:
            c = None
    if c is None:
        c = _read_full(*args)
    if not current_field and not np.any(np.isfinite(c.effort)):
        raise _no_effort(path, c.joint, topic)
    data = prepare(
        c.stamps,
        c.position,
        c.velocity,
        c.effort,
        current=c.current,
        current_t=c.current_t,
        torque_constant=torque_constant,
        gear_ratio=gear_ratio,
        events=c.events,
        velocity_window=velocity_window,
        acceleration_window=acceleration_window,
        torque_delay=torque_delay,
        source=str(path),
    )
    data.meta["warnings"] = c.warnings + data.meta.get("warnings", [])
    return data
