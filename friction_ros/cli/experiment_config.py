"""friction-experiment's configuration: ``--set`` values, the program sized to the joint (preset or
probe values), and the node parameter values that carry both."""

from __future__ import annotations

from friction_ros.core.config import flatten
from friction_ros.core.validation import ParameterError
from friction_ros.core.yaml_files import YamlLimitError, parse_yaml


def parse_sets(items: list[str]) -> dict[str, object]:
    out: dict[str, object] = {}
    for item in items:
        if "=" not in item:
            raise ParameterError(f"--set {item!r} must be KEY=VALUE, e.g. plateaus.v_max=2.0")
        key, raw = item.split("=", 1)
        try:
            value = parse_yaml(raw, f"--set {item!r}")
            if isinstance(value, str):  # YAML 1.1 reads 1e-4 (no dot) as text: a number is meant
                try:
                    value = float(value)
                except ValueError:
                    pass
            out[key.strip()] = value
        except YamlLimitError:
            raise
        except ParameterError:
            raise ParameterError(f"--set {item!r}: cannot parse the value {raw!r}") from None
    return out


def nest(flat: dict[str, object]) -> dict:
    nested: dict = {}
    for key, value in flat.items():
        parts = key.split(".")
        d = nested
        for p in parts[:-1]:
            d = d.setdefault(p, {})
            if not isinstance(d, dict):
                raise ParameterError(f"--set {key}: {p} is not a section")
        d[parts[-1]] = value
    return nested


# the control period of the experiment node and the plant in the ROS graph (their default)
NODE_PERIOD = 1e-3
PROBE = ("breakaway", "inertia", "torque_limit", "speed_limit", "travel", "resolution")


#: --set limits that bound the joint scale the program is sized to
_SCALE_LIMITS = {
    "limits.max_travel": "travel",
    "limits.max_velocity": "speed_limit",
    "limits.max_torque": "torque_limit",
}


def sized_config(args, preset, sets: dict | None = None, load: float | None = None) -> dict:
    """The program's sections sized to the joint (preset or probe values), or {} for the profile.

    Limits given with ``--set`` (``limits.max_travel``/``max_velocity``/``max_torque``) bound the
    joint's travel, speed and torque before sizing, so the plateaus, amplitudes and ramps are
    derived within them. ``load``: the constant load [N*m] the joint feels at its start (an arm
    joint's gravity there) instead of the preset's constant load."""
    from dataclasses import replace

    from friction_ros.core.experiment.experiment_sizing import experiment_config
    from friction_ros.core.experiment.joint_scale import JointScale

    given = {k: getattr(args, k) for k in PROBE if getattr(args, k) is not None}
    sizing = args.sizing or ("joint" if (preset is not None or given) else "profile")
    if sizing == "profile":
        if given:
            raise ParameterError(
                f"--{next(iter(given)).replace('_', '-')} sizes the program to the joint: drop --sizing profile"
            )
        return {}
    if preset is not None:
        scale = JointScale.from_preset(preset, period=NODE_PERIOD, **given)
    else:
        missing = [k for k in PROBE if k not in given]
        if missing:
            raise ParameterError(
                "--sizing joint on a real joint needs the probe values "
                + ", ".join("--" + k.replace("_", "-") for k in missing)
                + " (or --sizing profile)"
            )
        scale = JointScale.from_probe(**given, period=NODE_PERIOD)
    if load is not None:
        try:
            scale = replace(scale, load=float(load))
        except ParameterError as exc:
            raise ParameterError(f"the load at the start position ({load:+.4g} N*m): {exc}") from None
    bounds = {}
    for key, field in _SCALE_LIMITS.items():
        value = (sets or {}).get(key)
        if isinstance(value, (int, float)) and not isinstance(value, bool) and value > 0:
            bounds[field] = min(float(getattr(scale, field)), float(value))
    if bounds:
        try:
            scale = replace(scale, **bounds)
        except ParameterError as exc:
            raise ParameterError(f"the --set limits leave no room for the experiment: {exc}") from None
    return experiment_config(scale, args.profile)


def node_values(config: dict, profile: str, sized_flat: dict) -> dict:
    """The experiment node's parameters: the sized values and whatever the limits fit changed."""
    from friction_ros.core.experiment.excitation_config import SECTIONS, profile_defaults

    base = flatten({s: profile_defaults(profile)[s] for s in SECTIONS}, keep_none=True)
    fitted = flatten({s: config[s] for s in SECTIONS}, keep_none=True)
    changed = {k: v for k, v in fitted.items() if base.get(k) != v and k not in sized_flat}
    out = dict(sized_flat)
    out.update({k: fitted[k] for k in sized_flat if k in fitted})
    out.update(changed)
    return typed_like_defaults(out, profile)


def typed_like_defaults(flat: dict, profile: str) -> dict:
    """Plain Python values typed like the declared defaults (ROS parameters are typed: an int where
    a double is declared is refused)."""
    from friction_ros.core.experiment.excitation_config import profile_defaults

    base = flatten(profile_defaults(profile), keep_none=True)
    out = {}
    for k, v in flat.items():
        ref = base.get(k)
        if isinstance(v, (list, tuple)):
            v = [float(x) if isinstance(ref, list) and ref and isinstance(ref[0], float) else x for x in v]
        elif isinstance(ref, float) and not isinstance(v, (bool, str)):
            v = float(v)
        elif isinstance(ref, int) and not isinstance(ref, bool) and not isinstance(v, (bool, str)):
            v = int(v)
        elif hasattr(v, "item"):  # numpy scalar
            v = v.item()
        out[k] = v
    return out
