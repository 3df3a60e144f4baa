"""The plant presets of a multi-joint plant: one preset per joint with its own sections (pure).

``plant_simulator`` with ``joints: [...]`` and ``friction-experiment --joints`` build their plants
here: ``presets[i]`` (or the node's ``preset``) per joint, and the ``plant`` / ``friction_motor`` /
``friction_load`` sections in the per-joint layout of :mod:`friction_ros.core.joint_config`
(``plant.<joint>.<key>`` on top of ``plant.<key>``; a per-joint friction section naming its own
``model`` replaces the node-level one).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from friction_ros.core.joint_config import JointLayout, JointNames, joint_errors, joint_values
from friction_ros.core.presets import Preset, resolve_preset
from friction_ros.core.validation import ParameterError

PRESET_SECTIONS = ("plant", "friction_motor", "friction_load")
# a per-joint friction section naming its own model replaces the node-level section of that joint
_REPLACED_BY = {"friction_motor": "model", "friction_load": "model"}


def joint_plant_configs(
    values: Mapping[str, Any], joints: list[str], overrides: Mapping[str, Mapping[str, Any]]
) -> list[tuple[str, str, dict]]:
    """``(joint, preset, sections)`` of every joint: the preset name (``presets[i]`` or ``preset``)
    and its ``plant`` / ``friction_motor`` / ``friction_load`` overrides (node-level values with the
    joint's ``overrides``, node-level flat names such as ``plant.gravity``, on top). Pure."""
    presets = list(values.get("presets") or [])
    if presets and len(presets) != len(joints):
        raise ParameterError(
            f"presets = {presets} has {len(presets)} names for {len(joints)} joints "
            f"({', '.join(joints)}): must hold one preset per joint, in the order of joints, or none "
            "(every joint uses preset)"
        )
    node_sections = {s: dict(values.get(s) or {}) for s in PRESET_SECTIONS}
    if values.get("joints"):
        for key, value in node_sections["plant"].items():
            if isinstance(value, Mapping):  # plant.<name>.<key> for a name that is not a joint
                raise ParameterError(
                    f"plant.{key}.{next(iter(value), '')}: {key!r} is not one of the joints "
                    f"({', '.join(joints)}), so it has no per-joint plant values"
                )
    out = []
    for i, joint in enumerate(joints):
        own = dict(overrides.get(joint, {}))
        for name in own:
            if name.split(".", 1)[0] not in PRESET_SECTIONS:
                raise ParameterError(
                    f"{JointLayout(joints, ()).joint_name(joint, name)}: only the plant sections "
                    f"({', '.join(PRESET_SECTIONS)}) have per-joint values"
                )
        sections = joint_values(node_sections, own, _REPLACED_BY)
        out.append((joint, presets[i] if presets else values["preset"], sections))
    return out


def resolve_joint_presets(
    values: Mapping[str, Any], joints: list[str], overrides: Mapping[str, Mapping[str, Any]]
) -> list[Preset]:
    """The plant preset of every joint, all at the node's ``control_period`` (one joint: the node's
    preset with its sections, as without ``joints``). Errors name the per-joint parameter when the
    joint has its own value (``plant.j2.gravity``), else the node-level one and the joint
    (:class:`~friction_ros.core.joint_config.JointNames`). Pure."""
    multi = bool(values.get("joints"))
    layout = JointLayout(joints, PRESET_SECTIONS)
    out = []
    for joint, name, sections in joint_plant_configs(values, joints, overrides):
        sections = {**sections, "control_period": values["control_period"]}
        if not multi:
            out.append(resolve_preset(name, sections))
            continue
        names = JointNames(layout, joint, overrides.get(joint, {}), _REPLACED_BY)
        with joint_errors(names):
            out.append(resolve_preset(name, sections, names=names))
    return out
