"""The compensating controller's configuration: its fields (:data:`CONTROLLER_FIELDS`, defaults,
units and meaning), the ROS parameter layout of the compensating_controller node
(:func:`controller_parameter_schema`) and its typed config (:func:`ros_controller_config`: the ROS
layout is the struct, as in ros2_controllers' generate_parameter_library). Every section's schema
lives beside the part it configures (``pid``: :data:`.pid.PID_SCHEMA`, ``compensation``:
:data:`.compensation.COMPENSATION_SCHEMA`, a scheme's ``SCHEMA`` ...); a config is validated and
typed here once, and :class:`~friction_ros.core.control.controller.CompensatingController` hands
each part its typed section. A dict in the core layout (``friction`` = how the model is applied
+ ``model``) is typed once by :func:`core_controller_config`.
"""

from __future__ import annotations

import copy
import math
from collections.abc import Mapping
from typing import Any

from friction_ros.core.config import Field, Names, Schema, TypedConfig, unflatten
from friction_ros.core.control.command_safety import PLAUSIBLE_GAIN
from friction_ros.core.control.compensation import COMPENSATION_DEFAULTS, COMPENSATION_SCHEMA
from friction_ros.core.control.limit_cycle import LIMIT_CYCLE_DEFAULTS
from friction_ros.core.control.pid import PID_DEFAULTS, PID_SCHEMA
from friction_ros.core.control.schemes import DNPF, Cascade, GainScheduling, SlidingMode
from friction_ros.core.friction.joint_load import JOINT_LOAD_SCHEMA
from friction_ros.core.friction.learned_residual import LEARNED_RESIDUAL_SCHEMA
from friction_ros.core.joint_type import joint_schema
from friction_ros.core.validation import ParameterError, check_keys

CONTROLLER_MODES = ("pid", "cascade", "dnpf", "gain_scheduling", "sliding_mode", "compensation_only")
VELOCITY_SOURCES = ("measured", "differentiated")

