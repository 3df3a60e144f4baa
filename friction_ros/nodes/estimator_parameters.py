"""The friction_estimator node's parameters: its own, the estimator's
(:data:`~friction_ros.core.estimation.estimator.ESTIMATOR_SCHEMA`) and the input gate; per joint
in the layout of :mod:`friction_ros.core.joint_config` (see :mod:`friction_ros.nodes.friction_estimator`)."""

from __future__ import annotations

from friction_ros.core.config import Field, Names, Schema, prefixed
from friction_ros.core.control_period import control_period_field
from friction_ros.core.estimation.estimator import ESTIMATOR_SCHEMA
from friction_ros.core.joint_config import JointLayout, JointNames, joint_values
from friction_ros.core.joint_type import JOINT_TYPE_FIELD
from friction_ros.nodes.parameters import SCHEDULING, input_gate_schema

NODE_FIELDS = [
    Field(
        "joint_name",
        "joint1",
        "joint to estimate (name in joint_states); not used when joints is set",
        read_only=True,
    ),
    JOINT_TYPE_FIELD,
    control_period_field("nominal sample period (used when stamps do not advance)", hi=1.0),
    Field(
        "publish_every",
        10,
        "publish one estimate every N samples (every sample is still processed)",
        lo=1,
        hi=100000,
    ),
    Field("diagnostics_period", 1.0, "period of the diagnostics status", lo=0.05, hi=60.0, unit="s"),
]

#: the estimator's plain keys: per joint as ``gains.<joint>.<key>``
PLAIN_KEYS = tuple(name for name, item in ESTIMATOR_SCHEMA.items.items() if isinstance(item, Field)) + (
    "joint_type",
)


JOINTS_FIELD = Field(
    "joints",
    [],
    "the joints to estimate (names in joint_states); per-joint gains.<joint>.<key> (estimator keys), "
    "initial.<joint>.<coef>, lugre.<joint>.<key>, input_gate.<joint>.<key> (empty: the one joint "
    "joint_name)",
    kind=str,
    read_only=True,
)


def parameter_schema(with_joints: bool = True) -> Schema:
    """The node's parameters: ``joints``, its own, the estimator's (:data:`ESTIMATOR_SCHEMA`), the
    input gate. ``joints`` is declared by
    :func:`~friction_ros.nodes.joint_parameters.declare_joints` (the node builds the schema without it)."""
    joints = [JOINTS_FIELD] if with_joints else []
    return Schema(
        "friction_estimator",
        [*joints, *NODE_FIELDS, *ESTIMATOR_SCHEMA, input_gate_schema(), *SCHEDULING],
    )


def core_config(values: dict) -> dict:
    """The estimator's config (:data:`ESTIMATOR_SCHEMA` keys) from a joint's nested values."""
    return {k: values[k] for k in ESTIMATOR_SCHEMA.items if k in values}


def joint_config(node_values: dict, overrides: dict) -> dict:
    """One joint's nested values: node-level values with the joint's overrides (node-level flat
    names) on top; see the module docstring for ``initial`` / ``lugre``."""
    out = joint_values(node_values, overrides, REPLACED_BY)
    if "model" in overrides and overrides["model"] != node_values.get("model"):
        own = {k[len("initial.") :]: v for k, v in overrides.items() if k.startswith("initial.")}
        out["initial"] = joint_values({}, own)
    return out


#: the single-joint node's names of the estimator's keys: its ROS names (``forgetting_factor``)
NODE_NAMES: Names = prefixed("")
#: a per-joint section whose own ``model`` replaces the node-level section
REPLACED_BY = {"lugre": "model"}


def joint_names(layout: JointLayout | None, joint: str, overrides: dict) -> Names:
    """The ROS names of one joint's estimator keys (``gains.j3.forgetting_factor`` for its own
    value, ``forgetting_factor`` for the node-level one); the node's names without ``joints``."""
    return NODE_NAMES if layout is None else JointNames(layout, joint, overrides, REPLACED_BY)
