"""Fitted coefficients -> friction-library configs and the ROS parameter YAML the nodes load.

The library configs themselves (``model.to_config()`` form) come from the fit
(:func:`~friction_ros.core.identification.fit.fit_registry.library_config`); ``anfis``/``nusvr``
have no library model: no config (JSON summary only).

Parameter file (``node_name: ros__parameters:``):

* ``compensating_controller``: ``inertia`` and ``friction.model`` (the config dict);
* ``friction_estimator``: ``inertia``, the nearest estimator ``model`` (lugre, stribeck,
  coulomb_viscous or their asymmetric forms) with ``initial`` coefficients in the library config's
  layout (``positive: {fc, fv}`` ...) (and ``lugre`` config);
* every section: ``joint_type`` (the fit's, ``FitResult.options["joint_type"]``);
* ``plant_simulator``: a preset section with ``plant.motor_inertia`` and ``friction_motor``
  (loadable by :func:`friction_ros.core.presets.preset_from_config`).
"""

from __future__ import annotations

import math
from typing import Any

import yaml

from friction_ros.core.identification.fit.fit_units import fit_joint_type
from friction_ros.core.validation import ParameterError


def estimator_section(config: dict, inertia: float) -> dict:
    """friction_estimator parameters nearest to a library config."""
    m = config.get("model")
    out: dict[str, Any] = {"inertia": float(inertia)}
    if m == "lugre":
        out.update({"model": "lugre", "lugre": dict(config)})
        return out
    if m == "asymmetric":
        p, n = config["positive"], config["negative"]
        if config.get("base") == "coulomb_viscous":
            out.update(
                {
                    "model": "asymmetric_coulomb_viscous",
                    "initial": {
                        "positive": {"fc": p["fc"], "fv": p["fv"]},
                        "negative": {"fc": n["fc"], "fv": n["fv"]},
                    },
                }
            )
            return out
        if config.get("base") == "stribeck":
            out.update(
                {
                    "model": "asymmetric_stribeck",
                    "vs": p["vs"],
                    "delta": p["delta"],
                    "initial": {
                        "positive": {"fc": p["fc"], "fs": p["fs"], "fv": p["fv"]},
                        "negative": {"fc": n["fc"], "fs": n["fs"], "fv": n["fv"]},
                    },
                }
            )
            return out
        config = {"model": config.get("base"), **p}
        m = config["model"]
    if m in ("coulomb", "coulomb_viscous"):
        out.update({"model": "coulomb_viscous", "initial": {"fc": config["fc"], "fv": config.get("fv", 0.0)}})
        return out
    # stribeck family, GMS, Dahl: the steady-state Stribeck curve
    fc = config.get("fc", 0.0)
    out.update(
        {
            "model": "stribeck",
            "vs": config.get("vs", 0.05),
            "delta": config.get("delta", 2.0),
            "initial": {"fc": fc, "fs": config.get("fs", fc), "fv": config.get("fv", 0.0)},
        }
    )
    return out


def compensation_section(gate=None) -> dict:
    """``compensation`` of compensating_controller from the safety gate's verdicts.

    ``source`` is the enabled mode with the lowest RMS on the identified plant (``none`` when the
    gate enabled nothing); ``refused``/``refused_reasons`` list what it refused and why (the node
    will not start with a refused source unless ``allow_refused`` is set). Without a verdict the
    file says feedforward, as before the gate existed.
    """
    if not gate:
        return {"source": "feedforward", "gain": 1.0}
    enabled = [m for m, v in gate.items() if v.enabled]
    best = min(enabled, key=lambda m: gate[m].worst_ratio) if enabled else "none"
    sec: dict = {"source": best, "gain": 1.0, "blend": 0.5}
    refused = [m for m, v in gate.items() if not v.enabled]
    if refused:
        sec["refused"] = refused
        sec["refused_reasons"] = [gate[m].reason for m in refused]
    return sec


