"""Issue 2: the package builds with colcon, messages cross processes, the core is rclpy-free."""

from __future__ import annotations

import ast
import os
import re
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest
from import_scan import import_graph, imports

ROOT = Path(__file__).resolve().parents[1]
MSG_TYPES = ["DriveState", "FrictionEstimate", "ControllerState", "ExperimentEvent"]


#: top-level packages the pure core must not import: rclpy and the ROS message/IDL packages
ROS_PACKAGES = (
    "rclpy",
    "rosidl",
    "rmw",
    "rcl_interfaces",
    "builtin_interfaces",
    "std_msgs",
    "sensor_msgs",
    "trajectory_msgs",
    "diagnostic_msgs",
    "friction_msgs",
    "launch",
    "launch_ros",
)


def _imports(path: Path) -> list[tuple[int, str, str | None]]:
    """Every import statement of a module, also inside functions: ``(line, module, name or None)``."""
    return [(imp.line, imp.module, imp.name) for imp in imports(path)]


def _import_graph() -> dict[str, set[str]]:
    return import_graph()


def test_pure_core_imports_without_rclpy():
    """No module under friction_ros/core imports rclpy or a ROS message package, checked statically
    on every import statement (module level and inside functions)."""
    files = sorted((ROOT / "friction_ros" / "core").rglob("*.py"))
    assert len(files) >= 1
    bad = []
    for path in files:
        for line, module, _ in _imports(path):
            top = module.split(".")[0]
            if (
                top in ROS_PACKAGES
                or top.startswith("rosidl")
                or module.endswith((".msg", ".srv", ".action"))
            ):
                bad.append(f"{path.relative_to(ROOT)}:{line}: import {module}")
    assert not bad, "the pure core imports ROS packages:\n" + "\n".join(bad)


def test_every_core_module_imports_without_rclpy():
    """Every module under friction_ros.core imports with rclpy made unimportable."""
    code = textwrap.dedent(
        """
        import importlib, pkgutil, sys
        class Block:
            def find_spec(self, name, path=None, target=None):
                if name == 'rclpy' or name.startswith('rclpy.'):
                    raise ImportError('rclpy is blocked: the pure core must not import it')
        sys.meta_path.insert(0, Block())
        import friction_ros.core as core
        names = [m.name for m in pkgutil.walk_packages(core.__path__, 'friction_ros.core.')]
        for name in names:
            importlib.import_module(name)
        assert 'rclpy' not in sys.modules
        print(len(names))
        """
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT, timeout=120)
    assert out.returncode == 0, out.stderr
    assert int(out.stdout.strip().splitlines()[-1]) >= 1


def test_import_graph_has_no_circles():
    """The static import graph of friction_ros (module-level and function-level imports) is acyclic."""
    graph = _import_graph()
    assert len(graph) > 50
    state: dict[str, int] = {}  # 1: on the current path, 2: done
    circles = []

    def visit(node: str, path: list[str]) -> None:
        state[node] = 1
        for nxt in sorted(graph[node]):
            if state.get(nxt) == 1:
                circles.append(
                    " -> ".join(path[path.index(nxt) :] + [node, nxt]) if nxt in path else f"{node} -> {nxt}"
                )
            elif nxt not in state:
                visit(nxt, path + [node])
        state[node] = 2

    for node in sorted(graph):
        if node not in state:
            visit(node, [])
    assert not circles, "import circles:\n" + "\n".join(circles)


def test_import_graph_sees_function_level_imports():
    """The graph the circle test walks includes imports inside functions (a lazy import is an edge)."""
    graph = _import_graph()
    lazy = import_graph(module_level_only=True)
    # the controller's compensation loads the friction models on first use (their compiled kernels)
    edge = "friction_ros.core.friction.registry"
    assert edge in graph["friction_ros.core.control.compensation"]
    assert edge not in lazy["friction_ros.core.control.compensation"]


@pytest.mark.ros
def test_every_package_import_resolves_also_inside_functions():
    """Every ``from friction_ros.x import y`` in the package, tests, benchmarks and scripts (module
    level and inside functions, which only run on some paths) names a module and a name that exist."""
    import importlib

    missing = []
    for folder in ("friction_ros", "test", "bench", "scripts"):
        for path in sorted((ROOT / folder).rglob("*.py")):
            for node in ast.walk(ast.parse(path.read_text())):
                if not (isinstance(node, ast.ImportFrom) and node.level == 0 and node.module):
                    continue
                if not node.module.startswith("friction_ros"):
                    continue
                where = f"{path.relative_to(ROOT)}:{node.lineno}"
                try:
                    module = importlib.import_module(node.module)
                except ImportError as exc:
                    missing.append(f"{where} {node.module} ({exc})")
                    continue
                for alias in node.names:
                    if alias.name == "*" or hasattr(module, alias.name):
                        continue
                    try:
                        importlib.import_module(f"{node.module}.{alias.name}")
                    except ImportError:
                        missing.append(f"{where} {node.module}.{alias.name}")
    assert not missing, "imports that fail:\n" + "\n".join(missing)


