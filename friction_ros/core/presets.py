"""Plant presets: ROS parameter YAML files in ``params/`` -> plant parameters + friction models.

File format (one file per preset)::

    plant_simulator:
      ros__parameters:
        preset: <name>
        description: "..."
        control_period: 0.001
        plant: {<PlantParams field>: value, ...}
        friction_motor: {model: <name>, <coefficient>: value, ...}
        friction_load: {model: none}

``load_preset(name_or_path)`` accepts a preset name (see ``PRESET_NAMES``) or a path to such a file.

One way from a preset to a plant: :func:`resolve_preset` (a preset by name, path or object, its
sections overridden by a parameter file's and/or by keywords) gives a :class:`Preset`, and
:meth:`Preset.make_plant` the :class:`~friction_ros.core.plant.servo.GearheadServoPlant`
(:func:`make_plant` does both). The harness, the synthetic identification records, the CAN drive
emulator, the plant_simulator node and the CLIs all go this way.

The control period is owned by the plant's preset: ``Preset.control_period`` (the ``control_period``
of the YAML file, validated by :func:`~friction_ros.core.control_period.check_control_period`), by default
:data:`~friction_ros.core.control_period.DEFAULT_CONTROL_PERIOD`. The nodes' ``control_period`` parameters (
1 / period in drive_interface) take their default and range from :data:`~friction_ros.core.control_period.DEFAULT_CONTROL_PERIOD` and
:data:`CONTROL_PERIOD_RANGE`; plant_simulator hands its ``control_period`` to the preset it builds
and steps the plant at ``Preset.control_period``.
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from friction_ros.core.config import Names
from friction_ros.core.control_period import DEFAULT_CONTROL_PERIOD, check_control_period
from friction_ros.core.friction import FrictionModel
from friction_ros.core.plant.params import PlantParams
from friction_ros.core.plant.servo import GearheadServoPlant
from friction_ros.core.validation import ParameterError, check_keys
from friction_ros.core.yaml_files import load_yaml

NODE_NAME = "plant_simulator"
PRESET_NAMES: tuple[str, ...] = (
    "abb_m19s",
    "seed002_x",
    "seed002_y",
    "seed002_z",
    "seed004_dc_motor",
    "seed001_harmonic_drive",
    "seed000_gearhead",
)
# joint_type: the node's (a fitted parameter file used as a preset carries it); the plant ignores it
_SECTION_KEYS = (
    "preset",
    "description",
    "control_period",
    "joint_type",
    "plant",
    "friction_motor",
    "friction_load",
)
_OVERRIDE_KEYS = ("control_period", "plant", "friction_motor", "friction_load")
_FRICTION_SIDES = ("friction_motor", "friction_load")


def params_dir() -> Path:
    """Directory of the preset YAML files (``$FRICTION_ROS_PARAMS`` or the repository's ``params/``)."""
    env = os.environ.get("FRICTION_ROS_PARAMS")
    if env:
        return Path(env)
    here = Path(__file__).resolve()
    for cand in (here.parents[2] / "params", here.parents[1] / "params"):
        if cand.is_dir():
            return cand
    try:  # installed with colcon: share/friction_ros/params
        from ament_index_python.packages import get_package_share_directory

        return Path(get_package_share_directory("friction_ros")) / "params"
    except Exception:  # pragma: no cover
        return here.parents[2] / "params"


def preset_path(name_or_path: str | os.PathLike) -> Path:
    s = str(name_or_path)
    if s in PRESET_NAMES or (not s.endswith((".yaml", ".yml")) and os.sep not in s):
        p = params_dir() / f"{s}.yaml"
        if not p.is_file():
            raise ParameterError(
                f"preset = {s!r} is not allowed: must be one of {', '.join(PRESET_NAMES)} or a YAML path"
            )
        return p
    p = Path(s)
    if p.is_dir():
        raise ParameterError(f"preset file {s!r} is a directory, not a preset YAML file")
    if not p.is_file():
        raise ParameterError(f"preset file {s!r} does not exist")
    return p


@dataclass
class Preset:
    """A loaded preset: plant parameters (with their friction models) and metadata."""

    name: str
    description: str
    control_period: float
    params: PlantParams
    source: str = ""

    @property
    def friction(self) -> FrictionModel:
        """The main (truth) friction model: load side if set, else motor side."""
        fl = self.params.friction_load
        return fl if fl.name != "none" else self.params.friction_motor

    def joint_friction(self, v) -> np.ndarray:
        """Steady-state friction seen at the joint [N*m or N] at joint velocity ``v``: load-side
        friction, motor-side friction reflected through the gear (``r eta F_m(r v)``) and the viscous
        damping of both sides (``(r^2 eta B_m + B_l) v``), what a plateau experiment measures.

        A load-dependent load-side model (``fc + fl |tau|``) is evaluated at the torque the plant
        gives it, which at steady sliding contains that friction itself: the coupling torque
        ``F_l + B_l v`` of a compliant transmission, the joint torque (``F_l + B_l v`` plus the
        reflected motor side) of a rigid one; solved by fixed-point iteration (contraction ``fl``)."""
        p = self.params
        v = np.asarray(v, dtype=float)
        r, eta = p.ratio, p.gear_efficiency
        fm = np.zeros_like(v)
        if p.friction_motor.name != "none":
            fm = r * eta * np.asarray(p.friction_motor.steady_state(r * v), dtype=float)
        fl_model = p.friction_load
        f = np.asarray(fl_model.steady_state(v), dtype=float)
        if getattr(fl_model, "load_dependent", False) and not fl_model.is_dynamic:
            others = p.load_damping * v
            if not p.compliant:
                others = others + fm + r * r * eta * p.motor_damping * v
            for _ in range(100):
                f_new = np.asarray(fl_model.torque(v, np.abs(f + others)), dtype=float)
                if np.max(np.abs(f_new - f), initial=0.0) <= 1e-15 * max(
                    np.max(np.abs(f_new), initial=0.0), 1e-300
                ):
                    f = f_new
                    break
                f = f_new
        return f + fm + (r * r * eta * p.motor_damping + p.load_damping) * v

    @property
    def friction_motor(self) -> FrictionModel:
        return self.params.friction_motor

    @property
    def friction_load(self) -> FrictionModel:
        return self.params.friction_load

    def make_plant(self) -> GearheadServoPlant:
        """A new plant with this preset's parameters (the one way from a preset to a plant)."""
        return GearheadServoPlant(self.params)

    def override(
        self, sections: Mapping[str, Any] | None = None, /, names: Names | None = None, **changes: Any
    ) -> Preset:
        """This preset with ROS parameter ``sections`` and keyword ``changes`` applied.

        ``sections``: ``plant`` (merged key by key), ``friction_motor`` / ``friction_load`` (a section
        that names a ``model`` replaces the preset's model as a whole, one without merges its
        coefficients into the preset's model), ``control_period``; an empty section changes nothing.
        ``changes``: plant keys and/or whole ``friction_motor`` / ``friction_load`` models (configs or
        model objects), applied after ``sections``. ``names``: the parameter names in messages
        (:meth:`PlantParams.from_config <friction_ros.core.plant.params.PlantParams.from_config>`).
        """
        given = {k: v for k, v in dict(sections or {}).items() if v}
        check_keys("preset overrides", given, _OVERRIDE_KEYS)
        plant = {**given.get("plant", {}), **{k: v for k, v in changes.items() if k not in _FRICTION_SIDES}}
        friction = {}
        for side in _FRICTION_SIDES:
            if side in changes:
                friction[side] = changes[side]
            elif side in given:
                sec = dict(given[side])
                own = getattr(self.params, side)
                friction[side] = sec if "model" in sec else {**own.to_config(), **sec}
        params = self.params.replace(names, **plant, **friction) if plant or friction else self.params
        period = self.control_period
        if "control_period" in given:
            where = "preset.control_period" if names is None else names("control_period")
            period = check_control_period(where, given["control_period"])
        return replace(self, params=params, control_period=period)

    def to_config(self) -> dict:
        """The ROS parameter YAML document (``{plant_simulator: {ros__parameters: {...}}}``)."""
        cfg = self.params.to_config()
        section = {
            "preset": self.name,
            "description": self.description,
            "control_period": self.control_period,
            **cfg,
        }
        return {NODE_NAME: {"ros__parameters": section}}

    def __iter__(self):  # allows ``params, friction = load_preset(...)``
        yield self.params
        yield self.friction


def preset_from_config(doc: Mapping[str, Any], source: str = "") -> Preset:
    """Build a :class:`Preset` from a parsed YAML document or a bare ``ros__parameters`` section."""
    sec: Any = doc
    if isinstance(sec, Mapping) and len(sec) == 1 and "ros__parameters" not in sec:
        sec = next(iter(sec.values()))  # node name (plant_simulator or any other)
    if isinstance(sec, Mapping) and "ros__parameters" in sec:
        sec = sec["ros__parameters"]
    if not isinstance(sec, Mapping):
        raise ParameterError(f"preset {source or ''}: expected a 'ros__parameters' mapping")
    check_keys(f"preset {source}".strip(), sec, _SECTION_KEYS)
    if "plant" not in sec:
        raise ParameterError(f"preset {source}: missing the 'plant' section")
    params = PlantParams.from_config(sec["plant"], sec.get("friction_motor"), sec.get("friction_load"))
    return Preset(
        name=str(sec.get("preset", Path(source).stem if source else "custom")),
        description=str(sec.get("description", "")),
        control_period=check_control_period(
            "preset.control_period", sec.get("control_period", DEFAULT_CONTROL_PERIOD)
        ),
        params=params,
        source=source,
    )


def load_preset(name_or_path: str | os.PathLike) -> Preset:
    """Load a preset by name (``PRESET_NAMES``) or YAML path; returns a :class:`Preset`.

    ``params, friction = load_preset("abb_m19s")`` also works (plant params, main friction model).
    """
    path = preset_path(name_or_path)
    doc = load_yaml(path, "preset file")
    if doc is not None and not isinstance(doc, Mapping):
        raise ParameterError(
            f"preset file {str(path)!r}: expected a mapping (plant_simulator: ros__parameters: ...), "
            f"got a {type(doc).__name__}"
        )
    return preset_from_config(doc or {}, source=str(path))


def save_preset(preset: Preset, path: str | os.PathLike) -> Path:
    """Write ``preset`` as a ROS parameter YAML file (round-trips through :func:`load_preset`)."""
    path = Path(path)
    path.write_text(yaml.safe_dump(preset.to_config(), sort_keys=False), encoding="utf-8")
    return path


def resolve_preset(
    preset: str | os.PathLike | Preset | Mapping[str, Any] = "",
    overrides: Mapping[str, Any] | None = None,
    /,
    names: Names | None = None,
    **changes: Any,
) -> Preset:
    """A preset by name, path or object with its sections overridden (the one way from a preset or a
    parameter file to a plant: ``resolve_preset(...).make_plant()``).

    ``overrides``: the ``plant`` / ``friction_motor`` / ``friction_load`` / ``control_period``
    sections of a parameter file, ``changes``: plant keys and whole friction models as keywords
    (see :meth:`Preset.override`). ``preset`` = "" means no base preset: the sections are the whole
    plant (as in a ``friction-fit`` parameter file), missing plant keys take their defaults; a
    mapping ``preset`` is such a whole plant (``{"plant": ..., "friction_motor": ...}``).
    ``names``: the parameter names in messages (a joint's, :class:`~friction_ros.core.joint_config.JointNames`).
    """
    if isinstance(preset, Mapping):
        preset, overrides = "", {**preset, **dict(overrides or {})}
    if isinstance(preset, Preset):
        base = preset
    elif preset:
        base = load_preset(preset)
    else:  # the sections (and keywords) are the whole plant
        given = {k: v for k, v in dict(overrides or {}).items() if v}
        check_keys("preset overrides", given, _OVERRIDE_KEYS)
        doc = {**given, "preset": "custom"}
        doc["plant"] = {
            **given.get("plant", {}),
            **{k: v for k, v in changes.items() if k not in _FRICTION_SIDES},
        }
        doc.update({side: changes[side] for side in _FRICTION_SIDES if side in changes})
        return preset_from_config(doc, source="parameter file")
    return base.override(overrides, names=names, **changes)


def make_plant(
    preset: str | os.PathLike | Preset | Mapping[str, Any] = "",
    overrides: Mapping[str, Any] | None = None,
    /,
    **changes: Any,
) -> GearheadServoPlant:
    """``resolve_preset(preset, overrides, **changes).make_plant()``: e.g.
    ``make_plant("abb_m19s", encoder_cpr=0)`` or ``make_plant({"plant": {...}, "friction_motor": {...}})``."""
    return resolve_preset(preset, overrides, **changes).make_plant()
