"""Joint types and their units (REP-103): a revolute joint moves in rad, a prismatic one in m.

``sensor_msgs/JointState`` carries both: position [rad or m], velocity [rad/s or m/s], effort
[N*m or N]. The schemas and the fitter write their units for a revolute joint; :func:`joint_unit`
gives the unit of the same quantity on a prismatic joint (``N*m`` -> ``N``, ``rad/s`` -> ``m/s``,
``kg*m^2`` -> ``kg``, ``N*m*s/rad`` -> ``N*s/m`` ...), :func:`joint_schema` a schema whose fields
carry the joint's units and :func:`joint_text` rewrites the bracketed units of a message
(``must be > 0 [N*m]`` -> ``must be > 0 [N]``). :func:`detect_joint_type` reads the joint type
from a log's metadata. Pure: no rclpy.
"""

from __future__ import annotations

import contextlib
import dataclasses
import re
from collections.abc import Iterator, Mapping, Sequence
from pathlib import Path
from typing import Any

from friction_ros.core.config import Field, Schema
from friction_ros.core.validation import ParameterError

JOINT_TYPES = ("revolute", "prismatic")
DEFAULT_JOINT_TYPE = "revolute"

#: the ``joint_type`` parameter of every node that handles joint quantities
JOINT_TYPE_FIELD = Field(
    "joint_type",
    DEFAULT_JOINT_TYPE,
    "revolute: positions in rad, efforts in N*m; prismatic: positions in m, efforts in N (REP-103)",
    choices=JOINT_TYPES,
    read_only=True,
)

#: settings whose unit does not follow the joint: angular frequencies [rad/s] and the motor's own
#: quantities (a prismatic axis is often a rotary motor on a screw)
FIXED_UNIT_KEYS = frozenset(
    {"observer_bandwidth", "omega_start", "omega_end", "amplitude_decay", "torque_constant", "motor_inertia"}
)

_TORQUE = re.compile(r"\bN\*m\b(?!\^)")  # N*m (torque), not N*m^2
_INERTIA = re.compile(r"\bkg\*m\^2\b")
_ANGLE = re.compile(r"\b(rad)\b")
_BRACKET = re.compile(r"\[([^\[\]]+)\]")

#: the units of a joint's quantities, by joint type (summary.json ``units``, report headers)
QUANTITY_UNITS = {
    "position": "rad",
    "velocity": "rad/s",
    "acceleration": "rad/s^2",
    "friction": "N*m",
    "effort": "N*m",
    "J": "kg*m^2",
}


def check_joint_type(value: Any, name: str = "joint_type") -> str:
    """``value`` if it is a joint type, else a one-line ParameterError naming the allowed values."""
    if not (isinstance(value, str) and value in JOINT_TYPES):
        raise ParameterError(f"{name} = {value!r} is not allowed: must be one of {', '.join(JOINT_TYPES)}")
    return value


def joint_unit(unit: str, joint_type: str = DEFAULT_JOINT_TYPE) -> str:
    """The unit of a quantity written ``unit`` for a revolute joint, on a ``joint_type`` joint.

    Revolute: ``unit`` unchanged. Prismatic: torque -> force (``N*m`` -> ``N``), angle -> length
    (``rad`` -> ``m``), rotational inertia -> mass (``kg*m^2`` -> ``kg``), in every product and
    quotient (``N*m*s/rad`` -> ``N*s/m``, ``1/rad`` -> ``1/m``); a unit already written for both
    (``N*m or N``) gives its prismatic half. Units of neither (s, Hz, A, V) are unchanged.
    """
    joint_type = check_joint_type(joint_type)
    if " or " in unit:
        parts = unit.split(" or ", 1)
        return parts[0] if joint_type == "revolute" else parts[1]
    if joint_type == "revolute" or not unit:
        return unit
    out = _INERTIA.sub("kg", unit)
    out = _TORQUE.sub("N", out)
    out = _ANGLE.sub("m", out)
    return out


def joint_text(text: str, joint_type: str = DEFAULT_JOINT_TYPE) -> str:
    """``text`` with every bracketed unit (``[N*m]``, ``[rad/s]``) in the joint's units; a message
    about a setting of :data:`FIXED_UNIT_KEYS` keeps its units."""
    if check_joint_type(joint_type) == "revolute":
        return text
    head = text.split(" ", 1)[0].rsplit(".", 1)[-1]
    if head in FIXED_UNIT_KEYS:
        return text
    return _BRACKET.sub(lambda m: f"[{joint_unit(m.group(1), joint_type)}]", text)


