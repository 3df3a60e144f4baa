"""Several drives on one bus: joint names, per-joint parameter values, run-time changes and the
:class:`DriveSet` a node steps once per control period.

A node's values are the defaults of every drive; with several drives (``joints``) each drive's
own ``<joint>.<key>`` (for the per-drive :data:`AXIS_KEYS`) goes on top.
"""

from __future__ import annotations

import dataclasses
import re
from collections.abc import Callable

from friction_ros.core.can.axis import DriveAxis, JointSample
from friction_ros.core.can.axis_config import AXIS_SCHEMA, AxisConfig, axis_config
from friction_ros.core.can.axis_health import AxisHealth
from friction_ros.core.can.faults import FAULT_BUS
from friction_ros.core.can.frame import Frame
from friction_ros.core.config import Field
from friction_ros.core.joint_type import JOINT_TYPES, joint_schema
from friction_ros.core.validation import ParameterError

JOINT_NAME = re.compile(r"[A-Za-z][A-Za-z0-9_]*\Z")

#: per-drive parameters when a node runs several drives (``joints``): ``<joint>.<key>``
AXIS_KEYS = (
    "node_id",
    "mit.master_id",
    "joint_type",
    "lead",
    "gear_ratio",
    "torque_constant",
    "direction",
    "zero_offset",
    "torque_limit",
    "current_limit",
    "velocity_limit",
)


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


def axis_param_specs(joints: list[str], v: dict, joint_types: dict[str, str] | None = None) -> list[Field]:
    """Per-joint parameters ``<joint>.<key>`` for :data:`AXIS_KEYS`, defaulting to the node-level
    values ``v``, in the units of each joint's type (``joint_types``; default: ``v["joint_type"]``)."""
    by = {t: dict(joint_schema(AXIS_SCHEMA, t).fields()) for t in JOINT_TYPES}
    types = {j: (joint_types or {}).get(j, v.get("joint_type", "revolute")) for j in joints}
    return [
        dataclasses.replace(by[types[j]][k], name=f"{j}.{k}", default=v[k], doc=f"{j}: {by[types[j]][k].doc}")
        for j in joints
        for k in AXIS_KEYS
    ]


class AxisPort:
    """One drive of a node: its joint, the :class:`DriveAxis`, its parameter values, its health
    report and the fault flags of its last period."""

    def __init__(self, values: dict):
        self.values = values
        self.joint = values["joint_name"]
        self.axis = DriveAxis(axis_config(values, 1.0 / values["control_period"]))
        self.health = AxisHealth()
        self.flags = 0
        self.label = f"drive '{self.joint}' (id {values['node_id']})"


class DriveSet:
    """The drives of one node on one bus (``values``: each drive's parameter values, from
    :func:`axis_values`; ``multi``: the node names its drives with ``joints``). Enabling, faults of
    the bus and safe stops act on all of them; each keeps its own safety state."""

    def __init__(self, values: list[dict], multi: bool):
        self.ports = [AxisPort(v) for v in values]
        self.axes = [p.axis for p in self.ports]
        self.joints = [p.joint for p in self.ports]
        self.multi = multi
        check_distinct_ids(self.joints, [a.cfg for a in self.axes])

    def describe(self) -> str:
        """``'shoulder' (id 1), 'elbow' (id 2)``: the joints and node ids, for the start-up line."""
        return ", ".join(f"'{p.joint}' (id {p.axis.cfg.node_id})" for p in self.ports)

    def cycle(self, now: float) -> tuple[list[Frame], list[JointSample | None], list[tuple[str, str]]]:
        """One control period of every drive (:meth:`DriveAxis.cycle`): the frames to send, each
        drive's joint sample (None: no fresh telemetry) and the fault lines to log as
        ``(level, "drive '<joint>' (id N): text")``."""
        frames: list[Frame] = []
        samples: list[JointSample | None] = []
        lines: list[tuple[str, str]] = []
        for port in self.ports:
            res = port.axis.cycle(now)
            port.flags = res.flags
            frames += res.frames
            samples.append(res.sample)
            if res.events:
                lines += [(ev.level, f"{port.label}: {ev.text}") for ev in res.events]
        return frames, samples, lines

    def send_failed(self) -> None:
        """The period's frames did not all leave: every drive's flags carry the bus fault."""
        for port in self.ports:
            port.flags |= FAULT_BUS

    def request_enable(self) -> None:
        for a in self.axes:
            a.request_enable()

    def disable_frames(self) -> list[Frame]:
        """Disable every drive (zero torque, idle / exit motor mode): the frames to send."""
        return [f for a in self.axes for f in a.request_disable()]

    def shutdown_frames(self) -> list[Frame]:
        """Frames that leave every drive safe; marks them disabled."""
        return [f for a in self.axes for f in a.shutdown_frames()]

    def fail(self, reason: str) -> list[Frame]:
        """An internal error of the adapter: a latched fault on every drive; the frames that leave
        them safe."""
        for a in self.axes:
            a.report_bus_fault(reason)
        return self.shutdown_frames()

    def reconfigure(self, changes: dict) -> dict:
        """A run-time parameter change (:func:`changed_values`): every affected drive's config is
        built first (ParameterError: nothing changes), then swapped in. Returns the node-level part."""
        values = [p.values for p in self.ports]
        new_values, shared = changed_values(self.joints, values, changes, AXIS_KEYS, self.multi)
        configs = [axis_config(vals, 1.0 / vals["control_period"]) for vals in new_values]
        for port, vals, cfg in zip(self.ports, new_values, configs):
            with port.axis._lock:
                port.axis.cfg = cfg
            port.values = vals
        return shared

    def health(self, now: float) -> tuple[int, str, dict]:
        """Diagnostics status of the drives (:meth:`AxisHealth.report`): one drive's as is; several:
        the worst level, ``"<joint>: message"`` joined by '; ', values named ``<joint>.<key>``."""
        statuses = [p.health.report(p.axis, p.flags, now) for p in self.ports]
        if len(statuses) == 1:
            return statuses[0]
        level = max(s[0] for s in statuses)
        message = "; ".join(f"{p.joint}: {s[1]}" for p, s in zip(self.ports, statuses))
        values = {f"{p.joint}.{k}": v for p, s in zip(self.ports, statuses) for k, v in s[2].items()}
        return level, message, values
