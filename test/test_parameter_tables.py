"""docs/parameters.md is generated from the configuration schemas and cannot drift from them."""

import importlib.util
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


def _generator():
    spec = importlib.util.spec_from_file_location(
        "parameter_tables", ROOT / "scripts" / "parameter-tables.py"
    )
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_committed_parameter_reference_equals_the_generator_output():
    text = _generator().render()
    assert (ROOT / "docs" / "parameters.md").read_text() == text, "run scripts/parameter-tables.py"


def test_parameter_reference_has_one_table_per_node_with_units():
    text = (ROOT / "docs" / "parameters.md").read_text()
    for node in ("plant_simulator", "compensating_controller", "friction_estimator", "drive_interface"):
        assert f"## {node}" in text
    assert "| `control_period` | float | `0.001` | in [1e-05, 0.1] | s |" in text


def test_readme_key_parameters_equal_the_generator_output():
    gen = _generator()
    text = (ROOT / "README.md").read_text()
    assert gen.render_readme(text) == text, "run scripts/parameter-tables.py"
    assert "| `compensating_controller` | `mode` | `pid` |" in text
    assert "| | `pid.p` | `0` | N*m/rad | proportional gain" in text.replace("|  |", "| |")