_INF = math.inf
#: The plain (not section) controller settings: default, meaning, range, unit.
CONTROLLER_FIELDS: tuple[Field, ...] = (
    Field(
        "mode",
        "pid",
        "controller mode: pid, cascade, dnpf, gain_scheduling, sliding_mode, or compensation_only "
        "(an add-on to the arm's own controller: only the friction and load compensation)",
        choices=CONTROLLER_MODES,
    ),
    Field(
        "compensation_scale",
        1.0,
        "compensation_only: scale of the compensation output (1: as identified, 0: off)",
        lo=0.0,
        hi=2.0,
    ),
    Field(
        "feedforward_gain",
        0.0,
        "velocity feedforward gain (command += gain * reference velocity)",
        lo=0.0,
        hi=PLAUSIBLE_GAIN,
        unit="N*m*s/rad",
    ),
    Field(
        "inertia",
        0.0,
        "J_hat for the inertia feedforward J_hat * reference acceleration",
        lo=0.0,
        hi=PLAUSIBLE_GAIN,
        unit="kg*m^2",
    ),
    Field(
        "load_feedforward",
        0.0,
        "constant torque added to the command: holds a known load such as gravity",
        unit="N*m",
    ),
    Field(
        "effort_limit",
        _INF,
        "the joint's torque (force) limit: every command is clamped to +-effort_limit; the node needs "
        "it (or finite u_clamp_max/min): the plant preset's, the drive's torque_limit or friction-fit's",
        lo=0.0,
        lo_open=True,
        unit="N*m",
        allow_inf=True,
    ),
    Field(
        "u_clamp_max", _INF, "upper torque limit (also bounded by effort_limit)", unit="N*m", allow_inf=True
    ),
    Field("u_clamp_min", -_INF, "lower torque limit (< u_clamp_max)", unit="N*m", allow_inf=True),
    Field(
        "position_min",
        -_INF,
        "lowest reference position allowed (references beyond are refused)",
        unit="rad",
        allow_inf=True,
    ),
    Field("position_max", _INF, "highest reference position allowed", unit="rad", allow_inf=True),
    Field(
        "velocity_limit",
        _INF,
        "largest |reference velocity| allowed",
        lo=0.0,
        lo_open=True,
        unit="rad/s",
        allow_inf=True,
    ),
    Field(
        "acceleration_limit",
        _INF,
        "largest |reference acceleration| allowed",
        lo=0.0,
        lo_open=True,
        unit="rad/s^2",
        allow_inf=True,
    ),
    Field("rate_limit", _INF, "torque rate limit", lo=0.0, lo_open=True, unit="N*m/s", allow_inf=True),
    Field(
        "velocity_source",
        "measured",
        "measured (joint_states velocity) or differentiated (filtered position difference)",
        choices=VELOCITY_SOURCES,
    ),
    Field("velocity_filter_time_constant", 0.0, "velocity filter time constant", lo=0.0, unit="s"),
    Field(
        "position_jump_limit",
        _INF,
        "reject position samples that jump more than this (lost encoder bits)",
        lo=0.0,
        lo_open=True,
        unit="rad",
        allow_inf=True,
    ),
    Field(
        "limit_cycle_detection",
        True,
        "switch friction compensation off (latched) when it causes a limit cycle",
    ),
    Field(
        "limit_cycle_min_frequency",
        LIMIT_CYCLE_DEFAULTS["min_frequency"],
        "limit cycle: lowest oscillation frequency that counts",
        lo=1.0,
        unit="Hz",
    ),
    Field(
        "limit_cycle_min_amplitude",
        LIMIT_CYCLE_DEFAULTS["min_amplitude"],
        "limit cycle: smallest error amplitude (RMS) that counts (also 4 encoder counts)",
        lo=0.0,
        unit="rad",
    ),
    Field(
        "limit_cycle_window",
        LIMIT_CYCLE_DEFAULTS["window"],
        "limit cycle: averaging time constant of the detector (window + hold <= 0.1 s)",
        lo=0.005,
        hi=1.0,
        unit="s",
    ),
    Field(
        "limit_cycle_hold",
        LIMIT_CYCLE_DEFAULTS["hold"],
        "limit cycle: how long the oscillation must hold before the fallback (window + hold <= 0.1 s)",
        lo=0.0,
        hi=1.0,
        unit="s",
    ),
)

#: Full default configuration (nested). Sections of modes that are not selected are ignored.
CONTROLLER_DEFAULTS: dict[str, Any] = {
    **{f.name: f.default for f in CONTROLLER_FIELDS},
    "pid": dict(PID_DEFAULTS),
    "friction": dict(COMPENSATION_DEFAULTS),
    "dnpf": dict(DNPF.DEFAULTS),
    "gain_scheduling": dict(GainScheduling.DEFAULTS),
    "cascade": dict(Cascade.DEFAULTS),
    "sliding_mode": dict(SlidingMode.DEFAULTS),
    # identified load, gravity and position-dependent friction (core/friction/joint_load.py):
    # defaults are all zero, i.e. no feedforward (core/control/load_compensation.py)
    "load": JOINT_LOAD_SCHEMA.defaults(),
    # learned residual map (core/friction/learned_residual.py): kind none = no residual
    "residual": LEARNED_RESIDUAL_SCHEMA.defaults(),
}
CONFIG_SECTIONS = (
    "pid",
    "friction",
    "dnpf",
    "gain_scheduling",
    "cascade",
    "sliding_mode",
    "load",
    "residual",
)
SCHEME_SECTIONS = ("pid", "dnpf", "gain_scheduling", "cascade", "sliding_mode")


