"""The 7-joint arm example: a plain PD per joint and the friction add-on, sized from the plant file.

For every joint of a multi-joint ``plant_simulator`` file (``params/arm7_plant.yaml``):

* the PD: :func:`~friction_ros.core.experiment.tracking_design.tracking_gains` of the joint's scale
  (phase-margin rule with the encoder bound), the "plain joint controller" an arm already has;
* the reference: :func:`~friction_ros.core.experiment.tracking_design.tracking_reference`
  (band-limited random motion at friction-dominated speeds, a different seed per joint), given to
  both controllers (on a robot both would follow the arm's JointTrajectory);
* the add-on (``mode: compensation_only``): the joint's steady-state friction map
  (:meth:`~friction_ros.core.presets.Preset.joint_friction`, what a plateau experiment and
  ``friction-fit`` measure) fitted by a Stribeck model ``F(v) = sgn(v) (fc + (fs - fc)
  exp(-(v/vs)^2)) + fv v`` (least squares over the speeds the reference reaches), fed forward from
  the reference velocity (plus a voltage drive's back-EMF damping, which the commanded torque
  sees as viscous friction), and the plant's gravity load ``gravity sin(q + gravity_phase)`` as
  ``load.gravity``/``load.gravity_phase`` at the measured position (sign: the plant's load is
  ``-gravity sin(q + phase)``, the compensation adds ``+gravity sin(q + phase)``).

:func:`arm_parameter_document` returns the parameter document (YAML-ready) of both nodes.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

import numpy as np
from scipy.optimize import least_squares

from friction_ros.core.experiment.joint_scale import JointScale
from friction_ros.core.experiment.tracking_design import tracking_gains, tracking_reference
from friction_ros.core.joint_config import joint_values
from friction_ros.core.presets import Preset, resolve_preset

PLANT_SECTIONS = ("plant", "friction_motor", "friction_load")


def _r(x: float) -> float:
    """Six significant digits: a readable parameter file, same numbers on every machine."""
    return float(f"{float(x):.6g}")


def joint_presets(plant_values: Mapping[str, Any]) -> list[tuple[str, Preset]]:
    """``(joint, preset with the joint's overrides)`` of a multi-joint plant_simulator parameter set."""
    joints = list(plant_values["joints"])
    presets = list(plant_values.get("presets") or [plant_values.get("preset", "abb_m19s")] * len(joints))
    period = float(plant_values.get("control_period", 1e-3))
    out = []
    for joint, name in zip(joints, presets):
        sections = {s: {} for s in PLANT_SECTIONS}
        own: dict[str, Any] = {}
        for s in PLANT_SECTIONS:
            for k, v in (plant_values.get(s) or {}).items():
                if k == joint and isinstance(v, Mapping):
                    own.update({f"{s}.{kk}": vv for kk, vv in v.items()})
                elif k not in joints:
                    sections[s][k] = v
        sections = joint_values(sections, own, {"friction_motor": "model", "friction_load": "model"})
        out.append((joint, resolve_preset(name, {**sections, "control_period": period})))
    return out


def stribeck_map(preset: Preset, v_max: float) -> dict[str, float]:
    """Stribeck coefficients fitted to the joint's steady-state friction on ``|v| <= v_max``."""
    v = np.geomspace(v_max * 1e-3, v_max, 200)
    f = 0.5 * (np.abs(preset.joint_friction(v)) + np.abs(preset.joint_friction(-v)))

    def model(x):
        fc, fs, vs, fv = x
        return fc + (fs - fc) * np.exp(-((v / vs) ** 2)) + fv * v

    fc0 = float(np.min(f))
    x0 = [fc0, float(f[0]), v_max * 0.05, max((float(f[-1]) - fc0) / v_max, 0.0)]
    lo = [0.0, 0.0, v_max * 1e-4, 0.0]
    hi = [np.inf, np.inf, v_max * 10, np.inf]
    res = least_squares(lambda x: model(x) - f, x0, bounds=(lo, hi))
    return canonical_stribeck(*(float(a) for a in res.x), f_scale=float(np.max(f)), v_max=v_max)


FIT_PRECISION = 1e-6  # relative to the joint's friction scale: below it the data fix no coefficient


def canonical_stribeck(fc: float, fs: float, vs: float, fv: float, f_scale: float, v_max: float) -> dict:
    """The Stribeck map with the coefficients the data do not determine written in one form.

    A term whose largest effect on ``|v| <= v_max`` stays below ``FIT_PRECISION * f_scale`` is not
    measured: ``fv v_max`` that small gives ``fv = 0``; ``fs - fc`` that small gives ``fs = fc``, and
    then ``F`` does not depend on ``vs``, which is written as ``0.05 v_max`` (the fit's start). The
    optimiser's last digits there differ between machines; the canonical form does not.
    """
    floor = FIT_PRECISION * f_scale
    fs = max(fs, fc)
    if fv * v_max < floor:
        fv = 0.0
    if fs - fc < floor:
        fs, vs = fc, 0.05 * v_max
    return {"model": "stribeck", "fc": fc, "fs": fs, "vs": vs, "fv": fv}


def arm_parameter_document(
    plant_values: Mapping[str, Any], duration: float = 20.0
) -> tuple[dict[str, Any], list[dict[str, Any]]]:
    """(parameter document of ``pd_controller`` and ``friction_addon``, per-joint design table)."""
    joints = list(plant_values["joints"])
    pd: dict[str, Any] = {"joints": joints, "mode": "pid", "gains": {}, "reference": {}}
    addon: dict[str, Any] = {
        "joints": joints,
        "mode": "compensation_only",
        "sum_base_command": True,
        "compensation": {"source": "feedforward", "smoothing": "tanh"},
        "gains": {},
        "friction": {},
        "load": {},
        "reference": {},
    }
    table = []
    for i, (joint, preset) in enumerate(joint_presets(plant_values)):
        scale = JointScale.from_preset(preset, period=float(plant_values.get("control_period", 1e-3)))
        gains = tracking_gains(scale)
        ref = tracking_reference(scale, duration=duration, seed=i + 1)
        v_rms = ref["amplitude"] * 2.0 * math.pi * ref["cutoff"] / math.sqrt(3.0)
        friction = stribeck_map(preset, 4.0 * v_rms)
        # a voltage drive's back-EMF acts as viscous friction on the commanded torque (what
        # friction-fit measures on such a joint): the scale's damping beyond the friction's viscous part
        friction["fv"] += max(float(scale.damping) - float(scale.viscous), 0.0)
        smoothing = min(0.1 * friction["vs"], 0.05 * v_rms)  # tanh near reversals of the reference
        friction = {k: (v if isinstance(v, str) else _r(v)) for k, v in friction.items()}
        ref = {k: (_r(v) if isinstance(v, float) else v) for k, v in ref.items()}
        pd["gains"][joint] = {"p": _r(gains["p"]), "i": 0.0, "d": _r(gains["d"])}
        pd["reference"][joint] = dict(ref)
        addon["reference"][joint] = dict(ref)
        addon["friction"][joint] = friction
        addon.setdefault("compensation", {})[joint] = {"smoothing_velocity": _r(smoothing)}
        p = preset.params
        gravity = float(getattr(p, "gravity", 0.0) or 0.0)
        if gravity:
            addon["load"][joint] = {
                "gravity": _r(gravity),
                "gravity_phase": _r(getattr(p, "gravity_phase", 0.0)),
            }
        limit = _r(scale.torque_limit)
        pd["gains"][joint]["effort_limit"] = limit
        addon["gains"][joint] = {"effort_limit": limit}  # the sum sent to the joint stays inside it
        table.append(
            {
                "joint": joint,
                "preset": preset.name,
                "p": gains["p"],
                "d": gains["d"],
                "amplitude": ref["amplitude"],
                "cutoff": ref["cutoff"],
                "fc": friction["fc"],
                "fs": friction["fs"],
                "gravity": gravity,
                "torque_limit": limit,
            }
        )
    for key in ("load",):
        if not addon[key]:
            addon.pop(key)
    return {
        "/**/pd_controller": {"ros__parameters": pd},
        "/**/friction_addon": {"ros__parameters": addon},
    }, table
