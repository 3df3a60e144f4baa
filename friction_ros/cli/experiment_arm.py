"""friction-experiment on an arm: the joints, their plants and each joint's program sized to it.

The joints come from ``--joints j1,j2,...`` or from the parameter files (``--params``): the
``joints`` of their ``identification_experiment`` or ``plant_simulator`` section (e.g.
``params/arm7_plant.yaml``). Each joint's plant: ``--presets p1,p2,...`` (one per joint), else the
file's ``presets``, else ``--preset`` for every joint, with the file's ``plant.<joint>.<key>`` /
``friction_*.<joint>.<key>`` values on top, resolved exactly as plant_simulator resolves them. A
joint with a pendulum gravity load (``plant.<joint>.gravity``) is sized with the load at its start
position (its ``bias`` then holds it there).

Each joint's program is sized to its plant as ``friction-experiment --preset`` sizes one joint,
with the ``--set`` values: node-level keys (``plateaus.count=2``) apply to every joint, per-joint
keys (``limits.j2.max_travel=0.5``, ``gains.j2.bias=0.1``) to that joint only. The sized values
go to the experiment node as per-joint parameters (``plateaus.j2.v_max``, ``gains.j2.bias`` ...:
:mod:`friction_ros.core.joint_config`). As for one joint, the ``identification_experiment`` values
of the parameter files are not sized but win over the sized ones: a node-level value there
(``limits.max_travel``) replaces every joint's sized value, a per-joint one
(``limits.j2.max_travel``) that joint's.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

from friction_ros.cli.experiment_config import nest, node_values, sized_config, typed_like_defaults
from friction_ros.core.config import flatten
from friction_ros.core.joint_config import JointLayout, check_joint_list
from friction_ros.core.validation import ParameterError

EXPERIMENT_NODE, PLANT_NODE = "identification_experiment", "plant_simulator"


@dataclass
class ArmSetup:
    """What friction-experiment needs to run an arm (see the module docstring)."""

    joints: list[str]
    presets: list[str] | None  # one plant preset per joint (None: the plant's preset for every joint)
    plants: list[Any]  # resolved Preset per joint (None entries on a real arm): sizing and summary
    node_params: dict[str, Any] = field(default_factory=dict)  # per-joint experiment parameters
    durations: list[float] = field(default_factory=list)
    marked_count: int = 0
    name: str = ""

    def total_duration(self, sequence: str, gap: float) -> float:
        if sequence == "together":
            return max(self.durations)
        return sum(self.durations) + gap * (len(self.durations) - 1)


def file_section(paths: list[str], node: str) -> dict[str, Any]:
    """The flat ``ros__parameters`` of ``node`` in the parameter files (later files win; sections
    named ``node``, ``/**/node``, ``/ns/node`` or nested under a namespace)."""
    from friction_ros.core.yaml_files import check_parameter_file

    out: dict[str, Any] = {}

    def walk(d: dict, name: str) -> None:
        for key, value in d.items():
            if key == "ros__parameters":
                if name.split("/")[-1] in (node, "**") and isinstance(value, dict):
                    out.update(flatten(value, keep_none=True))
            elif isinstance(value, dict):
                walk(value, str(key))

    for p in paths:
        walk(check_parameter_file(p), "")
    return out


def _names(text: str | None, what: str) -> list[str] | None:
    if text is None:
        return None
    names = [t.strip() for t in text.split(",")]
    if not names or any(not t for t in names):
        raise ParameterError(f"{what} {text!r}: an empty name: write e.g. {what} j1,j2")
    return names


def arm_joints(args) -> tuple[list[str], list[str] | None, dict[str, Any], dict[str, Any]] | None:
    """``(joints, presets, plant section, experiment section)`` of an arm (flat sections of the
    parameter files), or None for one joint (module docstring)."""
    plant = file_section(args.params, PLANT_NODE)
    exp = file_section(args.params, EXPERIMENT_NODE)
    joints = _names(args.joints, "--joints") or list(exp.get("joints") or plant.get("joints") or [])
    presets = _names(args.presets, "--presets")
    if not joints:
        if presets:
            raise ParameterError("--presets names one preset per joint: give the joints with --joints")
        return None
    try:
        joints = check_joint_list(joints)
    except ParameterError as exc:
        raise ParameterError(f"--joints: {exc}") from None
    if presets is None and plant.get("presets"):
        presets = list(plant["presets"])
    if presets is not None and len(presets) != len(joints):
        raise ParameterError(
            f"{len(presets)} presets ({', '.join(presets)}) for {len(joints)} joints ({', '.join(joints)}): "
            "give one preset per joint, in the order of the joints"
        )
    return joints, presets, plant, exp


def joint_plants(args, joints: list[str], presets: list[str] | None, plant: dict[str, Any]) -> list:
    """Each joint's plant preset as plant_simulator resolves it (per-joint plant values included)."""
    from friction_ros.core.config import unflatten
    from friction_ros.core.plant.multi_joint import PRESET_SECTIONS, resolve_joint_presets

    layout = JointLayout(joints, PRESET_SECTIONS)
    node_flat, per_joint = layout.split_all(
        {k: v for k, v in plant.items() if k.split(".")[0] in PRESET_SECTIONS}
    )
    values = {
        **unflatten(node_flat),
        "joints": joints,
        "presets": presets or [],
        "preset": args.preset,
        "control_period": float(plant.get("control_period", 0.001)),
    }
    return resolve_joint_presets(values, joints, per_joint)