def controller_parameter_schema(friction_model: bool = True, reference: bool = True) -> list[Field | Schema]:
    """The compensating_controller's ROS layout of the controller (see :func:`ros_controller_config`).

    Plain keys, one open section per scheme, ``compensation`` (how the model is applied),
    ``friction`` (the library model config: ``model`` + its coefficients), ``load`` (identified
    load, gravity and position-dependent friction: :data:`JOINT_LOAD_SCHEMA`), ``residual`` (the
    learned residual map: :data:`LEARNED_RESIDUAL_SCHEMA`) and ``reference`` (the built-in
    reference generator). ``friction_model`` / ``reference``: give ``friction.model``
    (``none``) and ``reference.type`` (``constant``) defaults (a parameter file that sets any key of
    the section brings its own).
    """
    items: list[Field | Schema] = list(CONTROLLER_FIELDS)
    items += [PID_SCHEMA, DNPF.SCHEMA, GainScheduling.SCHEMA, Cascade.SCHEMA, SlidingMode.SCHEMA]
    items.append(COMPENSATION_SCHEMA)
    items.append(JOINT_LOAD_SCHEMA)
    items.append(LEARNED_RESIDUAL_SCHEMA)
    items.append(
        Schema.from_defaults("friction", {"model": "none"} if friction_model else {}, "friction model")
    )
    items.append(
        Schema.from_defaults("reference", {"type": "constant"} if reference else {}, "reference generator")
    )
    return items


def friction_schema(model: Any) -> Schema:
    """The ROS ``friction`` section of a model (``model`` + its coefficients, closed); an open
    section for ``none`` and for models without a flat coefficient list (``asymmetric``)."""
    from friction_ros.core.friction.registry import MODEL_CLASSES  # loads the compiled kernels

    names = ("none", *MODEL_CLASSES)
    cls = MODEL_CLASSES.get(model) if isinstance(model, str) else None
    coefs = cls.COEFS if cls is not None else ()
    return Schema(
        "friction", [Field("model", "none", "friction model", choices=names), *coefs], open=not coefs
    )


def ros_controller_config(
    values: Mapping[str, Any], names: Names | None = None, joint_type: str = "revolute"
) -> TypedConfig:
    """compensating_controller ROS parameters (nested) -> the controller's typed config.

    The ROS layout (README "Key parameters", written by ``friction-fit``) keeps the friction model and
    the way it is applied apart: ``friction`` is a library model config (``{model: gms, fc: ...}``,
    validated against the model's coefficients) and ``compensation`` holds source, gain, blend,
    smoothing. Keys of the node itself (joint_name, control_period, reference ...) are left out.
    Validated once; messages name the ROS parameters (``names``, default: the dotted key itself)
    in the joint's units. ``values`` nested or in dotted names.
    """
    friction = values.get("friction")
    model = (
        friction.get("model", "none")
        if isinstance(friction, Mapping)
        else values.get("friction.model", "none")
    )
    schema = _ros_schema(model if isinstance(model, str) else "", joint_type)
    given = {k: v for k, v in values.items() if str(k).split(".", 1)[0] in schema.items}
    return schema.typed(given, names=names)


def core_controller_config(config: Mapping[str, Any] | None) -> TypedConfig:
    """A controller config in the core layout (nested or dotted; ``friction`` = how the model is
    applied, with ``model``: a model config, a model or None; None values: the default) as the
    typed config, validated once; messages name ``controller.<key>`` and a model's coefficients by
    the model's name (``gms.fc``)."""
    given = unflatten(config) if config and any("." in str(k) for k in config) else dict(config or {})
    check_keys("controller", given, CONTROLLER_DEFAULTS)
    ros: dict[str, Any] = {}
    for k, v in given.items():
        if v is None:
            continue
        if k in CONFIG_SECTIONS and not isinstance(v, Mapping):
            raise ParameterError(f"controller.{k} = {v!r} must be a mapping (a parameter section)")
        ros[k] = {kk: vv for kk, vv in v.items() if vv is not None} if k in CONFIG_SECTIONS else v
    model = None
    if "friction" in ros:
        settings = ros.pop("friction")
        model = settings.pop("model", None)
        ros["compensation"] = settings
    if hasattr(model, "to_config"):
        model = model.to_config()
    if model is not None and not isinstance(model, Mapping):
        raise ParameterError(
            f"controller.friction.model = {model!r} must be a model config dict with a 'model' key"
        )
    name = (model or {}).get("model") or "none"
    ros["friction"] = dict(model) if model else {"model": "none"}
    return ros_controller_config(ros, _core_names(name if isinstance(name, str) else "friction"))


