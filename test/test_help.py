"""Every node and every console script answers --help / -h with exit code 0 and starts nothing.

Each console script of setup.py is called as its generated wrapper calls it (``main()`` with
``sys.argv`` = program, ``--help``), in this process: the test observes that no rclpy context
exists afterwards, a node installed no SIGINT handler, and (through a Python audit hook) that no
socket (a CAN bus, a DDS participant created from Python) and no child process was opened. A node
prints every parameter of the schema it declares. One case runs drive_interface as a real process
on a machine with no CAN interface: nothing about the bus appears.
"""

from __future__ import annotations

import ast
import importlib
import os
import signal
import subprocess
import sys
import time

import pytest
import rclpy
from conftest import ROOT

from friction_ros.nodes.node_help import help_requested, node_schema, parameter_lines

_RECORDING: list[list[str]] = []
_WATCHED = ("socket.__new__", "subprocess.Popen", "os.posix_spawn", "os.fork", "os.exec")


def _audit(event: str, args) -> None:
    if _RECORDING and event in _WATCHED:
        _RECORDING[-1].append(event)


sys.addaudithook(_audit)


def console_scripts() -> dict[str, str]:
    """name -> module of every console script in setup.py's ENTRY_POINTS."""
    tree = ast.parse((ROOT / "setup.py").read_text())
    for node in tree.body:
        if isinstance(node, ast.Assign) and getattr(node.targets[0], "id", "") == "ENTRY_POINTS":
            entries = ast.literal_eval(node.value)
    out = {}
    for entry in entries:
        name, target = (s.strip() for s in entry.split("="))
        module, func = target.split(":")
        assert func == "main", entry
        out[name] = module
    return out


SCRIPTS = console_scripts()
#: the modules whose help lists a schema's parameters (simulated_drive: drive_interface's)
SCHEMA_OF = {"simulated_drive": "friction_ros.nodes.drive_interface"}


def test_every_node_is_a_console_script():
    nodes = {m.rsplit(".", 1)[1] for m in SCRIPTS.values() if m.startswith("friction_ros.nodes.")}
    assert nodes >= {
        "plant_simulator",
        "compensating_controller",
        "friction_estimator",
        "identification_experiment",
        "drive_interface",
        "simulated_drive",
        "drive_emulator",
        "bag_recorder",
        "bag_player",
    }
    assert {"friction-fit", "friction-demo", "friction-bag", "friction-bringup"} <= set(SCRIPTS)
    assert {"friction-experiment", "friction-doctor"} <= set(SCRIPTS)


@pytest.mark.timeout(30)
@pytest.mark.parametrize("flag", ["--help", "-h"])
@pytest.mark.parametrize("name", sorted(SCRIPTS))
def test_help_exits_0_and_starts_nothing(name, flag, monkeypatch, capsys):
    module = importlib.import_module(SCRIPTS[name])
    monkeypatch.setattr(sys, "argv", [name, flag])
    sigint, sigterm = signal.getsignal(signal.SIGINT), signal.getsignal(signal.SIGTERM)
    _RECORDING.append([])
    t0 = time.monotonic()
    try:
        with pytest.raises(SystemExit) as exc:
            sys.exit(module.main())
    finally:
        opened = _RECORDING.pop()
        handler = signal.getsignal(signal.SIGINT)
        signal.signal(signal.SIGINT, sigint)  # a CLI may install its own Ctrl-C handler first
        signal.signal(signal.SIGTERM, sigterm)
    elapsed = time.monotonic() - t0
    out, err = capsys.readouterr()
    assert exc.value.code in (0, None), err
    assert elapsed < 5.0
    assert not rclpy.ok(), "rclpy was started"
    if SCRIPTS[name].startswith("friction_ros.nodes."):
        assert handler is sigint, "a node process was started (signal handlers)"
    assert opened == [], f"{name} --help opened {opened}"
    assert err == ""
    assert "usage:" in out
    schema_module = SCHEMA_OF.get(name, SCRIPTS[name])
    schema = node_schema(importlib.import_module(schema_module)) if "nodes" in schema_module else None
    if schema is not None:
        names = [n for n, _ in schema.fields()]
        assert len(names) >= 3
        for n in names:
            assert f"  {n}  " in out, f"{name} --help does not list parameter {n}"


def test_parameter_line_has_type_default_unit_range():
    from friction_ros.nodes.plant_simulator import parameter_schema

    fields = dict(parameter_schema().fields())
    text = "\n".join(parameter_lines(parameter_schema()))
    f = fields["control_period"]
    assert (
        f"  control_period  float  default {f.default:g} s  in [{f.lo:g}, {f.hi:g}]  fixed at start" in text
    )
    assert f.doc in text
    assert "  mode  str  default realtime  one of realtime, lockstep" in text
    assert "  plant.*  section" in text


@pytest.mark.parametrize(
    "args, wanted",
    [
        (["n", "--help"], True),
        (["n", "-h", "--ros-args", "-p", "a:=1"], True),
        (["n", "--ros-args", "-p", "a:=1", "--", "-h"], True),
        (["n", "--ros-args", "-p", "help:=1"], False),
        (["n", "--ros-args", "--help"], False),  # belongs to ROS, not to the node
        (["--help"], False),  # the program name itself
    ],
)
def test_help_requested(args, wanted):
    assert help_requested(args) is wanted


def test_drive_interface_help_without_can_interface():
    """A real drive_interface process with --help on a machine where can0 does not exist."""
    assert not os.path.exists("/sys/class/net/can0"), "this test needs a machine without can0"
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    cmd = [
        sys.executable,
        "-c",
        "import sys; from friction_ros.nodes.drive_interface import main; sys.exit(main())",
    ]
    t0 = time.monotonic()
    r = subprocess.run(
        [*cmd, "--help", "--ros-args", "-p", "channel:=can0", "-p", "interface:=socketcan"],
        capture_output=True,
        text=True,
        timeout=30,
        env=env,
    )
    assert r.returncode == 0, r.stderr
    assert time.monotonic() - t0 < 10.0
    assert r.stderr == ""
    assert "  channel  str  default can0" in r.stdout
    assert "can0" not in r.stdout.replace("default can0", "")  # no message about the bus
    for word in ("No such device", "not found", "[INFO]", "[WARN]", "[ERROR]"):
        assert word not in r.stdout
