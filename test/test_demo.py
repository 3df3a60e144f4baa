"""Issue 9: the main job end to end (shortened): experiment -> bag -> fit -> parameter file -> compensation."""

from __future__ import annotations

import json
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

pytestmark = [pytest.mark.ros, pytest.mark.slow]
ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def demo_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("demo")
    t0 = time.monotonic()
    proc = subprocess.run(
        [sys.executable, "-m", "friction_ros.cli.demo", "--quick", "--results", str(out / "results")],
        capture_output=True,
        text=True,
        timeout=900,
        cwd=ROOT,
    )
    return proc, out / "results", time.monotonic() - t0


def test_demo_prints_the_table_and_names_its_files(demo_run):
    proc, results, _ = demo_run
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
    assert "Traceback" not in proc.stderr
    assert "| compensation | RMS error [mrad] | max error [mrad] | RMS reduction [%] |" in proc.stdout
    assert re.search(r"Model chosen: \w+", proc.stdout)
    for name in ("tracking_error.png", "friction_map.png", "demo_summary.json"):
        assert (results / name).is_file() and (results / name).stat().st_size > 1000 or name.endswith(".json")
        assert str(results / name) in proc.stdout


def test_demo_bag_is_valid_for_an_independent_reader(demo_run):
    _, results, _ = demo_run
    summary = json.loads((results / "demo_summary.json").read_text())
    bag = Path(summary["bag"])
    with AnyReader([bag]) as reader:
        topics = {c.topic: c.msgtype for c in reader.connections}
        assert topics["/joint_states"] == "sensor_msgs/msg/JointState"
        assert topics["/experiment_events"] == "friction_msgs/msg/ExperimentEvent"
        n = sum(
            1
            for _ in reader.messages(
                connections=[c for c in reader.connections if c.topic == "/joint_states"]
            )
        )
    assert n > 20000  # the quick profile: ~30 s at 1 kHz


def test_compensation_with_fitted_coefficients_halves_the_tracking_error(demo_run):
    _, results, _ = demo_run
    s = json.loads((results / "demo_summary.json").read_text())
    none = s["runs"]["none"]["rms_mrad"]
    best = s["runs"][s["best"]]["rms_mrad"]
    assert none > 0.5
    assert best <= 0.5 * none, s["runs"]
    assert s["fit_nmse_percent"]["high"] < 5.0


def test_fitted_parameter_file_loads_into_the_controller_node(demo_run):
    """The parameter file written into params/ starts the compensating_controller as it is."""
    from friction_msgs.msg import ControllerState

    _, results, _ = demo_run
    s = json.loads((results / "demo_summary.json").read_text())
    params = s["params_file"]
    specs = [
        NodeSpec("plant_simulator", "", [], {"preset": "abb_m19s", "mode": "lockstep"}),
        NodeSpec("compensating_controller", "", [params], {"use_sim_time": True}),
    ]
    with Listener("demo_params_check") as lis:
        states = lis.subscribe(ControllerState, "controller_state")
        with Graph(specs) as g:
            assert lis.wait_for(lambda: len(states) > 50, 60, g), g.output("compensating_controller")
            out = g.output("compensating_controller")
    doc = yaml.safe_load(Path(params).read_text())
    model = doc["compensating_controller"]["ros__parameters"]["friction"]["model"]
    assert isinstance(model, str) and model != "none"
    assert f"friction model {model}," in out
