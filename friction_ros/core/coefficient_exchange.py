"""Friction model configs <-> the flat (model, names, values) fields of friction_msgs/FrictionEstimate.

A library model config is a nested dict (``{"model": "asymmetric", "base": "stribeck",
"positive": {"fc": ...}, "negative": {...}}``); the message carries one model string and parallel
name/value arrays. String leaves other than ``model`` go into the model string after a colon
(``"asymmetric:base=stribeck"``), numeric leaves get dotted names (``positive.fc``), list leaves
indexed names (``k[0]``). :func:`from_fields` inverts :func:`to_fields` exactly.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

from friction_ros.core.validation import ParameterError


def to_fields(config: Mapping[str, Any]) -> tuple[str, list[str], list[float]]:
    """Model config -> (model string, coefficient names, coefficient values)."""
    if not isinstance(config, Mapping) or "model" not in config:
        raise ParameterError(f"model config = {config!r} must be a mapping with a 'model' key")
    tags: list[str] = []
    names: list[str] = []
    values: list[float] = []

    def walk(d: Mapping[str, Any], prefix: str) -> None:
        for k, v in d.items():
            if prefix == "" and k == "model":
                continue
            key = f"{prefix}{k}"
            if isinstance(v, Mapping):
                walk(v, key + ".")
            elif isinstance(v, str):
                tags.append(f"{key}={v}")
            elif isinstance(v, Sequence):
                for i, x in enumerate(v):
                    names.append(f"{key}[{i}]")
                    values.append(float(x))
            else:
                names.append(key)
                values.append(float(v))

    walk(config, "")
    model = str(config["model"]) + (":" + ",".join(tags) if tags else "")
    return model, names, values


def from_fields(model: str, names: Sequence[str], values: Sequence[float]) -> dict[str, Any]:
    """Inverse of :func:`to_fields`; raises ParameterError on inconsistent fields."""
    if len(names) != len(values):
        raise ParameterError(f"friction estimate has {len(names)} coefficient names but {len(values)} values")
    head, _, tagtext = str(model).partition(":")
    if not head:
        raise ParameterError("friction estimate has an empty model name")
    config: dict[str, Any] = {"model": head}

    def put(path: str, value: Any) -> None:
        parts = path.split(".")
        d = config
        for p in parts[:-1]:
            d = d.setdefault(p, {})
        leaf = parts[-1]
        if leaf.endswith("]") and "[" in leaf:
            base, idx = leaf[:-1].split("[")
            lst = d.setdefault(base, [])
            i = int(idx)
            lst.extend([0.0] * (i + 1 - len(lst)))
            lst[i] = value
        else:
            d[leaf] = value

    for tag in filter(None, tagtext.split(",")):
        key, _, val = tag.partition("=")
        put(key, val)
    for n, v in zip(names, values):
        put(str(n), float(v))
    return config