def start_load(preset, initial_position: float) -> float | None:
    """The constant load [N*m, along +q] a joint feels at its start position when it has a
    pendulum gravity load (None without one: the preset's constant load is used)."""
    p = preset.params
    g = float(getattr(p, "gravity", 0.0) or 0.0)
    if g == 0.0:
        return None
    phase = float(getattr(p, "gravity_phase", 0.0) or 0.0)
    return float(p.load_torque - p.gravity_force - g * math.sin(initial_position + phase))


def arm_setup(args, sets: dict[str, Any]) -> ArmSetup | None:
    """The arm's joints, plants and per-joint sized programs; None for one joint."""
    from friction_ros.core.experiment.excitation import ExcitationProgram
    from friction_ros.core.experiment.excitation_config import SECTIONS, resolve_config
    from friction_ros.core.experiment.experiment_sizing import fit_to_limits
    from friction_ros.nodes.identification_experiment import PER_JOINT_PLAIN_KEYS

    found = arm_joints(args)
    if found is None:
        return None
    joints, presets, plant, exp = found
    plants = [None] * len(joints) if args.no_sim else joint_plants(args, joints, presets, plant)
    setup = ArmSetup(joints, presets, plants)
    layout = JointLayout(joints, SECTIONS, None, (), PER_JOINT_PLAIN_KEYS)
    try:
        node_sets, joint_sets = layout.split_all(sets)
    except ParameterError as exc:
        raise ParameterError(f"--set {exc}") from None
    q0 = float(plant.get("initial_position", 0.0))
    exp_node, _ = layout.split_all({k: v for k, v in exp.items() if k != "joints"})
    names = []
    for j, pobj in zip(joints, plants):
        sets_j = {**node_sets, **joint_sets[j]}
        try:
            load = start_load(pobj, q0) if pobj is not None else None
            sized = sized_config(args, pobj, sets_j, load=load)
            sized_flat = typed_like_defaults(flatten(sized, keep_none=True), args.profile)
            sized_flat = {
                k: v for k, v in sized_flat.items() if k not in ("program", "profile", "control_period")
            }
            core = {"program": args.program, "profile": args.profile, **nest({**sized_flat, **sets_j})}
            program = ExcitationProgram(fit_to_limits(resolve_config(core), keep=set(sets_j)))
        except ParameterError as exc:
            raise ParameterError(f"joint {j}: {exc}") from None
        for k, v in node_values(program.config, args.profile, sized_flat).items():
            if k not in exp_node:  # a node-level value of the parameter files applies to every joint
                setup.node_params[layout.joint_name(j, k)] = v
        setup.durations.append(program.total_duration)
        setup.marked_count += program.marked_count
        names.append(program.name)
    setup.name = "+".join(dict.fromkeys(names))
    return setup
