"""The main job end to end on every preset (quick): experiment -> bag -> fit -> gate -> compensation.

One ``friction-demo --all-presets --quick`` run is shared by the module; a second run of one preset
under CPU contention must give the same bag, fit and figures.
"""

from __future__ import annotations

import json
import multiprocessing
import os
import re
import subprocess
import sys
import time
from pathlib import Path

import pytest
import yaml
from ros_graph import Graph, Listener
from rosbags.highlevel import AnyReader

from friction_ros.cli.bringup import NodeSpec
from friction_ros.core.presets import PRESET_NAMES

pytestmark = [pytest.mark.ros, pytest.mark.slow]
ROOT = Path(__file__).resolve().parents[1]
MODES = ("feedforward", "feedback", "blended")


def _demo(args: list[str], out: Path, timeout: float = 1500) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "friction_ros.cli.demo", "--quick", "--results", str(out), *args],
        capture_output=True,
        text=True,
        timeout=timeout,
        cwd=ROOT,
    )


@pytest.fixture(scope="module")
def all_presets(tmp_path_factory):
    out = tmp_path_factory.mktemp("demo_all") / "results"
    t0 = time.monotonic()
    proc = _demo(["--all-presets"], out)
    return proc, out, time.monotonic() - t0


def _busy(stop_at: float) -> None:
    x = 0
    while time.time() < stop_at:
        x += 1


@pytest.fixture(scope="module")
def loaded_run(tmp_path_factory):
    """The abb_m19s demo again, while two busy processes keep both cores loaded."""
    out = tmp_path_factory.mktemp("demo_loaded") / "results"
    stop_at = time.time() + 600
    ctx = multiprocessing.get_context("spawn")
    hogs = [ctx.Process(target=_busy, args=(stop_at,), daemon=True) for _ in range(os.cpu_count() or 2)]
    for h in hogs:
        h.start()
    try:
        proc = _demo(["--preset", "abb_m19s"], out)
    finally:
        for h in hogs:
            h.terminate()
            h.join()
    return proc, out


def test_every_preset_completes_with_every_mode_enabled_or_refused(all_presets):
    proc, out, wall = all_presets
    assert "Traceback" not in proc.stderr, proc.stderr[-3000:]
    s = json.loads((out / "demo_summary.json").read_text())
    assert s["presets_failed"] == {}, s["presets_failed"]
    assert sorted(s["presets_ok"]) == sorted(PRESET_NAMES), (s["presets_ok"], proc.stdout[-4000:])
    assert proc.returncode == 0, proc.stderr[-3000:]
    for name, p in s["presets"].items():
        none = p["runs"]["none"]
        assert none["enabled"] is True and none["samples"] == 4001
        for m in MODES:
            r = p["runs"][m]
            assert isinstance(r["enabled"], bool) and r["samples"] == 4001, (name, m, r)
            assert isinstance(r["reason"], str) and r["reason"], (name, m, r)
            if r["enabled"]:
                assert r["rms_mrad"] <= 1.02 * none["rms_mrad"], (name, m, r, none)
                # the run-time watch never fires on a file friction-fit wrote (every preset, lockstep)
                assert r["fallback_s"] is None, (name, m, r)
            assert p["gate"][m]["enabled"] == r["enabled"]
        # every table names every mode with its state
        assert re.search(rf"\[{name}\] Model chosen: \w+", proc.stdout)


