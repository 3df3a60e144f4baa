"""The joint type of a fit and the units its outputs are written in.

The fit itself works in SI numbers only; its outputs (report, ``summary.json``, the parameter
file) name the units of the joint: rad, rad/s, N*m, kg*m^2 on a revolute joint, m, m/s, N, kg
on a prismatic one. The joint type is ``FitResult.options["joint_type"]`` (revolute when absent).
"""

from __future__ import annotations

import re

from friction_ros.core.joint_type import DEFAULT_JOINT_TYPE, check_joint_type, joint_unit, quantity_units

#: coefficients of a fit that no friction model lists: the inertia and the linear zone of sgn(v)
_EXTRA = {"J": "kg*m^2", "eps": "rad/s"}


def fit_joint_type(res) -> str:
    """``res.options["joint_type"]`` (a FitResult, or its options dict), checked; revolute if absent."""
    options = res if isinstance(res, dict) else getattr(res, "options", {}) or {}
    return check_joint_type(options.get("joint_type") or DEFAULT_JOINT_TYPE)


def units(joint_type: str) -> dict[str, str]:
    """``position``, ``velocity``, ``acceleration``, ``friction``, ``effort``, ``J`` units of the joint."""
    return quantity_units(joint_type)


def units_note(joint_type: str) -> str:
    """``N*m, rad/s, kg*m^2`` (revolute) or ``N, m/s, kg`` (prismatic): the parameter file's header."""
    u = quantity_units(joint_type)
    return f"{u['friction']}, {u['velocity']}, {u['J']}"


def coefficient_unit(model: str, config: dict | None, name: str, joint_type: str) -> str:
    """The unit of fitted coefficient ``name`` of ``model`` (``gms4``, ``stribeck`` ...) on the joint;
    '' when unknown or dimensionless."""
    from friction_ros.core.friction import MODEL_CLASSES

    base = (config or {}).get("model") if isinstance(config, dict) else None
    if base == "asymmetric":
        base = config.get("base")
    base = base or re.sub(r"\d+d?$", "", model)
    cls = MODEL_CLASSES.get(base)
    for f in getattr(cls, "COEFS", ()):
        if f.name == name:
            return joint_unit(f.unit, joint_type)
    return joint_unit(_EXTRA.get(name, ""), joint_type)