def quantity_units(joint_type: str = DEFAULT_JOINT_TYPE) -> dict[str, str]:
    """``{"position": "rad" | "m", "velocity": ..., "friction": ..., "J": ...}`` of the joint."""
    return {k: joint_unit(u, joint_type) for k, u in QUANTITY_UNITS.items()}


def joint_field(field: Field, joint_type: str = DEFAULT_JOINT_TYPE) -> Field:
    """A :class:`~friction_ros.core.config.Field` with its unit in the joint's units."""
    if joint_type == "revolute" or not field.unit or field.name.rsplit(".", 1)[-1] in FIXED_UNIT_KEYS:
        return field
    return dataclasses.replace(field, unit=joint_unit(field.unit, joint_type))


def joint_schema(schema: Schema, joint_type: str = DEFAULT_JOINT_TYPE) -> Schema:
    """A copy of a :class:`~friction_ros.core.config.Schema` whose fields (sections included)
    carry the joint's units; the schema itself when the joint is revolute."""
    if check_joint_type(joint_type) == "revolute":
        return schema
    items = [
        joint_schema(item, joint_type) if isinstance(item, Schema) else joint_field(item, joint_type)
        for item in schema
    ]
    return Schema(schema.name, items, doc=schema.doc, open=schema.open, read_only=schema.read_only)


@contextlib.contextmanager
def units_of(joint_type: str = DEFAULT_JOINT_TYPE) -> Iterator[None]:
    """Re-raise a ParameterError raised inside with its units in the joint's units (core objects
    check their values in revolute units)."""
    try:
        yield
    except ParameterError as exc:
        if joint_type == "revolute":
            raise
        raise ParameterError(joint_text(str(exc), joint_type)) from None


# ------------------------------------------------------------------------------ detection

#: CSV headers (lower case, unit suffix stripped) that name a force, not a torque
_FORCE_HEADERS = ("force",)
_LINEAR_SUFFIXES = ("_m", " [m]", " (m)", "_m_s", "_m/s", " [m/s]", " (m/s)", "_n", " [n]", " (n)")
_ROTARY_SUFFIXES = (
    "_rad",
    " [rad]",
    " (rad)",
    "_rad_s",
    "_rad/s",
    " [rad/s]",
    "_nm",
    " [n*m]",
    " [nm]",
    " (nm)",
)
_TEXT_SOURCES = ("joint_type", "joint-type", "jointtype")


def _from_mapping(meta: Mapping, joint: str | None, where: str) -> tuple[str | None, str]:
    keys = ([f"joint_type.{joint}", f"{joint}.joint_type", f"joint_type/{joint}"] if joint else []) + list(
        _TEXT_SOURCES
    )
    for key in keys:
        value = meta.get(key)
        if isinstance(value, str) and value.strip().lower() in JOINT_TYPES:
            return value.strip().lower(), f"{where} {key}: {value.strip()}"
    return None, ""


_URDF_JOINT = re.compile(r"<joint\b[^>]*>", re.S)
_ATTR = re.compile(r"""(\w+)\s*=\s*["']([^"']*)["']""")


def _from_urdf(text: str, joint: str | None, where: str) -> tuple[str | None, str]:
    """The type of ``joint`` (or of every joint, when they agree) in URDF text."""
    types = {}
    for tag in _URDF_JOINT.findall(text):
        a = dict(_ATTR.findall(tag))
        if a.get("type") in ("revolute", "continuous", "prismatic"):
            types[a.get("name", "")] = "prismatic" if a["type"] == "prismatic" else "revolute"
    if joint in types:
        return types[joint], f"{where}: URDF joint {joint} is {types[joint]}"
    if not joint and len(set(types.values())) == 1:
        t = next(iter(types.values()))
        return t, f"{where}: every URDF joint is {t}"
    return None, ""


