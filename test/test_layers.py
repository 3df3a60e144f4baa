"""The pure core in layers: every import (module level AND inside functions) points to the same layer
or a lower one, never back up; a function-level import never hides a cycle and loads a third-party
package only from the allow-list of optional heavy dependencies. The layers are documented in
docs/architecture.md ("Layers of the core")."""

from __future__ import annotations

import sys

from import_scan import import_graph, imports, package_modules, target

CORE = "friction_ros.core"

#: the core's layers, lowest first; a module belongs to the first layer whose prefix it matches
LAYERS: list[tuple[str, tuple[str, ...]]] = [
    (
        "foundations",
        (
            "validation",
            "config",
            "yaml_files",
            "control_period",
            "joint_config",
            "joint_type",
            "input_gate",
            "joint_channel",
            "coefficient_exchange",
            "command_sources",
            "plotting",
        ),
    ),
    ("wire", ("wire",)),  # the CDR wire format and the nodes' message codecs
    ("bag", ("bag",)),  # rosbag2 MCAP files: writer, scan, schema-driven CDR
    ("friction", ("friction",)),  # the friction model library
    ("plant", ("plant", "presets")),  # the servo plant and the presets that build it
    ("estimation", ("estimation",)),  # online estimation (the LuGre observer, RLS)
    ("control", ("control",)),  # controllers, compensation, safety
    ("experiment", ("experiment",)),  # what a run does: excitation, references, sizing
    ("can", ("can",)),  # drive codecs, drive logic, drive emulator of a preset
    (
        "simulation",
        ("harness", "compensation_gate", "joint_group", "joint_group_inputs"),
    ),  # closed loop without ROS (N joints: joint_group), the fitter's gate
    # offline identification in three layers: data <- fit <- report (the package re-exports the
    # entry points of all three, so it sits with report)
    ("identification.data", ("identification.data",)),  # logs, records, segments, scales, selection
    ("identification.fit", ("identification.fit",)),  # models, fits, comparison, recommendation
    ("identification.report", ("identification.report", "identification")),  # report, plots, files
    ("fleet", ("fleet",)),  # many runs of many robots: table, trends, wear alarms
    ("synthetic", ("synthetic",)),  # synthetic truths for tests and benchmarks: nothing imports them
]

#: the fitter, which never imports the synthetic truths (it would fit what it simulated itself)
FITTER = CORE + ".identification"
SYNTHETIC = CORE + ".synthetic"

#: third-party packages a core function may import on first use (heavy and optional)
LAZY_THIRD_PARTY = {
    "matplotlib",  # plots of the report
    "numba",  # compiled kernels
    "sklearn",  # learned models
    "torch",
    "scipy",  # signal filters and optimisers of single paths
    "rosbags",  # SQLite3 bags
    "lz4",  # compressed MCAP chunks
    "zstandard",
    "ament_index_python",  # installed share directory (ROS installs only)
    "can",  # python-can
    "yaml",
    "pyarrow",  # the fleet table (Parquet)
    "dask",  # the fleet's distributed fits
    "distributed",
    "canopen",  # CiA 402 drives: the EDS reader and the emulated drive
}


def layer_of(module: str) -> int:
    rest = module[len(CORE) + 1 :]
    for index, (_, prefixes) in enumerate(LAYERS):
        if any(rest == p or rest.startswith(p + ".") for p in prefixes):
            return index
    raise AssertionError(f"{module} is in no layer: add it to LAYERS (and to docs/architecture.md)")


def _core_modules():
    return {m: p for m, p in package_modules().items() if m.startswith(CORE + ".")}


def test_every_core_module_has_a_layer():
    mods = _core_modules()
    assert len(mods) > 100
    layers = {layer_of(m) for m in mods}
    assert layers == set(range(len(LAYERS))), "a layer with no module: remove it"


def test_no_import_points_up_a_layer():
    """No core module imports (at module level or inside a function) from a higher layer."""
    modules = package_modules()
    up = []
    for mod, path in _core_modules().items():
        for imp in imports(path):
            t = target(imp, modules)
            if t.startswith(CORE + ".") and layer_of(t) > layer_of(mod):
                where = "function" if imp.in_function else "module"
                up.append(
                    f"{mod}:{imp.line} ({LAYERS[layer_of(mod)][0]}) -> {t} ({LAYERS[layer_of(t)][0]}), {where} level"
                )
    assert not up, "imports that point up a layer:\n" + "\n".join(sorted(up))


def synthetic_imports(modules: dict) -> list[str]:
    """Every import (module level or in a function) of a fitter module that loads the synthetic truths."""
    out = []
    for mod, path in modules.items():
        if mod == FITTER or mod.startswith(FITTER + "."):
            for imp in imports(path):
                t = target(imp, modules)
                if t == SYNTHETIC or t.startswith(SYNTHETIC + "."):
                    out.append(f"{mod}:{imp.line} -> {t}")
    return out


