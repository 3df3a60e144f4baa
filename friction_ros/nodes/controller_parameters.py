"""The compensating_controller node's parameters (its own, the core controller's sections, the
input gate) and the build of one joint's controller from them (see
:mod:`friction_ros.nodes.compensating_controller`)."""

from __future__ import annotations

from friction_ros.core.config import Field, Schema
from friction_ros.core.control.controller import controller_from_ros_parameters
from friction_ros.core.control.controller_config import CONTROLLER_FIELDS, controller_parameter_schema
from friction_ros.core.control_period import control_period_field
from friction_ros.core.joint_config import JointNames, joint_errors
from friction_ros.core.joint_type import JOINT_TYPE_FIELD, units_of
from friction_ros.core.validation import ParameterError
from friction_ros.nodes.parameters import SCHEDULING, input_gate_schema

NODE_FIELDS = [
    Field("joint_name", "joint1", "joint to control (name in joint_states / joint_commands)", read_only=True),
    Field(
        "terms_file",
        "",
        "write every period's terms (controller_state fields) to this CSV file ('' = off)",
        read_only=True,
    ),
    JOINT_TYPE_FIELD,
    control_period_field("nominal control period (dt of the control law)"),
    Field("adopt_estimator_coefficients", False, "hot-swap the friction model with converged estimates"),
    Field(
        "state_timeout",
        0.05,
        "zero torque once no joint state came for this long (wall)",
        lo=0.001,
        hi=60.0,
        unit="s",
    ),
    Field("diagnostics_period", 1.0, "period of the diagnostics status", lo=0.05, hi=60.0, unit="s"),
    Field(
        "sum_base_command",
        False,
        "add-on (mode compensation_only): add the arm controller's command (base_command) and "
        "publish the sum as joint_commands",
        read_only=True,
    ),
]

#: keys ``gains.<joint>.<key>`` accepts besides the PID keys (ros2_controllers puts
#: feedforward_gain and u_clamp_max there too)
PER_JOINT_PLAIN_KEYS = (*(f.name for f in CONTROLLER_FIELDS), "adopt_estimator_coefficients", "joint_type")


def parameter_schema(given_section=lambda prefix: {}) -> Schema:
    """The node's parameters; ``given_section(prefix)``: keys given for a section (friction model
    and reference defaults apply only when none is given)."""
    return Schema(
        "compensating_controller",
        [
            *NODE_FIELDS,
            *controller_parameter_schema(
                friction_model=not given_section("friction"), reference=not given_section("reference")
            ),
            input_gate_schema(),
            *SCHEDULING,
        ],
    )


def build_controller(values: dict, layout, joint: str, overrides: dict, single: bool):
    """(controller, reference config) of one joint; errors name the joint's parameter as written
    (:class:`~friction_ros.core.joint_config.JointNames`; the node-level one after ``joint <name>:``
    when the value is shared)."""
    names = None if single else JointNames(layout, joint, overrides)
    with units_of(values.get("joint_type", "revolute")), joint_errors(names):
        ctrl, ref = controller_from_ros_parameters(values, names)
        if not ctrl.limits_given:
            raise ParameterError(
                "effort_limit is not set: give the joint's torque (force) limit, e.g. effort_limit: 2.5 "
                "(per joint gains.<joint>.effort_limit; or finite u_clamp_min/u_clamp_max): the plant "
                "preset's, the drive's torque_limit, or the one friction-fit writes"
            )
    return ctrl, ref
