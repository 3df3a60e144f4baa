"""friction_ros uses public rclpy API only.

rclpy's private attributes (``node._parameter_overrides``, ``node._parameters``, ...) and its C
extension (``rclpy.impl.implementation_singleton``, ``_rclpy_pybind11``) change between releases
without notice; an update must not break the nodes. Every ``.py`` under friction_ros/ is scanned:

* by text: ``rclpy.impl``, ``rclpy._...``, ``_rclpy...``, ``_parameter_overrides``,
  ``._parameters``, ``node._...``;
* by syntax: imports of private rclpy modules or names; ``self._x`` in a class derived from an rclpy
  Node where ``_x`` is a private attribute of rclpy's Node (reading or overwriting it); ``obj._x`` on
  anything else where ``_x`` is a private attribute of an rclpy class (Node, Publisher,
  Subscription, Timer, Client, Service, executors, Context, Clock, TimeSource) and no friction_ros
  class defines an attribute of that name itself; the same names given to ``getattr`` & co.

A failure names file:line and what was found. Comments count too: keep the names out of the code.
"""

from __future__ import annotations

import ast
import importlib
import inspect
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = ROOT / "friction_ros"

TEXT_PATTERNS = [
    (re.compile(r"\brclpy\.impl\b"), "rclpy.impl (rclpy's C extension)"),
    (re.compile(r"\brclpy\._"), "a private rclpy module"),
    (re.compile(r"(?<![\w.])_rclpy"), "_rclpy (rclpy's C extension)"),
    (re.compile(r"(?<!\w)_parameter_overrides\b"), "rclpy Node's private _parameter_overrides"),
    (re.compile(r"\._parameters\b"), "rclpy Node's private _parameters"),
    (re.compile(r"\bnode\._(?!_)\w"), "a private attribute of an rclpy Node"),
]

RCLPY_MODULES = {
    "rclpy.node": ["Node"],
    "rclpy.publisher": ["Publisher"],
    "rclpy.subscription": ["Subscription"],
    "rclpy.timer": ["Timer"],
    "rclpy.client": ["Client"],
    "rclpy.service": ["Service"],
    "rclpy.executors": ["Executor", "SingleThreadedExecutor", "MultiThreadedExecutor"],
    "rclpy.context": ["Context"],
    "rclpy.clock": ["Clock", "ROSClock"],
    "rclpy.time_source": ["TimeSource"],
}

_RCLPY_CLASSES = sorted({c for cs in RCLPY_MODULES.values() for c in cs})
MANGLED = re.compile(rf"^_({'|'.join(_RCLPY_CLASSES)})__")  # self.__x inside an rclpy class


def _is_private(name: str) -> bool:
    return name.startswith("_") and not name.startswith("__")


def _private_names(module_name: str, class_names: list[str]) -> set[str]:
    """Private attribute names of rclpy classes: class members and ``self._x`` in their source."""
    module = importlib.import_module(module_name)
    names: set[str] = set()
    for cls_name in class_names:
        cls = getattr(module, cls_name)
        names |= {k for k in vars(cls) if _is_private(k)}
    tree = ast.parse(inspect.getsource(module))
    for n in ast.walk(tree):
        if isinstance(n, ast.Attribute) and isinstance(n.value, ast.Name) and n.value.id == "self":
            if _is_private(n.attr):
                names.add(n.attr)
    return names


@pytest.fixture(scope="module")
def rclpy_private() -> tuple[set[str], set[str]]:
    """(private names of rclpy's Node, private names of all the rclpy classes above)."""
    pytest.importorskip("rclpy")
    node = _private_names("rclpy.node", ["Node"])
    every = set(node)
    for module_name, classes in RCLPY_MODULES.items():
        every |= _private_names(module_name, classes)
    return node, every


def _own_private_names(trees: dict[Path, ast.AST]) -> set[str]:
    """``self._x`` attributes that friction_ros classes define (assign) themselves."""
    own: set[str] = set()
    for tree in trees.values():
        for n in ast.walk(tree):
            if isinstance(n, ast.Attribute) and isinstance(n.ctx, ast.Store):
                if isinstance(n.value, ast.Name) and n.value.id == "self" and _is_private(n.attr):
                    own.add(n.attr)
    return own


def _node_classes(trees: dict[Path, ast.AST]) -> set[str]:
    """Names of friction_ros classes derived (directly or through each other) from rclpy's Node."""
    bases: dict[str, set[str]] = {}
    for tree in trees.values():
        for n in ast.walk(tree):
            if isinstance(n, ast.ClassDef):
                names = set()
                for b in n.bases:
                    if isinstance(b, ast.Name):
                        names.add(b.id)
                    elif isinstance(b, ast.Attribute):
                        names.add(b.attr)
                bases.setdefault(n.name, set()).update(names)
    derived = {"Node"}
    changed = True
    while changed:
        changed = False
        for name, bs in bases.items():
            if name not in derived and bs & derived:
                derived.add(name)
                changed = True
    return derived - {"Node"}