def _from_parameter_file(text: str, joint: str | None, where: str) -> tuple[str | None, str]:
    """``joint_type`` set in an embedded ROS parameter file (node level or ``gains.<joint>``)."""
    from friction_ros.core.yaml_files import parse_yaml

    try:
        doc = parse_yaml(text, where)
    except ValueError:
        return None, ""
    found = set()
    for sec in (doc or {}).values() if isinstance(doc, Mapping) else ():
        params = sec.get("ros__parameters") if isinstance(sec, Mapping) else None
        if not isinstance(params, Mapping):
            continue
        gains = params.get("gains") if isinstance(params.get("gains"), Mapping) else {}
        own = gains.get(joint, {}) if joint else {}
        value = own.get("joint_type") if isinstance(own, Mapping) else None
        value = value or params.get("joint_type")
        if value in JOINT_TYPES:
            found.add(value)
    if len(found) == 1:
        t = found.pop()
        return t, f"{where} sets joint_type: {t}"
    return None, ""


def _from_columns(columns: Sequence[str]) -> tuple[str | None, str]:
    linear, rotary = [], []
    for c in columns:
        low = c.strip().strip("\"'").lower()
        base = re.sub(r"\s*[\[(][^\])]*[\])]\s*$", "", low)
        base = re.sub(r"_(n|m|m_s|m/s)$", "", base)
        if base in _FORCE_HEADERS or base.startswith("force_") or base.endswith("_force"):
            linear.append(c)
        elif low.endswith(_LINEAR_SUFFIXES):
            linear.append(c)
        elif low.endswith(_ROTARY_SUFFIXES) or base in ("torque", "tau") or "torque" in base:
            rotary.append(c)
    if linear and not rotary:
        return "prismatic", f"CSV column(s) {', '.join(map(repr, linear))} are in linear units (m, m/s, N)"
    if rotary and not linear:
        return "revolute", f"CSV column(s) {', '.join(map(repr, rotary))} are in rotary units (rad, N*m)"
    if linear and rotary:
        return None, (
            f"CSV columns mix linear ({', '.join(map(repr, linear))}) and rotary "
            f"({', '.join(map(repr, rotary))}) units: give the joint type"
        )
    return None, "CSV columns name no unit"


def _bag_custom_data(path: Path) -> dict:
    meta = path / "metadata.yaml"
    if not meta.is_file():
        return {}
    from friction_ros.core.yaml_files import load_yaml

    try:
        info = load_yaml(meta, "bag metadata")["rosbag2_bagfile_information"]
    except (ValueError, KeyError, TypeError):
        return {}
    custom = info.get("custom_data") if isinstance(info, Mapping) else None
    return dict(custom) if isinstance(custom, Mapping) else {}


def detect_joint_type(
    *,
    columns: Sequence[str] | None = None,
    metadata: Mapping[str, Mapping[str, str]] | None = None,
    path: str | Path | None = None,
    joint: str | None = None,
) -> tuple[str | None, str]:
    """The joint type a log states, as ``(type or None, reason)``.

    Looked for, first hit wins: a ``joint_type`` (or ``joint_type.<joint>``) entry in a bag's
    ``metadata.yaml`` ``custom_data`` (``path``: the bag directory), then in the MCAP metadata
    records (``metadata``: ``Bag.metadata``, any record), then in the parameter files the recorder
    embedded there (``parameter_file:<path>``: a node's ``joint_type``) or a URDF held there (the
    joint's ``type``), then the CSV ``columns``: a force column
    (``force``, ``force_N``) or linear unit suffixes (``position_m``, ``velocity [m/s]``) say
    prismatic; rotary ones (``torque``, ``position_rad``, ``[N*m]``) say revolute. None when nothing
    states it or the hints disagree; ``reason`` says why, for the fit report.
    """
    if path is not None and Path(path).is_dir():
        found, why = _from_mapping(_bag_custom_data(Path(path)), joint, "bag metadata.yaml custom_data")
        if found:
            return found, why
    for name, record in (metadata or {}).items():
        if isinstance(record, Mapping):
            found, why = _from_mapping(record, joint, f"bag metadata {name}")
            if found:
                return found, why
    for name, record in (metadata or {}).items():  # embedded parameter files, URDF text
        for key, text in record.items() if isinstance(record, Mapping) else ():
            if not isinstance(text, str):
                continue
            if "<joint" in text:
                found, why = _from_urdf(text, joint, f"bag metadata {name} {key}")
            elif key.startswith("parameter_file:"):
                found, why = _from_parameter_file(text, joint, f"bag metadata {name} {key}")
            else:
                continue
            if found:
                return found, why
    if columns:
        return _from_columns(columns)
    return None, "the log states no joint type"
