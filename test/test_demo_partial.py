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


def test_the_map_error_covers_the_whole_excited_speed_range():
    """A fit right on the plateaus but wrong in the Stribeck region below them: the plateau-range
    error is small, the error over the excited range is not (it was reported as 0.7 % before)."""
    import math

    import numpy as np

    from friction_ros.cli.demo_results import excited_speeds, map_error_vs_truth
    from friction_ros.core.identification.data.plateau_detection import Plateau

    def truth(v):
        return np.sign(v) * (0.2 + 0.1 * np.exp(-((np.abs(v) / 0.05) ** 2)))

    def fitted(v):
        return np.sign(v) * 0.2 * np.ones_like(np.asarray(v, dtype=float))

    plateaus = [Plateau(0.0, 1.0, s * v, 0.2, 0.0, 0.0, 100) for v in (0.3, 1.0) for s in (1, -1)]
    rec = type("R", (), {"velocity": np.concatenate([np.geomspace(1e-3, 1.0, 500), [0.0] * 50])})()
    lo, hi = excited_speeds([rec])
    assert 1e-3 <= lo < 2e-3 and 0.9 < hi <= 1.0
    out = map_error_vs_truth(fitted, truth, plateaus, (lo, hi))
    assert out["sliding_percent"] < 1e-6
    assert math.isclose(out["map_percent"], 100 * 0.1 / 0.3, rel_tol=0.02)
