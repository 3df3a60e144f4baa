"""friction-experiment on a real joint (``--no-sim``) with no drive running: it gives up after the
first-state wait (not the whole run's timeout) and names the cause, over real DDS."""

from __future__ import annotations

import os
import subprocess
import sys
import time

import pytest

pytestmark = pytest.mark.ros


def test_no_drive_fails_fast_naming_the_topic_and_domain(tmp_path):
    ns = f"no_drive_{os.getpid()}"
    out = tmp_path / "run"
    t0 = time.monotonic()
    r = subprocess.run(
        [sys.executable, "-m", "friction_ros.cli.experiment", "--no-sim", "--namespace", ns]
        + ["--state-timeout", "2", "-o", str(out), "--quiet"],
        capture_output=True,
        text=True,
        timeout=60,
    )
    wall = time.monotonic() - t0
    assert r.returncode == 1, r.stdout + r.stderr
    lines = r.stderr.strip().splitlines()
    assert lines[-1] == (
        f"error: no joint_states received on /{ns}/joint_states within 2 s: is the drive_interface running "
        f"(with the same --namespace), and is ROS_DOMAIN_ID the same in its shell "
        f"(here: {os.environ['ROS_DOMAIN_ID']})?"
    ), r.stderr
    assert "Traceback" not in r.stderr
    assert wall < 20.0  # the run's own timeout would be 60 s + 10 x 127 s planned
    assert not out.exists()  # nothing was recorded: the folder it created is removed


def test_state_timeout_must_be_positive(tmp_path):
    r = subprocess.run(
        [sys.executable, "-m", "friction_ros.cli.experiment", "--no-sim", "--state-timeout", "0"],
        capture_output=True,
        text=True,
        timeout=30,
    )
    assert r.returncode == 2
    assert r.stderr.strip() == "error: --state-timeout 0: must be > 0 s"
