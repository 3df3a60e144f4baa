"""The identification_experiment's parameters: its own fields, the arm's (``joints``) and the
excitation program's sections (defaults from ``profile``: :mod:`friction_ros.core.experiment.excitation_config`)."""

from __future__ import annotations

import copy
import dataclasses

from friction_ros.core.config import Field, Schema
from friction_ros.core.control_period import control_period_field
from friction_ros.core.experiment.arm import SEQUENCES
from friction_ros.core.experiment.excitation_config import DEFAULTS, PROFILES, SECTIONS, profile_defaults
from friction_ros.nodes.parameters import ParameterNode

NODE_FIELDS = [
    Field("joint_name", "joint1", "joint to excite (name in joint_states / joint_commands)", read_only=True),
    Field(
        "profile",
        "default",
        "program defaults: default (~2 min, ABB M19-S scale) or quick (~30 s, tests/demo)",
        choices=tuple(PROFILES),
        read_only=True,
    ),
    Field(
        "program",
        "sequence",
        "excitation program: plateaus, breakaway, random, chirp, presliding or sequence",
        choices=("plateaus", "breakaway", "random", "chirp", "presliding", "sequence"),
        read_only=True,
    ),
    Field(
        "sequence",
        list(DEFAULTS["sequence"]),
        "programs run by 'sequence', in order",
        read_only=True,
    ),
    Field(
        "gap",
        float(DEFAULTS["gap"]),
        "zero-torque pause between programs",
        lo=0.0,
        hi=60.0,
        unit="s",
        read_only=True,
    ),
    Field(
        "bias",
        float(DEFAULTS["bias"]),
        "torque added to every command of the program: holds a constant load such as gravity",
        lo=-1e6,
        hi=1e6,
        unit="N*m",
        read_only=True,
    ),
    control_period_field("nominal period of the joint states"),
    Field(
        "wait_for_subscribers",
        0,
        "start only once this many subscribers listen on experiment_events (the recorder)",
        lo=0,
        hi=100,
        read_only=True,
    ),
    Field("exit_when_done", True, "exit by itself when the program is over", read_only=True),
    Field(
        "end_tail",
        0.2,
        "joint time answered with zero torque after the program ends; later states are not answered, "
        "so a lockstep plant stops and the record ends on simulated time",
        lo=0.0,
        hi=60.0,
        unit="s",
        read_only=True,
    ),
    Field(
        "exit_delay", 0.5, "wall time between the end of the program and the exit", lo=0.0, hi=60.0, unit="s"
    ),
    Field(
        "progress_period",
        2.0,
        "log progress every this much wall time (0: never)",
        lo=0.0,
        hi=3600.0,
        unit="s",
    ),
    Field("diagnostics_period", 1.0, "period of the diagnostics status", lo=0.05, hi=60.0, unit="s"),
]
#: the node's parameters with ``joints`` (an arm); without ``joints`` they are not declared
ARM_FIELDS = [
    Field(
        "joint_sequence",
        SEQUENCES[0],
        "with joints: one_at_a_time (each joint's program in turn, the others held by a PD hold) or "
        "together (every joint's program at once)",
        choices=SEQUENCES,
        read_only=True,
    ),
    Field(
        "joint_gap",
        0.5,
        "with joints, one_at_a_time: time every joint is held between two joints' programs",
        lo=0.0,
        hi=60.0,
        unit="s",
        read_only=True,
    ),
    Field(
        "hold_p",
        0.0,
        "PD hold of a joint not being excited: position gain (0: the joint's velocity_loop.i, the "
        "tracking design's K_p)",
        lo=0.0,
        hi=1e9,
        unit="N*m/rad",
        read_only=True,
    ),
    Field(
        "hold_d",
        0.0,
        "PD hold: velocity gain (0: the joint's velocity_loop.p, the tracking design's K_d)",
        lo=0.0,
        hi=1e9,
        unit="N*m*s/rad",
        read_only=True,
    ),
]
#: node-level keys a joint may have its own value of, as ``gains.<joint>.<key>``
PER_JOINT_PLAIN_KEYS = ("program", "sequence", "gap", "bias", "hold_p", "hold_d")


def profile_of(node: ParameterNode) -> str:
    """The ``profile`` given to the node (its program defaults), ``default`` when none or unknown."""
    given = node.given_parameters.get("profile")
    return given.value if given is not None and given.value in PROFILES else "default"


def parameter_schema(profile: str = "default", arm: bool = False) -> Schema:
    """The node's parameters; program-level defaults follow the chosen ``profile``. ``arm``: with
    the parameters of an experiment on several joints (``joints``)."""
    base = profile_defaults(profile)
    fields = [
        dataclasses.replace(f, default=copy.deepcopy(base[f.name])) if f.name in ("sequence", "gap") else f
        for f in NODE_FIELDS
    ]
    sections = [Schema.from_defaults(s, base[s], f"{s} parameter", read_only=True) for s in SECTIONS]
    return Schema("identification_experiment", [*fields, *(ARM_FIELDS if arm else []), *sections])