def test_compensation_helps_where_friction_matters_and_is_reported_where_not(all_presets):
    """Measured on the development VM (quick profile): best enabled mode -89 to -98 % on six presets;
    on seed000_gearhead (60-count encoder at the joint, backlash, load-dependent gear friction) -10 %,
    and the demo names why: the encoder caps any measured reduction at -46 %."""
    _, out, _ = all_presets
    s = json.loads((out / "demo_summary.json").read_text())
    helped = 0
    for name, p in s["presets"].items():
        best = p["best"]
        red = p["reduction_percent"].get(best, 0.0) if best != "none" else 0.0
        if red >= 50.0:
            helped += 1
        else:
            said = ("barely changes", "no compensation mode", "caps what any compensation can show")
            assert any(x in w for x in said for w in p["warnings"]), (name, red, p["warnings"])
        # stick-slip measurably lower with the best enabled mode
        if red >= 50.0:
            assert p["runs"][best]["stick_fraction"] <= p["runs"]["none"]["stick_fraction"] + 1e-9, name
    assert helped >= 6, {n: p["reduction_percent"] for n, p in s["presets"].items()}
    cap = s["presets"]["seed000_gearhead"]["encoder_cap_percent"]
    assert 40.0 < cap < 50.0, cap  # q / sqrt(12) of a 60-count encoder against ~55 mrad uncompensated
    assert all(p["encoder_cap_percent"] > 95.0 for n, p in s["presets"].items() if n != "seed000_gearhead")
    assert s["presets"]["abb_m19s"]["reduction_percent"][s["presets"]["abb_m19s"]["best"]] >= 80.0


def test_the_summary_keeps_its_keys_and_the_files_exist(all_presets):
    _, out, _ = all_presets
    p = json.loads((out / "abb_m19s" / "demo_summary.json").read_text())
    for key in (
        "preset",
        "bag",
        "model",
        "fit_nmse_percent",
        "params_file",
        "runs",
        "best",
        "reduction_percent",
    ):
        assert key in p
    for f in ("tracking_error.png", "friction_map.png", "friction_params.yaml", "fit/report.md"):
        assert (out / "abb_m19s" / f).is_file() and (out / "abb_m19s" / f).stat().st_size > 500, f


def test_the_bag_is_valid_for_an_independent_reader(all_presets):
    _, out, _ = all_presets
    s = json.loads((out / "abb_m19s" / "demo_summary.json").read_text())
    with AnyReader([Path(s["bag"])]) as reader:
        topics = {c.topic: c.msgtype for c in reader.connections}
        assert topics["/joint_states"] == "sensor_msgs/msg/JointState"
        assert topics["/experiment_events"] == "friction_msgs/msg/ExperimentEvent"
        n = sum(1 for _ in reader.messages([c for c in reader.connections if c.topic == "/joint_states"]))
    assert n > 10000


def test_a_run_under_cpu_contention_gives_identical_results(all_presets, loaded_run):
    proc, out = loaded_run
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
    a = json.loads((all_presets[1] / "abb_m19s" / "demo_summary.json").read_text())
    b = json.loads((out / "demo_summary.json").read_text())
    assert a["bag_digest"] == b["bag_digest"]
    assert a["model"] == b["model"]
    assert a["fit_nmse_percent"] == b["fit_nmse_percent"]
    assert a["gate"] == b["gate"]
    for m in ("none", *MODES):
        for k in ("rms_mrad", "max_mrad", "enabled", "samples", "stick_fraction", "hunting_reversals"):
            assert a["runs"][m][k] == b["runs"][m][k], (m, k)
    fa = yaml.safe_load(Path(a["params_file"]).read_text())
    fb = yaml.safe_load(Path(b["params_file"]).read_text())
    assert fa == fb


def test_the_fitted_parameter_file_starts_the_controller_node(all_presets):
    """The parameter file the demo wrote starts compensating_controller as it is, with an enabled mode."""
    from friction_msgs.msg import ControllerState

    _, out, _ = all_presets
    s = json.loads((out / "abb_m19s" / "demo_summary.json").read_text())
    params = s["params_file"]
    specs = [
        NodeSpec("plant_simulator", "", [], {"preset": "abb_m19s", "mode": "lockstep"}),
        NodeSpec("compensating_controller", "", [params], {"use_sim_time": True}),
    ]
    with Listener("demo_params_check") as lis:
        states = lis.subscribe(ControllerState, "controller_state")
        with Graph(specs) as g:
            assert lis.wait_for(lambda: len(states) > 50, 60, g), g.output("compensating_controller")
            out_text = g.output("compensating_controller")
    doc = yaml.safe_load(Path(params).read_text())
    model = doc["compensating_controller"]["ros__parameters"]["friction"]["model"]
    assert isinstance(model, str) and model != "none"
    assert f"friction model {model}," in out_text
