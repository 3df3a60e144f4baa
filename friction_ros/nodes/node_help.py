"""``--help`` / ``-h`` of every node: its purpose and its parameters, printed without starting anything.

:func:`~friction_ros.nodes.runtime.start_process` (and so ``run_node``) calls :func:`exit_if_help`
before rclpy starts: no context, no DDS participant, no CAN bus, no experiment. The text is the
first paragraph of the node module's docstring, the usage of ROS parameters, the node's own
command-line options (if it has an argparse parser) and one line per parameter from the schema the
node declares (:class:`~friction_ros.core.config.Schema`): name, type, default, unit, range.

A node module is found from its node class (``run_node(NodeClass)``) and names its schema as
``parameter_schema()`` (a function with defaults for every argument) or ``SCHEMA``; a new node that
follows that convention gets ``--help`` for free. Imports no rclpy.
"""

from __future__ import annotations

import argparse
import inspect
import sys
from types import ModuleType
from typing import Any

from friction_ros.core.config import Field, Schema

HELP_FLAGS = ("-h", "--help")


def help_requested(args: list[str]) -> bool:
    """True if ``-h``/``--help`` is among the node's own arguments (``args[0]`` is the program; a
    ``--ros-args`` section, up to ``--``, holds ROS arguments and is skipped)."""
    in_ros = False
    for a in args[1:]:
        if a == "--ros-args":
            in_ros = True
        elif a == "--":
            in_ros = False
        elif not in_ros and a in HELP_FLAGS:
            return True
    return False


def node_module(about: Any) -> ModuleType | None:
    """The module of a node class, factory or module (None if it cannot be told)."""
    if isinstance(about, ModuleType):
        return about
    name = getattr(about, "__module__", None) or getattr(getattr(about, "func", None), "__module__", None)
    return sys.modules.get(name) if name else None


def node_schema(module: ModuleType | None) -> Schema | None:
    """The schema a node module declares: ``parameter_schema()`` or ``SCHEMA`` (None if neither)."""
    if module is None:
        return None
    make = getattr(module, "parameter_schema", None)
    if callable(make):
        return make()
    schema = getattr(module, "SCHEMA", None)
    return schema if isinstance(schema, Schema) else None


def _default_text(field: Field) -> str:
    if field.required:
        return "required"
    value = field.default
    if field.is_list:
        return "[" + ", ".join(str(v) for v in value) + "]"
    if isinstance(value, str):
        return repr(value) if value == "" else value
    if isinstance(value, bool):
        return str(value).lower()
    if isinstance(value, float):
        return f"{value:g}"
    return str(value)


def _range_text(field: Field) -> str:
    return field.range_text().split(", i.e.")[0]


def field_line(name: str, field: Field) -> str:
    """``name  type  default [unit]  range  (fixed at start)`` and the meaning on the next line."""
    unit = f" {field.unit}" if field.unit else ""
    parts = [f"  {name}", field.type_name, f"default {_default_text(field)}{unit}"]
    if rng := _range_text(field):
        parts.append(rng)
    if field.read_only:
        parts.append("fixed at start")
    line = "  ".join(parts)
    return f"{line}\n      {field.doc}" if field.doc else line


def parameter_lines(schema: Schema, prefix: str = "") -> list[str]:
    """One entry per field of ``schema`` in declaration order; an open section names the keys it
    takes from a parameter file besides its listed ones."""
    out: list[str] = []
    for item in schema:
        if isinstance(item, Schema):
            name = f"{prefix}{item.name}"
            if item.open:
                doc = f": {item.doc}" if item.doc else ""
                out.append(f"  {name}.*  section{doc}; further keys from the parameter file")
            out.extend(parameter_lines(item, f"{name}."))
        else:
            out.append(field_line(f"{prefix}{item.name}", item))
    return out


def purpose(module: ModuleType | None) -> str:
    """The first paragraph of the module docstring (the node's purpose)."""
    doc = inspect.getdoc(module) if module is not None else None
    return doc.split("\n\n")[0].strip() if doc else ""


def node_help(about: Any, parser: argparse.ArgumentParser | None = None) -> str:
    """The ``--help`` text of a node (``about``: its class, factory or module)."""
    module = node_module(about)
    prog = (module.__name__.rsplit(".", 1)[-1] if module else None) or "node"
    lines = [purpose(module), ""]
    if parser is not None:
        lines += [parser.format_help().rstrip(), ""]
    lines.append(f"usage: {prog} [--ros-args -p NAME:=VALUE ... --params-file FILE]")
    schema = node_schema(module)
    if schema is not None:
        lines += ["", "parameters (type, default and unit, allowed range; revolute joint units):"]
        lines += parameter_lines(schema)
    return "\n".join(lines).strip() + "\n"


def exit_if_help(args: list[str], about: Any, parser: argparse.ArgumentParser | None = None) -> None:
    """Print :func:`node_help` and end the process with exit code 0 if ``--help``/``-h`` was given."""
    if help_requested(args):
        sys.stdout.write(node_help(about, parser))
        sys.stdout.flush()
        raise SystemExit(0)
