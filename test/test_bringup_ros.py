"""friction-bringup over real DDS: the printed plan and the end-of-run summary of the controllers'
diagnostics (the 7-joint arm: PD + friction add-on); when things go wrong, the first failing node's
one line is what the user sees (with or without --quiet), the other nodes stop quietly, Ctrl-C
during start-up leaves no traceback."""

from __future__ import annotations

import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

BRINGUP = [sys.executable, "-m", "friction_ros.cli.bringup", "--preset", "abb_m19s"]
ROOT = Path(__file__).resolve().parents[1]
JOINTS = [f"joint{i}" for i in range(1, 8)]


def test_the_arm_bringup_prints_its_plan_and_each_controllers_last_status():
    """params/bringup_arm7.yaml: three nodes in /arm, each printed with its name, parameter files and
    remaps before anything starts; at the end one line per controller from its diagnostics: the PD
    compensates nothing, the add-on compensates every joint with the feedforward source."""
    r = subprocess.run(
        [
            sys.executable,
            "-m",
            "friction_ros.cli.bringup",
            "--config",
            str(ROOT / "params" / "bringup_arm7.yaml"),
        ]
        + ["--duration", "25", "--quiet"],  # start-up on a busy machine + diagnostics
        capture_output=True,
        text=True,
        timeout=120,
        cwd=ROOT,
    )
    assert r.returncode == 0, r.stdout[-3000:] + r.stderr[-3000:]
    _quiet_output(r.stdout + r.stderr)
    lines = r.stdout.splitlines()
    params = "params params/arm7_plant.yaml, params/arm7_controllers.yaml"  # as the file names them
    plan = {
        ln.split(": ", 1)[0].split()[-1]: ln
        for ln in lines
        if ": plant_simulator, " in ln or ": compensating_controller, " in ln
    }
    assert set(plan) == {"arm/plant_simulator", "arm/pd_controller", "arm/friction_addon"}, lines
    assert (
        "namespace /arm, name pd_controller; " + params + "; remap joint_commands:=pd_command"
        in plan["arm/pd_controller"]
    )
    assert (
        "name friction_addon; "
        + params
        + "; remap base_command:=pd_command, controller_state:=compensation_state"
        in plan["arm/friction_addon"]
    )
    assert (
        "set mode=lockstep" in plan["arm/plant_simulator"]
        and "use_sim_time=true" in plan["arm/pd_controller"]
    )
    # the plan comes before the nodes run: before the summary
    end = lines.index("[bringup] controllers at the end of the run (last diagnostics status):")
    assert all(lines.index(ln) < end for ln in plan.values())
    summary = {ln.split()[1].rstrip(":"): ln for ln in lines[end + 1 :]}
    assert set(summary) == {"arm/pd_controller", "arm/friction_addon"}, lines[end:]
    assert summary["arm/pd_controller"].endswith("OK pid running; compensation none on 7 of 7 joints")
    assert summary["arm/friction_addon"].endswith(
        "OK compensation_only running; compensation feedforward on 7 of 7 joints"
    )


def _quiet_output(text: str) -> None:
    assert "Traceback" not in text and "KeyboardInterrupt" not in text, text[-3000:]


@pytest.mark.parametrize("quiet", [True, False])
def test_one_node_refusing_its_parameters_gives_its_line_and_the_others_stop_quietly(tmp_path, quiet):
    bad = tmp_path / "controller.yaml"
    bad.write_text("compensating_controller:\n  ros__parameters:\n    bogus_param: 1\n")
    t0 = time.monotonic()
    r = subprocess.run(
        [*BRINGUP, "--params", str(bad), "--duration", "60", *(["--quiet"] * quiet)],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert r.returncode == 2, r.stdout[-3000:] + r.stderr[-3000:]
    err = r.stderr.strip().splitlines()
    assert len(err) == 1, r.stderr
    assert err[0].startswith(
        "error: compensating_controller: unknown parameter(s) bogus_param in the parameter"
    )
    _quiet_output(r.stdout + r.stderr)
    assert time.monotonic() - t0 < 45  # stopped on the failure, not at --duration
    if quiet:  # only friction-bringup's own lines (start, plan): the node's output is not forwarded
        assert all(ln.startswith("[bringup] ") for ln in r.stdout.strip().splitlines()), r.stdout
    assert "controllers at the end of the run" not in r.stdout  # no summary of a failed run


def test_ctrl_c_while_the_nodes_start_leaves_no_traceback():
    """SIGINT reaches only friction-bringup (the nodes run in their own process group); it stops the
    nodes in order with SIGTERM, also those still importing or building, without a traceback."""
    p = subprocess.Popen(
        [*BRINGUP, "--duration", "60"], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True
    )
    time.sleep(1.0)  # the nodes are importing rclpy / building
    p.send_signal(signal.SIGINT)
    out, err = p.communicate(timeout=60)
    assert p.returncode == 0, out[-3000:] + err[-3000:]
    assert err.strip() == "", err
    _quiet_output(out)
