"""friction-demo --preset arm7_plant: the 7-joint arm identified (experiment per joint, friction-fit
--joint all) and compensated (the arm's PD with the friction add-on) end to end over real DDS in
lockstep, quick profile; and the parameter file friction-fit writes for a joint whose fit explains
little (compensation disabled, the reason kept, the effort limit there)."""

from __future__ import annotations

import json
import math
import subprocess
import sys
from pathlib import Path

import pytest
import yaml

from friction_ros.core.identification.report.multi_joint import JointFit, controller_values

ROOT = Path(__file__).resolve().parents[1]
JOINTS = [f"joint{i}" for i in range(1, 8)]


@pytest.fixture(scope="module")
def arm_demo(tmp_path_factory):
    results = tmp_path_factory.mktemp("arm_demo") / "results"
    r = subprocess.run(
        [sys.executable, "-m", "friction_ros.cli.demo", "--preset", "arm7_plant", "--quick"]
        + ["--duration", "3", "--results", str(results)],
        capture_output=True,
        text=True,
        timeout=400,
        cwd=ROOT,
    )
    return r, results


def test_the_arm_demo_identifies_and_compensates_every_joint_or_says_why_not(arm_demo):
    r, results = arm_demo
    assert r.returncode == 0, r.stdout[-4000:] + r.stderr[-4000:]
    assert "Traceback" not in r.stdout + r.stderr
    summary = json.loads((results / "demo_summary.json").read_text())
    table = summary["table"]
    assert [row["joint"] for row in table] == JOINTS
    for row in table:  # enabled with its mode, or refused with the reason
        if row["enabled"]:
            assert row["mode"] in ("feedforward", "feedback", "blended") and row["reason"] == "", row
        else:
            assert row["mode"] == "none" and row["reason"].startswith(("the fit ", "fit failed")), row
        assert math.isfinite(row["rms_pd_mrad"]) and row["rms_pd_mrad"] > 0.0
    enabled = [row for row in table if row["enabled"]]
    assert enabled, "no joint compensated"
    for row in enabled:  # where the add-on compensates, it lowers the PD's tracking error
        assert row["rms_addon_mrad"] < row["rms_pd_mrad"], row
    for row in table:  # a refused joint's add-on output is its PD's command: the same run
        if not row["enabled"] and row["model"] == "none":
            assert row["rms_addon_mrad"] == pytest.approx(row["rms_pd_mrad"], rel=1e-9), row
    # every control period of both runs (3 s at 1 kHz)
    assert all(run["samples"] == 3001 for run in summary["runs"].values())
    # the console table: one row per joint, its state
    for row in table:
        line = next(ln for ln in r.stdout.splitlines() if ln.startswith(f"| {row['joint']} |"))
        assert line.endswith("| enabled |" if row["enabled"] else f"| refused: {row['reason']} |")
    # the fitted parameter file: each joint's effort limit (the controller node refuses to start without)
    cc = yaml.safe_load((results / "friction_params.yaml").read_text())["compensating_controller"]
    values = cc["ros__parameters"]
    for j in JOINTS:
        limit = (values.get("gains", {}).get(j) or {}).get("effort_limit", values.get("effort_limit"))
        assert limit is not None and limit > 0.0, j
    png = results / "tracking_error.png"
    assert png.stat().st_size > 20_000 and png.read_bytes()[:4] == b"\x89PNG"
    assert str(png) in summary["files"] and (results / "fit" / "index.md").exists()


def test_a_fit_that_explains_little_is_written_disabled_with_the_reason():
    """Its model stays in the file for inspection; compensation is none, every source refused with
    the reason (the node refuses them unless allow_refused); no fitted load term is fed forward; the
    effort limit is there."""
    doc = {
        "compensating_controller": {
            "ros__parameters": {
                "friction": {"model": "stribeck", "fc": 0.8, "fs": 1.0, "vs": 0.05, "fv": 0.01},
                "compensation": {"source": "blended", "gain": 1.0, "blend": 0.5},
                "load": {"offset": 0.1},
                "effort_limit": 3.0,
                "inertia": 0.01,
            }
        }
    }
    reason = "the fit explains little of the measured torque (validation NMSE 32.3 % > 30 %)"
    f = JointFit("j7", "explains little", "stribeck", 32.3, document=doc, reason=reason, effort_limit=3.0)
    assert not f.compensated
    v = controller_values(f)
    assert v["friction"]["model"] == "stribeck" and "load" not in v and v["effort_limit"] == 3.0
    assert v["compensation"] == {
        "source": "none",
        "refused": ["feedforward", "feedback", "blended"],
        "refused_reasons": [reason] * 3,
    }
    from friction_ros.core.control.compensation import FrictionCompensator

    comp = FrictionCompensator({**v["compensation"], "model": v["friction"]})
    assert comp.source == "none"
    from friction_ros.core.validation import ParameterError

    with pytest.raises(ParameterError, match="refused by the safety gate \\(the fit explains little"):
        FrictionCompensator({**v["compensation"], "source": "feedforward", "model": v["friction"]})
    failed = controller_values(JointFit("j8", "fit failed", reason="fit failed: no motion", effort_limit=2.0))
    assert failed["friction"] == {"model": "none"} and failed["effort_limit"] == 2.0
    assert failed["compensation"]["refused_reasons"] == ["fit failed: no motion"] * 3
