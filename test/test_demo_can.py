"""``friction-demo --can cia402 --quick``: the main job on a CiA 402 axis over CANopen, end to end.

The preset's plant behind an emulated CiA 402 drive (``drive_emulator``, its own process) and
``drive_interface`` on the ``friction_local`` bus (NMT, SDO configuration, SYNC + PDOs at 1 kHz),
the experiment, recorder, fit and controller over DDS. Real time on the wall clock: a fully
loaded machine makes the drive's telemetry late or stale, so the module is ``realtime`` (a CPU of its own,
after the parallel tests). ODrive and MIT run the same code path with another protocol name and
take as long again (~2 min each), so they are not repeated here.
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from friction_ros.cli import demo
from friction_ros.core.can.protocol import protocol_names

ROOT = Path(__file__).resolve().parents[1]
MODES = ("feedforward", "feedback", "blended")
DURATION = 2.0  # tracking seconds per run (the shortest that still shows the compensation)

pytestmark = [pytest.mark.ros, pytest.mark.slow, pytest.mark.realtime]


@pytest.fixture(scope="module")
def cia402(tmp_path_factory):
    out = tmp_path_factory.mktemp("demo_can") / "results"
    proc = subprocess.run(
        [sys.executable, "-m", "friction_ros.cli.demo", "--can", "cia402", "--quick",
         "--duration", str(DURATION), "--results", str(out)],
        capture_output=True, text=True, timeout=900, cwd=ROOT,
    )  # fmt: skip
    return proc, out


def test_cia402_demo_identifies_and_compensates(cia402):
    proc, out = cia402
    assert proc.returncode == 0, (proc.stdout[-3000:], proc.stderr[-3000:])
    assert "Traceback" not in proc.stderr
    s = json.loads((out / "demo_summary.json").read_text())
    assert s["status"] == "complete" and s["timing"] == "real time"
    assert s["can"]["protocol"] == "cia402" and s["can"]["bus"] == "friction_local"
    # the output says it is real time, not lockstep
    assert "real time, 1 kHz wall clock, over CAN: cia402" in proc.stdout
    assert "real time over CAN (cia402" in proc.stdout
    expected = round(DURATION / 1e-3) + 1
    for label in ("none", *MODES):
        r = s["runs"][label]
        # the periods the controller computed, and the ones it did not, add up to the run
        assert r["samples"] + r["missing_periods"] >= expected, (label, r)
        # a run that missed over 10 % of its periods (late telemetry) is flagged, never a result
        assert r["samples"] >= 0.9 * expected or "telemetry was late" in r["invalid"], (label, r)
        if label != "none":  # every mode enabled or refused, with the gate's reason
            assert isinstance(r["enabled"], bool) and r["reason"], (label, r)
            assert s["gate"][label]["enabled"] == r["enabled"]
        assert f"| {label} |" in proc.stdout
    # compensation helps, or the demo says why not
    best = s["best"]
    assert best == "none" or not s["runs"][best]["invalid"]
    red = s["reduction_percent"].get(best, 0.0) if best != "none" else 0.0
    if red < 30.0:
        said = ("barely changes", "no compensation mode", "caps what any", "telemetry was late")
        assert any(x in w for x in said for w in s["warnings"]), (red, s["warnings"])
    # the experiment and the four runs each ended with the drive reporting itself disabled
    assert s["can"]["steps"] == 5 and s["can"]["drive_disabled_after_every_step"] is True


def test_bad_can_value_is_one_line_exit_2(capsys):
    assert demo.main(["--can", "canbus9000"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--can 'canbus9000'" in err[0], err
    assert all(name in err[0] for name in protocol_names()), err
