"""The plant_simulator's parameters: its own fields, ``joints`` and the preset sections (open: the
keys of :data:`friction_ros.core.plant.params.PLANT_SCHEMA`, on top of the preset)."""

from __future__ import annotations

from friction_ros.core.config import Field, Schema
from friction_ros.core.control_period import control_period_field
from friction_ros.core.input_gate import PLAUSIBLE_EFFORT
from friction_ros.core.joint_type import JOINT_TYPE_FIELD
from friction_ros.core.plant.multi_joint import PRESET_SECTIONS
from friction_ros.nodes.parameters import SCHEDULING

NODE_FIELDS = [
    Field(
        "preset",
        "abb_m19s",
        "plant preset: a name in params/ (abb_m19s, seed002_x ...), a YAML path, or '' (the plant.* / friction_*.* parameters are the whole plant)",
        read_only=True,
    ),
    Field(
        "presets",
        [],
        "one plant preset per joint, in the order of joints (empty: every joint uses preset)",
        kind=str,
        read_only=True,
    ),
    Field("description", "", "free text describing the preset", read_only=True),
    Field(
        "joint_name",
        "joint1",
        "joint name used in joint_states and expected in joint_commands",
        read_only=True,
    ),
    Field(
        "mode",
        "realtime",
        "realtime: wall-clock loop; lockstep: one period per command + /clock",
        choices=("realtime", "lockstep"),
        read_only=True,
    ),
    JOINT_TYPE_FIELD,
    control_period_field("control period (plant step per state)"),
    Field("initial_position", 0.0, "joint position at start", lo=-1e6, hi=1e6, unit="rad", read_only=True),
    Field(
        "command_timeout",
        0.1,
        "realtime: zero torque when no command arrived for this long",
        lo=0.0,
        hi=60.0,
        unit="s",
    ),
    Field(
        "max_effort",
        PLAUSIBLE_EFFORT,
        "plausibility bound: a commanded |effort| above it is rejected like a NaN (zero torque, logged)",
        lo=1e-9,
        unit="N*m",
    ),
    Field(
        "log_period",
        1.0,
        "at most one log line per command rejection reason per this period",
        lo=0.0,
        unit="s",
        read_only=True,
    ),
    Field(
        "resend_period",
        0.2,
        "lockstep: re-publish the pending state after this wall time",
        lo=0.005,
        hi=60.0,
        unit="s",
    ),
    Field(
        "clock_period",
        0.01,
        "lockstep: publish /clock every this much simulated time (0: every period)",
        lo=0.0,
        hi=1.0,
        unit="s",
        read_only=True,
    ),
    Field(
        "wait_for_subscribers",
        0,
        "lockstep: publish the first state only once joint_states has this many subscribers (the "
        "controllers, a recorder, a monitor), so that each of them gets the run from its first "
        "period whatever the discovery takes (0: at once)",
        lo=0,
        hi=1000,
        read_only=True,
    ),
    Field(
        "exit_wait_for_readers",
        0.0,
        "lockstep: on exit, wait up to this long for every reader of joint_states (a recorder that "
        "fell behind) to confirm the last states (0: do not wait; friction-experiment sets it)",
        lo=0.0,
        hi=600.0,
        unit="s",
        read_only=True,
    ),
    Field(
        "stats_file",
        "",
        "write loop/latency statistics as JSON here on shutdown (benchmarks)",
        read_only=True,
    ),
    Field("diagnostics_period", 1.0, "period of the diagnostics status", lo=0.05, hi=60.0, unit="s"),
    Field(
        "stats_delay",
        0.0,
        "loop/latency statistics start this long (wall) after the first command (benchmarks skip start-up)",
        lo=0.0,
        hi=3600.0,
        unit="s",
        read_only=True,
    ),
]


JOINTS_FIELD = Field(
    "joints",
    [],
    "the joints of this plant, in joint_states order; per-joint plant.<joint>.<key> / "
    "friction_*.<joint>.<key> (empty: the one joint joint_name)",
    kind=str,
    read_only=True,
)


def parameter_schema(with_joints: bool = True) -> Schema:
    """The node's parameters; the preset sections take the keys given in the parameter file (on top
    of the preset; the plant's keys: :data:`friction_ros.core.plant.params.PLANT_SCHEMA`).
    ``joints`` is declared by :func:`~friction_ros.nodes.joint_parameters.declare_joints` (the node
    builds the schema without it)."""
    sections = [Schema(s, doc=f"preset {s} parameter", open=True, read_only=True) for s in PRESET_SECTIONS]
    joints = [JOINTS_FIELD] if with_joints else []
    return Schema("plant_simulator", [*joints, *NODE_FIELDS, *sections, *SCHEDULING])
