"""One joint of a bag (JointState topic and experiment event markers) as a prepared record."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from friction_ros.core.experiment.events import Event, event_joint_matches
from friction_ros.core.identification.records import ExcitationError, JointData, prepare


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
    from friction_ros.core.bag import BagError, read_bag

    path = Path(path)
    if not path.exists():
        raise ExcitationError(f"bag {path}: no such file or directory")
    try:
        bag = read_bag(path, topics=None)
    except BagError as exc:
        raise ExcitationError(f"bag {path}: {exc}") from None
    # the fitter names the source before each warning: a warning about the file itself need not repeat it
    own = f"{path}: "
    bag_warnings = [str(w).removeprefix(own) for w in getattr(bag, "warnings", [])]
    if getattr(bag, "truncated", False) and not bag_warnings:
        bag_warnings.append(f"bag {path} is truncated: the messages after the cut are lost")
    if topic not in bag:
        have = ", ".join(sorted(bag.topics)) if hasattr(bag, "topics") else "?"
        raise ExcitationError(
            f"bag {path} has no topic {topic} (topics: {have}): record the joint states "
            "(sensor_msgs/JointState) with the identification experiment, or pass --topic"
        )
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
    try:
        stamps = series.stamp
    except BagError:
        stamps = series.time
    if not np.all(np.isfinite(stamps)) or np.all(stamps == 0):
        stamps = series.time
    events = []
    if events_topic and events_topic in bag:
        ev = bag[events_topic]
        try:
            et = ev.stamp
        except BagError:
            et = ev.time
        # on an arm each event names its joint in header.frame_id: keep this joint's (and unnamed) ones
        frames = ev["header.frame_id"] if "header.frame_id" in ev else None
        for i in range(len(ev)):
            if frames is not None and not event_joint_matches(str(frames[i]), joint):
                continue
            events.append(
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
    current = current_t = None
    effort = series.effort
    if current_field:
        ct = bag[current_topic] if current_topic else js
        current = ct[current_field]
        if current.ndim > 1:
            col = names.index(joint) if ct is js else 0
            current = current[:, col]
        current_t = ct.time
        effort = None
    elif not np.any(np.isfinite(effort)):
        raise ExcitationError(
            f"bag {path}: joint {joint!r} on {topic} has no effort: pass the motor current with "
            "--current-topic/--current-field plus --torque-constant and --gear-ratio"
        )
    data = prepare(
        stamps,
        series.position,
        series.velocity,
        effort,
        current=current,
        current_t=current_t,
        torque_constant=torque_constant,
        gear_ratio=gear_ratio,
        events=events,
        velocity_window=velocity_window,
        acceleration_window=acceleration_window,
        torque_delay=torque_delay,
        source=str(path),
    )
    data.meta["warnings"] = bag_warnings + data.meta.get("warnings", [])
    return data