def violations(
    sources: dict[Path, str], node_private: set[str], rclpy_private: set[str], own: set[str] | None = None
) -> list[str]:
    """``file:line: what`` for every private rclpy use in ``sources`` (path -> text)."""
    found: list[str] = []
    trees = {p: ast.parse(text, str(p)) for p, text in sources.items()}
    own = _own_private_names(trees) if own is None else own
    node_classes = _node_classes(trees)

    def rel(p: Path) -> str:
        try:
            return str(p.relative_to(ROOT))
        except ValueError:
            return str(p)

    for path, text in sources.items():
        for lineno, line in enumerate(text.splitlines(), 1):
            for pattern, what in TEXT_PATTERNS:
                if pattern.search(line):
                    found.append(f"{rel(path)}:{lineno}: {what}: {line.strip()}")
        tree = trees[path]
        for n in ast.walk(tree):
            if isinstance(n, ast.ImportFrom) and (n.module or "").split(".")[0] == "rclpy":
                parts = n.module.split(".")
                if any(_is_private(p) or p == "impl" for p in parts) or any(
                    _is_private(a.name) for a in n.names
                ):
                    found.append(f"{rel(path)}:{n.lineno}: private rclpy import from {n.module}")
            elif isinstance(n, ast.Import):
                for a in n.names:
                    parts = a.name.split(".")
                    if parts[0] == "rclpy" and any(_is_private(p) or p == "impl" for p in parts):
                        found.append(f"{rel(path)}:{n.lineno}: private rclpy import {a.name}")
            elif isinstance(n, ast.ClassDef) and n.name in node_classes:
                for m in ast.walk(n):
                    if (
                        isinstance(m, ast.Attribute)
                        and isinstance(m.value, ast.Name)
                        and m.value.id == "self"
                        and m.attr in node_private
                    ):
                        found.append(
                            f"{rel(path)}:{m.lineno}: self.{m.attr} in {n.name} is rclpy Node's private attribute"
                        )
            elif (
                isinstance(n, ast.Call)
                and isinstance(n.func, ast.Name)
                and n.func.id in ("getattr", "setattr", "hasattr", "delattr")
                and len(n.args) >= 2
                and isinstance(n.args[1], ast.Constant)
                and isinstance(n.args[1].value, str)
                and (n.args[1].value in rclpy_private - own or MANGLED.match(n.args[1].value))
            ):
                found.append(
                    f"{rel(path)}:{n.lineno}: {n.func.id}(..., {n.args[1].value!r}) reads rclpy's private attribute"
                )
            elif isinstance(n, ast.Attribute) and MANGLED.match(n.attr):
                found.append(f"{rel(path)}:{n.lineno}: .{n.attr} is a name-mangled rclpy attribute")
            elif isinstance(n, ast.Attribute) and n.attr in rclpy_private and n.attr not in own:
                if not (isinstance(n.value, ast.Name) and n.value.id in ("self", "cls")):
                    found.append(
                        f"{rel(path)}:{n.lineno}: .{n.attr} is a private attribute of an rclpy class"
                    )
    return sorted(set(found), key=lambda s: (s.split(":")[0], int(s.split(":")[1])))


def test_friction_ros_uses_public_rclpy_api_only(rclpy_private):
    node_private, every_private = rclpy_private
    files = sorted(PACKAGE.rglob("*.py"))
    assert len(files) > 20, "the package was not found"
    sources = {p: p.read_text() for p in files}
    bad = violations(sources, node_private, every_private)
    assert not bad, "private rclpy API (breaks on an rclpy update; use the public API):\n" + "\n".join(bad)


def test_the_scan_finds_private_uses(rclpy_private):
    """The scanner itself: each kind of private use in a sample is reported with its line."""
    node_private, every_private = rclpy_private
    sample = """\
from rclpy.impl.implementation_singleton import rclpy_implementation as impl
import rclpy._rclpy_pybind11
from rclpy.node import Node


class MyNode(Node):
    def __init__(self):
        super().__init__("x")
        self._clock = self.get_clock()
        given = self._parameter_overrides


def f(node, sub):
    given = getattr(node, "_parameter_overrides", {}).get("profile")
    names = set(node._parameters)
    handle = sub._Subscription__subscription
    ex = node.executor
    return ex._nodes, names, handle, given


class Own:
    def __init__(self):
        self._lock = None

    def g(self, other):
        return other._lock
"""
    bad = violations({Path("sample.py"): sample}, node_private, every_private)
    lines = {int(b.split(":")[1]) for b in bad}
    assert {1, 2, 9, 10, 14, 15, 16, 18}.issubset(lines), bad
    assert 26 not in lines, bad  # a private name friction_ros defines itself is not rclpy's
    assert all(b.startswith("sample.py:") for b in bad)
