"""A demo step that fails keeps what the earlier steps produced, and says so."""

from __future__ import annotations

import json

from friction_ros.cli.demo import save_partial
from friction_ros.cli.demo_results import DemoResult


def test_a_failed_tracking_run_keeps_the_bag_the_fit_and_the_summary(tmp_path):
    res = DemoResult(preset="abb_m19s")
    res.bag, res.params_file, res.model = "bags/demo_x", str(tmp_path / "friction_params.yaml"), "gms4"
    line = save_partial(res, tmp_path, "tracking run feedback")
    assert line.startswith("kept: bag bags/demo_x, fit ") and str(tmp_path / "demo_summary.json") in line
    s = json.loads((tmp_path / "demo_summary.json").read_text())
    assert s["status"] == "incomplete: tracking run feedback failed" and s["completed_runs"] == []
    assert s["model"] == "gms4" and s["bag"] == "bags/demo_x"
    save_partial(res, tmp_path, "")
    assert json.loads((tmp_path / "demo_summary.json").read_text())["status"] == "running"
