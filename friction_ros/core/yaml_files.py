"""YAML input files (presets, ROS parameter files, bring-up files, bag metadata) read safely, with one clear error line.

Every reader of YAML that comes from outside (a user's file, a bag's metadata, a command-line value)
goes through :func:`load_yaml` (a file) or :func:`parse_yaml` (text), so a missing file, a
directory, binary data or a syntax error is one :class:`ParameterError` naming the file and the
problem (line and column for a syntax error) instead of a parser traceback. Both refuse input that
would take unbounded time or memory to use, whatever its size on disk:

* a file larger than :data:`MAX_FILE_BYTES` (only that much is read: /dev/zero is refused too),
  and anything but a regular file (a FIFO would block the reader);
* nesting deeper than :data:`MAX_DEPTH` (counted with aliases expanded);
* aliases that expand to more than :data:`MAX_ALIAS_EXPANSION` nodes in all (a "billion laughs"
  file of 1 kB: ``a1: &a1 [*a0, *a0, ...]`` repeated grows 4^n), and recursive aliases.

The aliases are measured on the composed node graph (each node's expanded size counted once,
memoised), so the check costs time linear in the file, never in the expansion.
:func:`check_parameter_file` adds the shape rcl needs of a ``--params-file`` (node names mapping
to ``ros__parameters``), so a node can refuse a bad file with that line before rcl prints its own
error and a traceback.
"""

from __future__ import annotations

import os
import stat
from pathlib import Path
from typing import Any

import yaml
from yaml.composer import Composer
from yaml.constructor import SafeConstructor
from yaml.nodes import MappingNode, SequenceNode
from yaml.resolver import Resolver

from friction_ros.core.validation import ParameterError

try:  # libyaml's event parser (C, ~4x faster); composing stays in Python, where the limits are checked
    from yaml._yaml import CParser as _EventParser
except ImportError:  # pragma: no cover - PyYAML without libyaml
    from yaml.loader import Parser, Reader, Scanner

    class _EventParser(Reader, Scanner, Parser):
        def __init__(self, stream):
            Reader.__init__(self, stream)
            Scanner.__init__(self)
            Parser.__init__(self)


MAX_FILE_BYTES = 1 << 20  # 1 MiB: the largest parameter file shipped is ~10 kB
MAX_DEPTH = 64  # nesting levels (a parameter file uses ~6)
MAX_ALIAS_EXPANSION = 100_000  # nodes that aliases may add in all (a shared gain table: tens)


class YamlLimitError(ParameterError):
    """YAML input exceeds one of the limits (size, depth, alias expansion)."""


class _LimitedLoader(Composer, SafeConstructor, Resolver, _EventParser):
    """yaml.SafeLoader's composer and constructor over libyaml's events; composing stops past
    :data:`MAX_DEPTH` (before Python's recursion limit)."""

    def __init__(self, stream):
        _EventParser.__init__(self, stream)
        Composer.__init__(self)
        SafeConstructor.__init__(self)
        Resolver.__init__(self)
        self._depth = 0

    def compose_node(self, parent, index):
        self._depth += 1
        try:
            if self._depth > MAX_DEPTH:
                mark = self.peek_event().start_mark
                raise YamlLimitError(
                    f"nested deeper than the limit of {MAX_DEPTH} levels (line {mark.line + 1}, column {mark.column + 1})"
                )
            return Composer.compose_node(self, parent, index)
        finally:
            self._depth -= 1


def _measure(root) -> tuple[int, int, int]:
    """(nodes in the file, nodes with aliases expanded, depth with aliases expanded) of a node graph.

    Iterative post-order walk over distinct nodes: each node's expanded size and depth are computed
    once (memoised by identity), so a graph whose expansion is astronomic is measured in linear time.
    Raises YamlLimitError for a recursive alias (a node that contains itself).
    """
    size: dict[int, int] = {}
    depth: dict[int, int] = {}
    active: set[int] = set()
    stack: list[tuple[Any, bool]] = [(root, False)]
    while stack:
        node, done = stack.pop()
        key = id(node)
        if done:
            kids = _children(node)
            size[key] = 1 + sum(size[id(k)] for k in kids)
            depth[key] = 1 + max((depth[id(k)] for k in kids), default=0)
            active.discard(key)
            continue
        if key in size:
            continue
        active.add(key)
        stack.append((node, True))
        for kid in _children(node):
            if id(kid) in active:
                raise YamlLimitError("a recursive alias (a node that contains itself)")
            if id(kid) not in size:
                stack.append((kid, False))
    return len(size), size[id(root)], depth[id(root)]


def _children(node) -> list:
    if isinstance(node, SequenceNode):
        return node.value
    if isinstance(node, MappingNode):
        return [x for kv in node.value for x in kv]
    return []


def parse_yaml(text: str, name: str = "YAML text") -> Any:
    """Parse YAML ``text`` safely (plain data, the limits of this module); ``name`` starts every error line."""
    loader = _LimitedLoader(text)
    try:
        root = loader.get_single_node()
        if root is None:
            return None
        distinct, expanded, depth = _measure(root)
        if expanded - distinct > MAX_ALIAS_EXPANSION:
            raise YamlLimitError(
                f"its aliases expand to {expanded - distinct:.3g} more nodes, over the limit of "
                f"{MAX_ALIAS_EXPANSION} (nested aliases multiply)"
            )
        if depth > MAX_DEPTH:
            raise YamlLimitError(
                f"nested {depth} levels deep with its aliases, over the limit of {MAX_DEPTH}"
            )
        return loader.construct_document(root)
    except YamlLimitError as exc:
        raise YamlLimitError(f"{name} refused: {exc}") from None
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        where = f" (line {mark.line + 1}, column {mark.column + 1})" if mark is not None else ""
        problem = getattr(exc, "problem", None) or str(exc).splitlines()[0]
        raise ParameterError(f"{name} is not valid YAML{where}: {problem}") from None
    finally:
        loader.dispose()


def load_yaml(path: str | os.PathLike, what: str = "file") -> Any:
    """Parse the YAML file ``path``; ParameterError naming ``what`` and the file on any problem."""
    name = f"{what} {str(path)!r}"
    p = Path(path)
    try:
        st = p.stat()
    except FileNotFoundError:
        raise ParameterError(f"{name} does not exist") from None
    except OSError as exc:
        raise ParameterError(f"{name} cannot be read: {exc.strerror}") from None
    if stat.S_ISDIR(st.st_mode):
        raise ParameterError(f"{name} is a directory, not a YAML file")
    if not stat.S_ISREG(st.st_mode):
        raise ParameterError(f"{name} is not a regular file (a device, pipe or socket): give a YAML file")
    if st.st_size > MAX_FILE_BYTES:
        raise YamlLimitError(f"{name} refused: {st.st_size} bytes, over the limit of {MAX_FILE_BYTES} bytes")
    try:
        with open(p, "rb") as fh:
            data = fh.read(MAX_FILE_BYTES + 1)
    except OSError as exc:
        raise ParameterError(f"{name} cannot be read: {exc.strerror}") from None
    if len(data) > MAX_FILE_BYTES:  # grew since stat
        raise YamlLimitError(f"{name} refused: over the limit of {MAX_FILE_BYTES} bytes")
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError:
        raise ParameterError(f"{name} is not a YAML file (binary data, not UTF-8 text)") from None
    if "\0" in text:
        raise ParameterError(f"{name} is not a YAML file (binary data)")
    return parse_yaml(text, name)


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