def test_custom_messages_round_trip_between_processes():
    """Each friction_msgs message published in another process arrives field-for-field equal."""
    import rclpy
    from friction_msgs import msg as fmsg
    from msg_samples import diff, fill

    from friction_ros.nodes.qos import STATE_QOS

    publisher = textwrap.dedent(
        f"""
        import sys, time, rclpy
        sys.path.insert(0, {str(ROOT / "test")!r})
        from msg_samples import fill
        from friction_msgs import msg as fmsg
        from friction_ros.nodes.qos import STATE_QOS
        rclpy.init()
        node = rclpy.create_node('roundtrip_pub')
        types = {MSG_TYPES!r}
        pubs = {{t: node.create_publisher(getattr(fmsg, t), 'roundtrip_' + t, STATE_QOS) for t in types}}
        end = time.monotonic() + 20
        while time.monotonic() < end:
            for t, p in pubs.items():
                p.publish(fill(getattr(fmsg, t)(), seed=7))
            time.sleep(0.05)
        """
    )
    proc = subprocess.Popen([sys.executable, "-c", publisher], cwd=ROOT)
    rclpy.init()
    node = rclpy.create_node("roundtrip_sub")
    received: dict[str, object] = {}
    for t in MSG_TYPES:
        node.create_subscription(
            getattr(fmsg, t), "roundtrip_" + t, lambda m, t=t: received.setdefault(t, m), STATE_QOS
        )
    try:
        deadline = time.monotonic() + 20
        while len(received) < len(MSG_TYPES) and time.monotonic() < deadline:
            rclpy.spin_once(node, timeout_sec=0.1)
    finally:
        node.destroy_node()
        rclpy.try_shutdown()
        proc.kill()
        proc.wait()
    assert sorted(received) == sorted(MSG_TYPES), f"missing: {set(MSG_TYPES) - set(received)}"
    for t in MSG_TYPES:
        expected = fill(getattr(fmsg, t)(), seed=7)
        assert diff(expected, received[t]) == [], t
        assert len(expected.get_fields_and_field_types()) >= 6


@pytest.mark.slow
def test_colcon_build_of_fresh_clone(tmp_path):
    """A clone in ws/src builds both packages with colcon; console scripts land in lib/friction_ros."""
    ws = tmp_path / "ws"
    (ws / "src").mkdir(parents=True)
    subprocess.run(["git", "clone", "-q", str(ROOT), str(ws / "src" / "friction_ros")], check=True)
    venv = Path(sys.prefix)
    env = dict(os.environ, AMENT_PREFIX_PATH=str(venv), CMAKE_PREFIX_PATH=str(venv))
    env["PATH"] = f"{venv / 'bin'}:{env['PATH']}"
    # The command documented in README for a Jazzy workspace.
    cmd = [
        str(venv / "bin" / "colcon"),
        "build",
        "--base-paths",
        "src",
        "src/friction_ros/msg_defs",
        "--cmake-args",
        "-DBUILD_TESTING=OFF",
        "--event-handlers",
        "console_direct-",
    ]
    out = subprocess.run(cmd, cwd=ws, env=env, capture_output=True, text=True, timeout=600)
    assert out.returncode == 0, out.stdout[-3000:] + out.stderr[-3000:]
    assert "2 packages finished" in out.stdout
    scripts = ws / "install" / "friction_ros" / "lib" / "friction_ros"
    setup_py = (ROOT / "setup.py").read_text()
    names = [
        line.split("=")[0].strip().strip('"')
        for line in setup_py.split("ENTRY_POINTS = [")[1].split("]")[0].splitlines()
        if "=" in line
    ]
    assert names, "no console scripts declared"
    for name in names:
        assert (scripts / name).is_file(), f"{name} missing in {scripts}"
    share = ws / "install" / "friction_ros" / "share" / "friction_ros"
    assert (share / "package.xml").is_file()
    tracked = subprocess.run(
        ["git", "ls-files", "params/*.yaml"], cwd=ROOT, capture_output=True, text=True
    ).stdout
    assert sorted(p.name for p in (share / "params").glob("*.yaml")) == sorted(
        Path(p).name for p in tracked.split()
    )
    generated = (
        ws / "install" / "friction_msgs" / "lib" / "python3.11" / "site-packages" / "friction_msgs" / "msg"
    )
    for t in MSG_TYPES:
        snake = re.sub(r"(?<!^)(?=[A-Z])", "_", t).lower()
        assert (generated / f"_{snake}.py").is_file(), t


def test_the_set_up_leaves_the_dependencies_and_the_package_byte_compiled():
    """Every process (node, graph, CLI) imports scipy, numba and rclpy: without their .pyc files
    (an install that writes none, and PYTHONDONTWRITEBYTECODE set) each start compiles them from
    source again, twice the CPU of an import. scripts/bootstrap.sh compiles every module of them,
    also the many no test imports (so this fails if it stops, whatever the tests wrote)."""
    import importlib
    import importlib.util

    for name in ("scipy", "numba", "rclpy", "friction_msgs"):
        root = Path(importlib.import_module(name).__file__).parent
        sources = list(root.rglob("*.py"))
        missing = [str(p) for p in sources if not os.path.exists(importlib.util.cache_from_source(str(p)))]
        assert sources and not missing, f"{len(missing)} of {len(sources)} {name} modules not byte-compiled " \
            f"(run scripts/bootstrap.sh), e.g. {missing[:3]}"  # fmt: skip