def parameter_document(
    config: dict,
    inertia: float,
    *,
    description: str = "",
    plant_preset=None,
    gate=None,
    gains: dict | None = None,
    load_feedforward: float = 0.0,
    load: dict | None = None,
    residual: dict | None = None,
    joint_type: str = "revolute",
    effort_limit: float = float("nan"),
) -> dict:
    """The ROS parameter YAML document for the three nodes.

    ``effort_limit``: the joint's torque (force) limit the controller clamps every command to
    (left out when not finite: the controller then refuses to start until one is given).

    Every section sets ``joint_type`` (revolute or prismatic), so the nodes read the coefficients
    in the joint's units (N*m, rad/s or N, m/s).

    ``plant_preset`` (name or path): the plant_simulator section starts from that preset's plant
    parameters (torque constant, encoder ...) with the identified inertia and friction; without it
    the section is a whole plant of its own: the identified joint as a direct-drive, torque-commanded
    joint (``torque_constant`` 1 N*m/A, gear ratio 1, ideal sensing), which the node runs as it is.
    ``gate``: the
    safety gate's verdicts (:func:`compensation_section`); ``gains``: the tracking PD written as
    ``pid``; ``load_feedforward``: a constant load the controller holds. ``load``: the identified
    load, gravity and position terms (:class:`~friction_ros.core.friction.joint_load.JointLoad`
    config), ``residual``: a learned residual model's config
    (:mod:`~friction_ros.core.friction.learned_residual`); both go to compensating_controller as
    feedforward.
    """
    plant: dict = {"actuation": "torque", "motor_inertia": float(inertia), "torque_constant": 1.0}
    if plant_preset:
        from friction_ros.core.presets import load_preset

        pc = load_preset(plant_preset).params.to_config()["plant"]
        if pc.get("gear_ratio", 1.0) == 1.0 and not pc.get("load_inertia"):
            pc["motor_inertia"] = float(inertia)
        plant = pc
    return {
        # node layout (config_from_ros_parameters): friction = the model, compensation = how it is applied
        "compensating_controller": {
            "ros__parameters": {
                "joint_type": joint_type,
                **({"effort_limit": float(effort_limit)} if math.isfinite(effort_limit) else {}),
                "inertia": float(inertia),
                **({"pid": {k: float(v) for k, v in gains.items()}} if gains else {}),
                **({"load_feedforward": float(load_feedforward)} if load_feedforward else {}),
                **({"load": ros_section(load)} if load else {}),
                **({"residual": ros_section(residual)} if residual else {}),
                "friction": config,
                "compensation": compensation_section(gate),
            }
        },
        "friction_estimator": {
            "ros__parameters": {"joint_type": joint_type, **estimator_section(config, inertia)}
        },
        "plant_simulator": {
            "ros__parameters": {
                # "" = no base preset: the plant section below is the whole plant
                "preset": str(plant_preset) if plant_preset else "",
                "joint_type": joint_type,
                "description": description or f"identified by friction-fit ({config.get('model')})",
                "plant": plant,
                "friction_motor": config,
            }
        },
    }


def fit_parameter_document(res, model: str | None = None, **gate_options) -> dict:
    """The parameter document of a :class:`~friction_ros.core.identification.fit.fit_results.FitResult`
    for ``model`` (default: the recommended one); ``gate_options``: ``gate`` (verdicts), ``gains``,
    ``load_feedforward`` of :func:`parameter_document` (defaults from the fit's options)."""
    name = model or res.recommended
    m = res.models[name]
    if m.config is None:
        raise ParameterError(f"model {name!r} has no friction-library form: choose a parametric model")
    opts = dict(res.options.get("gate_options") or {}, **gate_options)
    opts.setdefault("load_feedforward", float(res.options.get("load_offset", 0.0) or 0.0))
    opts.setdefault("load", m.extra.get("load"))
    opts.setdefault("residual", m.extra.get("residual"))
    opts.setdefault("effort_limit", res.effort_limit)
    return parameter_document(
        m.config,
        m.coefficients.get("J", 0.0),
        plant_preset=res.options.get("plant_preset"),
        joint_type=fit_joint_type(res),
        **opts,
    )


def ros_section(section: dict) -> dict:
    """``section`` without empty lists: rcl gives ``key: []`` no type and rclpy refuses such a
    parameter file; an empty list is every list field's default anyway."""
    out = {}
    for k, v in section.items():
        if isinstance(v, dict):
            out[k] = ros_section(v)
        elif not (isinstance(v, (list, tuple)) and len(v) == 0):
            out[k] = v
    return out


def dump_yaml(doc: dict, header: str = "") -> str:
    def clean(x):
        if isinstance(x, dict):
            return {k: clean(v) for k, v in x.items()}
        if isinstance(x, (list, tuple)):
            return [clean(v) for v in x]
        if hasattr(x, "item"):
            return x.item()
        return x

    text = yaml.safe_dump(clean(doc), sort_keys=False, default_flow_style=None)
    return (header + "\n" if header else "") + text
