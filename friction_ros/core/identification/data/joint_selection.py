"""Which joints of a bag to fit (``friction-fit BAG --joint all`` or ``--joint j1,j3``): the joint
names on a topic (streamed from an indexed MCAP bag, else from the whole bag) and the requested ones,
checked against them; one clear error line for a CSV log, a missing topic or a bag lacking a joint."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

from friction_ros.core.joint_config import check_joint_list
from friction_ros.core.validation import ParameterError

ALL = "all"


def is_joint_list(text: str | None) -> bool:
    """True when ``--joint`` asks for several joints: ``all`` or a comma-separated list."""
    return text is not None and (text.strip() == ALL or "," in text)


def bag_joint_names(bag_paths: Sequence, topic: str) -> list[str]:
    """The joints on ``topic`` of the first bag (order of first appearance); every other bag must
    have them too. ParameterError (one line) for a CSV log, a missing topic or a bag that lacks one."""
    from friction_ros.core.bag import BagError, read_bag
    from friction_ros.core.identification.data.log_loading import is_csv

    names: list[str] | None = None
    for p in bag_paths:
        if is_csv(p):
            raise ParameterError(f"{p}: a CSV log holds one joint: --joint all or a list needs bags")
        if not Path(p).exists():
            raise ParameterError(f"bag {p}: no such file or directory")
        here = _streamed_joint_names(p, topic)
        if here is None:
            try:
                bag = read_bag(p, topics=None)
            except BagError as exc:
                raise ParameterError(f"bag {p}: {exc}") from None
            if topic not in bag:
                have = ", ".join(sorted(bag.topics)) if hasattr(bag, "topics") else "?"
                raise ParameterError(f"bag {p} has no topic {topic} (topics: {have}): pass --topic")
            try:
                here = bag[topic].joint_names
            except BagError as exc:
                raise ParameterError(f"bag {p}: {exc}") from None
        if names is None:
            names = list(here)
        elif missing := [j for j in names if j not in here]:
            raise ParameterError(
                f"bag {p} lacks joint(s) {', '.join(missing)} of {bag_paths[0]} on {topic} "
                f"(it has {', '.join(here) or 'none'}): fit those bags separately"
            )
    if not names:
        raise ParameterError(f"{bag_paths[0]}: topic {topic} names no joints")
    return names


def _streamed_joint_names(path, topic: str) -> list[str] | None:
    """The joints on ``topic`` of an indexed MCAP bag, read chunk by chunk (None: read it whole)."""
    from friction_ros.core.bag import BagError, storage_of
    from friction_ros.core.bag.mcap_stream import NotStreamable, stream_topics
    from friction_ros.core.bag.reader import bag_files

    if storage_of(path) != "mcap":
        return None
    seen: dict[str, None] = {}
    try:
        topics, _ = stream_topics(
            bag_files(path)[1], {topic: lambda td: seen.update(dict.fromkeys(td.joint_names))}
        )
    except (NotStreamable, BagError):
        return None
    return list(seen) if topic in topics else None


def requested_joints(text: str, available: Sequence[str]) -> list[str]:
    """``all`` -> ``available``; ``j1,j3`` -> those, each of which must be in ``available``. Joint
    names must be usable in parameter names (:func:`~friction_ros.core.joint_config.check_joint_list`)."""
    if text.strip() == ALL:
        joints = list(available)
    else:
        joints = [j.strip() for j in text.split(",")]
        if any(not j for j in joints):
            raise ParameterError(f"--joint {text!r}: an empty joint name: write e.g. --joint j1,j3")
        unknown = [j for j in joints if j not in available]
        if unknown:
            raise ParameterError(
                f"--joint {text!r}: unknown joint(s) {', '.join(unknown)}: the bag has {', '.join(available)}"
            )
    try:
        return check_joint_list(joints)
    except ParameterError as exc:
        raise ParameterError(f"--joint {text!r}: {exc}") from None
