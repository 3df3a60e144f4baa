"""Static import scan of friction_ros shared by the import tests (test_foundation, test_layers):
every import statement, at module level and inside functions, relative imports resolved. Imports
under ``if TYPE_CHECKING:`` are left out: they name types for annotations and never run."""

from __future__ import annotations

import ast
import functools
from pathlib import Path
from typing import NamedTuple

ROOT = Path(__file__).resolve().parents[1]


class Import(NamedTuple):
    line: int
    module: str  # absolute module name of the statement
    name: str | None  # the imported name of ``from module import name``, None for ``import module``
    in_function: bool  # the statement is inside a function (runs on first call, not on import)


def module_name(path: Path) -> str:
    parts = list(path.relative_to(ROOT).with_suffix("").parts)
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def imports(path: Path) -> list[Import]:
    """Every import statement of a module, also inside functions and classes (parsed once per
    test process: the import tests scan the same files several times)."""
    return list(_imports(path, path.stat().st_mtime_ns))


@functools.cache
def _imports(path: Path, _mtime_ns: int) -> tuple[Import, ...]:
    tree = ast.parse(path.read_text(), str(path))
    name = module_name(path)
    package = name.split(".") if path.name == "__init__.py" else name.split(".")[:-1]
    in_function = {
        id(inner)
        for node in ast.walk(tree)
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.Lambda))
        for inner in ast.walk(node)
    }
    typing_only = {
        id(inner)
        for node in ast.walk(tree)
        if isinstance(node, ast.If) and _is_type_checking(node.test)
        for stmt in node.body
        for inner in ast.walk(stmt)
    }
    out = []
    for node in ast.walk(tree):
        if id(node) in typing_only:
            continue
        lazy = id(node) in in_function
        if isinstance(node, ast.Import):
            out += [Import(node.lineno, a.name, None, lazy) for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                base = ".".join(
                    package[: len(package) - node.level + 1] + ([node.module] if node.module else [])
                )
            out += [Import(node.lineno, base, a.name, lazy) for a in node.names]
    return tuple(out)


def _is_type_checking(test: ast.expr) -> bool:
    """``TYPE_CHECKING`` or ``typing.TYPE_CHECKING``."""
    return (isinstance(test, ast.Name) and test.id == "TYPE_CHECKING") or (
        isinstance(test, ast.Attribute) and test.attr == "TYPE_CHECKING"
    )


def package_modules() -> dict[str, Path]:
    """Every module of friction_ros: dotted name -> file."""
    return {module_name(p): p for p in (ROOT / "friction_ros").rglob("*.py")}


def target(imp: Import, modules: dict[str, Path]) -> str:
    """The module an import loads (``from package import name`` counts as ``package.name`` when that
    is a module)."""
    full = f"{imp.module}.{imp.name}" if imp.name else imp.module
    return full if full in modules else imp.module


def import_graph(*, module_level_only: bool = False) -> dict[str, set[str]]:
    """Static import graph of friction_ros: module -> the friction_ros modules it imports."""
    modules = package_modules()
    graph: dict[str, set[str]] = {}
    for mod, path in modules.items():
        targets = set()
        for imp in imports(path):
            if module_level_only and imp.in_function:
                continue
            t = target(imp, modules)
            if t in modules and t != mod:
                targets.add(t)
        graph[mod] = targets
    return graph