def _core_names(model: str):
    """Message names of the core layout: ``controller.<key>``, the ``compensation`` section as
    ``controller.friction`` and a model's coefficients by the model's name."""

    def names(rel: str) -> str:
        head, _, tail = rel.partition(".")
        if head == "compensation":
            return f"controller.friction.{tail}" if tail else "controller.friction"
        if head == "friction":  # the model's section: '' lets the model name itself
            return "controller.friction.model" if tail == "model" else f"{model}.{tail}" if tail else ""
        return f"controller.{rel}" if rel else "controller"

    return names


def core_config(cfg: TypedConfig) -> dict[str, Any]:
    """A typed ROS config as the core's nested config (a view for people and files, not a way into
    the controller): the ROS ``compensation`` section is the core's ``friction`` section and the
    ROS ``friction`` section its ``model`` (None for none)."""
    out = cfg.as_dict()
    model = out.pop("friction")
    out["friction"] = {
        **out.pop("compensation"),
        "model": None if model.get("model") in (None, "", "none") else model,
    }
    return out


def config_from_ros_parameters(values: Mapping[str, Any]) -> tuple[dict[str, Any], dict[str, Any]]:
    """compensating_controller ROS parameters (nested) -> (core controller config of the keys given,
    reference config), validated as :func:`ros_controller_config`."""
    core = core_config(ros_controller_config(values, joint_type=values.get("joint_type", "revolute")))
    given = {k: v for k, v in core.items() if k in values or k == "friction"}
    return given, dict(values.get("reference") or {"type": "constant"})


_ROS_SCHEMAS: dict[tuple, Schema] = {}


def _ros_schema(model: str, joint_type: str) -> Schema:
    """The controller's ROS schema with ``model``'s friction section (built once per model, joint
    type and model class, so each typed class is generated once)."""
    friction = friction_schema(model)
    fields = list(friction.items.values())
    key = (model, joint_type, fields[0].choices, tuple(id(f) for f in fields[1:]))
    if key not in _ROS_SCHEMAS:
        schema = Schema("", [*controller_parameter_schema()[:-2], friction])
        _ROS_SCHEMAS[key] = joint_schema(schema, joint_type)
    return _ROS_SCHEMAS[key]


def core_names(key: str) -> str:
    """Message names of the core config: ``controller.<key>``; a model by its own name."""
    return "" if key == "model" else f"controller.{key}" if key else "controller"


def merge_config(base: dict[str, Any], given: Mapping[str, Any]) -> dict[str, Any]:
    """``given`` (nested or dotted) laid over a full config ``base``: sections key by key, a
    friction ``model`` replaces the previous one as a whole."""
    if any("." in str(k) for k in given):
        given = unflatten(given)
    out = copy.deepcopy(base)
    for k, v in given.items():
        if k in CONFIG_SECTIONS:
            if v is None:
                continue
            if not isinstance(v, Mapping):
                raise ParameterError(f"controller.{k} = {v!r} must be a mapping (a parameter section)")
            if k == "friction" and "model" in v:
                out[k]["model"] = None  # a model replaces the previous one as a whole
            sec = out[k]
            for kk, vv in v.items():
                sec[kk] = copy.deepcopy(vv)
        else:
            out[k] = v
    return out


def default_config() -> dict[str, Any]:
    """A deep copy of :data:`CONTROLLER_DEFAULTS`."""
    return copy.deepcopy(CONTROLLER_DEFAULTS)
