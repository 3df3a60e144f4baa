"""friction-bringup when things go wrong, over real DDS: the first failing node's one line is what the
user sees (with or without --quiet), the other nodes stop quietly, Ctrl-C during start-up leaves no
traceback."""

from __future__ import annotations

import signal
import subprocess
import sys
import time

import pytest

BRINGUP = [sys.executable, "-m", "friction_ros.cli.bringup", "--preset", "abb_m19s"]


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
    if quiet:  # only the start line: the node's own output is not forwarded
        assert len(r.stdout.strip().splitlines()) == 1, r.stdout


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
