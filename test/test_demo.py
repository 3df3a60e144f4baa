"""The main job end to end (quick): experiment -> bag -> fit -> gate -> compensation, abb_m19s.

Every other preset runs in test_demo_presets_*.py (the groups of ``demo_runs.GROUPS``: together
every preset, so parallel test workers share the work). Here, one ``friction-demo --presets
abb_m19s`` run is shared by the module; its experiment beside it and its four tracking runs after
it, again on the same saturated CPU, must give the same bag and the same rows of every run; the
fitted parameter file starts the controller node.
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest
import yaml
from demo_runs import (
    GROUPS,
    MODES,
    check_compensation_helps,
    check_every_preset_completes,
    check_reruns_identical,
    demo,
    run_group,
)
from ros_graph import Graph, Listener
from rosbags.highlevel import AnyReader

from friction_ros.cli.bringup import NodeSpec
from friction_ros.core.presets import PRESET_NAMES

pytestmark = [pytest.mark.ros, pytest.mark.slow]


@pytest.fixture(scope="module")
def abb(tmp_path_factory):
    return run_group(tmp_path_factory, "abb", rerun=("abb_m19s",), tracking=("none", *MODES))


def test_every_preset_completes_with_every_mode_enabled_or_refused(abb):
    proc, out = abb.proc, abb.out
    check_every_preset_completes(proc, out, GROUPS["abb"])


def test_compensation_helps_where_friction_matters_and_is_reported_where_not(abb):
    out = abb.out
    check_compensation_helps(out, GROUPS["abb"])
    s = json.loads((out / "demo_summary.json").read_text())
    assert s["presets"]["abb_m19s"]["reduction_percent"][s["presets"]["abb_m19s"]["best"]] >= 80.0


def test_the_demo_groups_are_every_preset_once():
    names = [n for g in GROUPS.values() for n in g]
    assert sorted(names) == sorted(PRESET_NAMES) and len(names) == len(set(names))
    for group in GROUPS:  # each group has its test module
        mod = "test_demo.py" if group == "abb" else f"test_demo_presets_{group}.py"
        assert (Path(__file__).parent / mod).is_file(), mod


def test_the_summary_keeps_its_keys_and_the_files_exist(abb):
    out = abb.out
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


def test_the_bag_is_valid_for_an_independent_reader(abb):
    out = abb.out
    s = json.loads((out / "abb_m19s" / "demo_summary.json").read_text())
    with AnyReader([Path(s["bag"])]) as reader:
        topics = {c.topic: c.msgtype for c in reader.connections}
        assert topics["/joint_states"] == "sensor_msgs/msg/JointState"
        assert topics["/experiment_events"] == "friction_msgs/msg/ExperimentEvent"
        n = sum(1 for _ in reader.messages([c for c in reader.connections if c.topic == "/joint_states"]))
    assert n > 10000


def test_a_run_under_cpu_contention_gives_identical_results(abb):
    """The experiment and every mode's tracking run again on a saturated CPU: the same bag and rows.
    The fit, the gate and the parameter file are a function of the bag (no wall-clock budget)."""
    check_reruns_identical(abb)
    assert sorted(abb.reruns["abb_m19s"]["labels"]) == sorted(("none", *MODES))


def test_the_fitted_parameter_file_starts_the_controller_node(abb):
    """The parameter file the demo wrote starts compensating_controller as it is, with an enabled mode."""
    from friction_msgs.msg import ControllerState

    out = abb.out
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


@pytest.mark.parametrize(
    ("args", "said"),
    [
        (["--presets", "abb_m19s", "nosuch"], "preset = 'nosuch' is not allowed: must be one of abb_m19s"),
        (["--presets", "abb_m19s", "--bag", "x"], "they cannot be combined with --bag"),
        (["--all-presets", "--presets", "abb_m19s"], "not allowed with argument --all-presets"),
    ],
)
def test_bad_preset_lists_are_one_line_and_exit_2_before_any_run(tmp_path, args, said):
    proc = demo(args, tmp_path / "results", timeout=60)
    assert proc.returncode == 2 and said in proc.stderr.splitlines()[-1], proc.stderr
    assert "Traceback" not in proc.stderr and not (tmp_path / "results").exists()