def test_identification_is_data_fit_report():
    """Every identification module is in data, fit or report, and the three are ordered
    data < fit < report (report may import fit and data, fit may import data, data neither)."""
    loose = [
        m
        for m in _core_modules()
        if m.startswith(FITTER + ".") and m.split(".")[3] not in ("data", "fit", "report")
    ]
    assert not loose, f"identification modules outside data/fit/report: {loose}"
    order = [layer_of(f"{FITTER}.{sub}.x") for sub in ("data", "fit", "report")]
    assert order == sorted(order) and len(set(order)) == 3
    assert layer_of(FITTER) == order[2]


def test_the_fitter_never_imports_the_synthetic_truths():
    modules = package_modules()
    assert any(m.startswith(SYNTHETIC + ".") for m in modules)
    bad = synthetic_imports(modules)
    assert not bad, "the fitter imports the synthetic truths:\n" + "\n".join(sorted(bad))


def test_synthetic_check_sees_a_function_level_import(tmp_path):
    """The check flags a fitter function that imports a synthetic truth."""
    import import_scan

    pkg = tmp_path / "friction_ros" / "core" / "identification" / "fit"
    pkg.mkdir(parents=True)
    probe = pkg / "probe.py"
    probe.write_text("def f():\n    from friction_ros.core.synthetic import plant_runs\n")
    old = import_scan.ROOT
    import_scan.ROOT = tmp_path
    try:
        found = synthetic_imports({FITTER + ".fit.probe": probe})
    finally:
        import_scan.ROOT = old
    assert found == [f"{FITTER}.fit.probe:2 -> {SYNTHETIC}"]


def test_layer_check_sees_an_upward_import(tmp_path):
    """The check flags a function-level import from a lower layer to a higher one."""
    import import_scan

    pkg = tmp_path / "friction_ros" / "core" / "wire"
    pkg.mkdir(parents=True)
    (pkg / "probe.py").write_text("def f():\n    from friction_ros.core.bag.cdr import decode\n")
    old = import_scan.ROOT
    import_scan.ROOT = tmp_path
    try:
        (imp,) = imports(pkg / "probe.py")
    finally:
        import_scan.ROOT = old
    assert imp.in_function and imp.module == "friction_ros.core.bag.cdr"
    assert layer_of(imp.module) > layer_of("friction_ros.core.wire.probe")


def test_function_level_imports_hide_no_cycle():
    """A core function imports a friction_ros module lazily only where the same import at module
    level would create no cycle (it defers a heavy load; it does not hide a cycle)."""
    static = import_graph(module_level_only=True)
    modules = package_modules()

    closure: dict[str, set[str]] = {}

    def reaches(start: str, goal: str) -> bool:
        if start not in closure:  # every module reachable from start (computed once per start)
            seen, todo = set(), [start]
            while todo:
                node = todo.pop()
                if node not in seen:
                    seen.add(node)
                    todo += static.get(node, ())
            closure[start] = seen
        return goal in closure[start]

    hidden = []
    for mod, path in _core_modules().items():
        for imp in imports(path):
            t = target(imp, modules)
            if imp.in_function and t in modules and t != mod and reaches(t, mod):
                hidden.append(f"{mod}:{imp.line} -> {t}")
    assert not hidden, "function-level imports that hide a cycle:\n" + "\n".join(sorted(hidden))


def test_function_level_third_party_imports_are_heavy_optional_ones():
    """A core function imports a package other than friction_ros only if it is in LAZY_THIRD_PARTY
    (the standard library and numpy are imported at module level)."""
    bad = []
    for mod, path in _core_modules().items():
        for imp in imports(path):
            top = imp.module.split(".")[0]
            if imp.in_function and top != "friction_ros" and top not in LAZY_THIRD_PARTY:
                kind = "standard library" if top in sys.stdlib_module_names else "not in LAZY_THIRD_PARTY"
                bad.append(f"{mod}:{imp.line} imports {imp.module} in a function ({kind})")
    assert not bad, "\n".join(sorted(bad))


def test_no_package_module_over_500_lines():
    """Every module of the package stays under 500 lines (split by concept when it grows)."""
    long = {m: n for m, p in package_modules().items() if (n := len(p.read_text().splitlines())) > 500}
    assert not long, f"modules over 500 lines: {long}"


def test_one_flatten():
    """Nested config -> dotted names has one implementation (core.config.flatten)."""
    import ast

    defs = [
        f"{m}.{node.name}"
        for m, p in package_modules().items()
        for node in ast.walk(ast.parse(p.read_text()))
        if isinstance(node, ast.FunctionDef) and node.name.lstrip("_") == "flatten"
    ]
    assert defs == ["friction_ros.core.config.flatten"]
    from friction_ros.core.config import flatten

    nested = {"pid": {"p": 2.0, "i": None}, "joints": ["j1"]}
    assert flatten(nested) == {"pid.p": 2.0, "joints": ["j1"]}
    assert flatten(nested, keep_none=True) == {"pid.p": 2.0, "pid.i": None, "joints": ["j1"]}
