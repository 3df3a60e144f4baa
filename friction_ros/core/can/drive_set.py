"""Several drives on one bus: joint names, per-joint parameter values and run-time changes.

A node's values are the defaults of every drive; with several drives (``joints``) each drive's
own ``<joint>.<key>`` (for the per-drive ``keys``) goes on top.
"""

from __future__ import annotations

import re
from collections.abc import Callable
from typing import TYPE_CHECKING

from friction_ros.core.can.axis_config import AxisConfig
from friction_ros.core.validation import ParameterError

if TYPE_CHECKING:
    from friction_ros.core.can.axis import DriveAxis

JOINT_NAME = re.compile(r"[A-Za-z][A-Za-z0-9_]*\Z")


def check_joint_names(joints: list[str], reserved: set[str]) -> None:
    """Joint names that can prefix parameters: letters, digits, '_'; none twice, none in ``reserved``."""
    for i, j in enumerate(joints):
        if not JOINT_NAME.match(j):
            raise ParameterError(
                f"joints[{i}] = {j!r} is not allowed: must start with a letter and hold only letters, "
                "digits and '_' (it prefixes the per-joint parameters, e.g. <joint>.node_id)"
            )
        if j in reserved:
            raise ParameterError(f"joints[{i}] = {j!r} clashes with the parameter '{j}': rename the joint")
        if j in joints[:i]:
            raise ParameterError(f"joints[{i}] = {j!r} appears twice: joint names must differ")


def axis_values(joints: list[str], v: dict, per_joint: dict, keys: tuple[str, ...]) -> list[dict]:
    """Parameter values of every drive: the node's ``v``, with the joint's own ``<joint>.<key>`` on top."""
    if not joints:
        return [dict(v)]
    return [{**v, "joint_name": j, **{k: per_joint[f"{j}.{k}"] for k in keys}} for j in joints]


def check_distinct_ids(joints: list[str], configs: list[AxisConfig]) -> None:
    ids = [c.node_id for c in configs]
    if len(set(ids)) != len(ids):
        given = ", ".join(f"{j}.node_id = {c.node_id}" for j, c in zip(joints, configs))
        raise ParameterError(f"node ids must differ between the joints on one bus: {given}")


def changed_values(
    joints: list[str], values: list[dict], changes: dict, keys: tuple[str, ...], multi: bool
) -> tuple[list[dict], dict]:
    """A run-time change: ``(new values of every drive, the node-level part of changes)``.

    With several drives (``multi``) a per-drive key must be changed per joint (``<joint>.<key>``);
    a node-level one raises ParameterError naming the parameter to set instead.
    """
    shared = {k: v for k, v in changes.items() if "." not in k or k.split(".", 1)[0] not in joints}
    if multi:
        per_axis = [k for k in shared if k in keys]
        if per_axis:
            raise ParameterError(
                f"{per_axis[0]} applies per joint with several drives: set <joint>.{per_axis[0]} "
                f"(joints: {', '.join(joints)})"
            )
    new_values = []
    for joint, old in zip(joints, values):
        vals = {**old, **shared}
        for k, val in changes.items():
            if k.startswith(joint + ".") and multi:
                vals[k[len(joint) + 1 :]] = val
        new_values.append(vals)
    return new_values, shared


def frame_router(axes: list[DriveAxis]) -> Callable[[int, bytes], DriveAxis]:
    """Received frame (arbitration id, data) -> the axis it belongs to, for several drives on one bus.

    The protocol's :meth:`~friction_ros.core.can.protocol.DriveProtocol.route_key` names the drive
    (ODrive CANSimple: node id = arbitration id >> 5; MIT: a reply's first data byte is the motor id).
    With one axis, or for a frame of no configured drive, the first axis: its decoder counts the
    frame as ignored or rejected, as a single-drive node does.
    """
    first = axes[0]
    if len(axes) == 1:
        return lambda arb_id, data: first
    by_key = {a.protocol.own_route_key: a for a in axes}
    key = first.protocol.route_key
    return lambda arb_id, data: by_key.get(key(arb_id, data), first)
