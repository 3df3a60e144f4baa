"""A composed process's lines are labelled with the node they are about (cli.composed_output)."""

from __future__ import annotations

from friction_ros.cli.composed_output import LineRouter
from friction_ros.nodes.composition import node_label


def _router() -> LineRouter:
    return LineRouter(["plant_simulator", "ns/identification_experiment"], "composed[p,e]")


def test_log_lines_go_to_their_node_and_continuations_follow():
    r = _router()
    assert r.route("[INFO] [1.5] [plant_simulator]: preset x") == (
        "plant_simulator",
        "[INFO] [1.5] [plant_simulator]: preset x",
    )
    line = "[WARN] [2.0] [ns.identification_experiment]: ABORT program"
    assert r.route(line) == ("ns/identification_experiment", line)
    assert r.route("  a traceback line") == ("ns/identification_experiment", "  a traceback line")
    assert r.route("[INFO] [2.1] [rcl]: something") == ("composed[p,e]", "[INFO] [2.1] [rcl]: something")
    assert r.last_error is None


def test_a_refusal_names_its_node_as_its_own_process_would():
    r = _router()
    assert r.route("error: ns/identification_experiment: unknown parameter(s) bogus_key") == (
        "ns/identification_experiment",
        "error: unknown parameter(s) bogus_key",
    )
    assert r.last_error == "ns/identification_experiment"
    r = _router()
    assert r.route("error: ROS arguments refused: x") == ("composed[p,e]", "error: ROS arguments refused: x")
    assert r.last_error == "composed[p,e]"


def test_node_label_from_the_section_remappings():
    assert node_label("plant_simulator", ["--ros-args", "-p", "mode:=lockstep"]) == "plant_simulator"
    args = ["--ros-args", "-r", "__ns:=/arm/j2", "-r", "__node:=pd", "-p", "a:=1"]
    assert node_label("compensating_controller", args) == "arm/j2/pd"
