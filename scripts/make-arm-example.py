#!/usr/bin/env python3
"""Write params/arm7_controllers.yaml (the plain PD and the friction add-on of the 7-joint arm
example) from params/arm7_plant.yaml: friction_ros.core.experiment.arm_example says how.

    .venv/bin/python scripts/make-arm-example.py [--check]

``--check``: exit 1 if the committed file differs from what the plant file gives (tests call it):
the same keys and text, numbers within 1e-4 (relative) or 1e-12 (absolute). Coefficients the data
do not fix (``vs`` where ``fs = fc``, a viscous term below the fit's precision) are written in a
canonical form (``arm_example.canonical_stribeck``); the tolerance covers the last digits of the
optimiser, which differ between machines.
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

import yaml

from friction_ros.core.experiment.arm_example import arm_parameter_document
from friction_ros.core.identification.report.export import dump_yaml

ROOT = Path(__file__).resolve().parents[1]
PLANT = ROOT / "params" / "arm7_plant.yaml"
OUT = ROOT / "params" / "arm7_controllers.yaml"
HEADER = """\
# The 7-joint arm example's controllers (written by scripts/make-arm-example.py from arm7_plant.yaml;
# do not edit: change the plant file or friction_ros/core/experiment/arm_example.py and re-run it).
#   pd_controller:  the arm's own plain joint controller, a PD per joint (tracking design rule)
#   friction_addon: compensation_only: each joint's friction map (fitted to the plant's steady-state
#                   friction) fed forward from the reference velocity, gravity at the measured
#                   position; adds the PD's command (base_command) and sends the sum to the joints.
# Both follow the same per-joint references (on a robot: the arm's JointTrajectory on `reference`).
#   friction-bringup --config params/bringup_arm7.yaml
"""


def render() -> str:
    doc = yaml.safe_load(PLANT.read_text())
    plant = next(v["ros__parameters"] for k, v in doc.items() if k.endswith("plant_simulator"))
    params, _ = arm_parameter_document(plant)
    return dump_yaml(params, HEADER)


def same(a, b) -> bool:
    """Equal documents, numbers compared with a tolerance (see the module docstring)."""
    if isinstance(a, dict) and isinstance(b, dict):
        return a.keys() == b.keys() and all(same(a[k], b[k]) for k in a)
    if isinstance(a, list) and isinstance(b, list):
        return len(a) == len(b) and all(same(x, y) for x, y in zip(a, b))
    if isinstance(a, (int, float)) and isinstance(b, (int, float)) and not isinstance(a, bool):
        return math.isclose(a, b, rel_tol=1e-4, abs_tol=1e-12)
    return a == b


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--check", action="store_true", help="compare with the committed file")
    args = parser.parse_args()
    text = render()
    if args.check:
        if not OUT.exists() or not same(yaml.safe_load(OUT.read_text()), yaml.safe_load(text)):
            print(f"{OUT} is out of date: run scripts/make-arm-example.py", file=sys.stderr)
            return 1
        return 0
    OUT.write_text(text)
    print(f"wrote {OUT}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
