"""YAML input files (presets, ROS parameter files, bring-up files) read with one clear error line.

Every reader of a user's YAML file goes through :func:`load_yaml`, so a missing file, a directory,
binary data or a syntax error is one :class:`ParameterError` naming the file and the problem (line
and column for a syntax error) instead of a parser traceback. :func:`check_parameter_file` adds the
shape rcl needs of a ``--params-file`` (node names mapping to ``ros__parameters``), so a node can
refuse a bad file with that line before rcl prints its own error and a traceback.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import yaml

from friction_ros.core.validation import ParameterError


def load_yaml(path: str | os.PathLike, what: str = "file") -> Any:
    """Parse the YAML file ``path``; ParameterError naming ``what`` and the file on any problem."""
    name = f"{what} {str(path)!r}"
    p = Path(path)
    if not p.exists():
        raise ParameterError(f"{name} does not exist")
    if p.is_dir():
        raise ParameterError(f"{name} is a directory, not a YAML file")
    try:
        text = p.read_bytes().decode("utf-8")
    except UnicodeDecodeError:
        raise ParameterError(f"{name} is not a YAML file (binary data, not UTF-8 text)") from None
    except OSError as exc:
        raise ParameterError(f"{name} cannot be read: {exc.strerror}") from None
    if "\0" in text:
        raise ParameterError(f"{name} is not a YAML file (binary data)")
    try:
        return yaml.safe_load(text)
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        where = f" (line {mark.line + 1}, column {mark.column + 1})" if mark is not None else ""
        problem = getattr(exc, "problem", None) or str(exc).splitlines()[0]
        raise ParameterError(f"{name} is not valid YAML{where}: {problem}") from None


def check_parameter_file(path: str | os.PathLike) -> dict:
    """A ROS 2 parameter file: a mapping of node names (or ``/**``) to ``ros__parameters`` mappings.

    Returns the parsed document ({} for an empty file, which sets nothing); raises ParameterError with one line naming the file and the problem.
    Namespaced layouts (``ns: node: ros__parameters:``) are accepted.
    """
    doc = load_yaml(path, "parameter file")
    if doc is None:
        return {}  # an empty file sets nothing (rcl accepts it too)
    shape = (
        "node names mapping to 'ros__parameters:' sections "
        "(e.g. 'plant_simulator: {ros__parameters: {mode: lockstep}}')"
    )
    if not isinstance(doc, dict):
        raise ParameterError(f"parameter file {str(path)!r}: expected {shape}, got a {type(doc).__name__}")

    def walk(d: dict, trail: str) -> None:
        for key, value in d.items():
            where = f"{trail}{key}"
            if key == "ros__parameters":
                if not isinstance(value, dict):
                    raise ParameterError(
                        f"parameter file {str(path)!r}: {where} must be a mapping of parameter names to values"
                    )
                continue
            if not isinstance(key, str) or not isinstance(value, dict):
                raise ParameterError(f"parameter file {str(path)!r}: {where!s} is not {shape}")
            walk(value, where + ".")

    walk(doc, "")
    return doc
