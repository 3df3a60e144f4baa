"""Several friction_ros nodes in one process with one executor (as composable components on a robot).

    python -m friction_ros.nodes.composition --node plant_simulator --ros-args -p mode:=lockstep \\
        --node compensating_controller --ros-args --params-file ctrl.yaml -p use_sim_time:=true

Each ``--node NAME`` starts a node section; its ``--ros-args`` (namespace, node name, remappings,
parameter files, ``-p``) apply to that node only (rclpy ``cli_args`` without global arguments).
Messages between the nodes still go through the middleware, but one executor serves every
callback: a plant -> controller -> plant cycle needs no wake-up of another process.
``friction-bringup --compose`` and ``compose: true`` in a bring-up file use it.

A node that refuses its parameters ends the process with its one line ``error: NODE: reason``
and exit code 2. On SIGINT/SIGTERM every node's ``on_shutdown()`` runs, torque commanders first
(zero torque), then the others. A node can end the process itself (identification_experiment when
its program is over): the process exit code is then that node's (0, 3 stopped by a safety limit,
4 joint not excited).
"""

from __future__ import annotations

import importlib
import sys

import rclpy

from friction_ros.core.validation import ParameterError
from friction_ros.nodes.node_help import help_requested, purpose
from friction_ros.nodes.runtime import spin_until_stopped, start_process

#: node module -> its node class
NODE_CLASSES = {
    "plant_simulator": "PlantSimulator",
    "compensating_controller": "CompensatingControllerNode",
    "friction_estimator": "FrictionEstimatorNode",
    "drive_interface": "DriveInterface",
    "bag_recorder": "BagRecorder",
    "identification_experiment": "IdentificationExperiment",
}
#: torque commanders stop first
STOP_FIRST = ("identification_experiment", "compensating_controller")


def split_sections(argv: list[str]) -> list[tuple[str, list[str]]]:
    """``--node A --ros-args ... --node B ...`` -> ``[(A, [--ros-args, ...]), (B, [...])]``."""
    out: list[tuple[str, list[str]]] = []
    it = iter(argv)
    for a in it:
        if a == "--node":
            name = next(it, None)
            if name not in NODE_CLASSES:
                raise ParameterError(
                    f"--node {name!r}: must be one of {', '.join(NODE_CLASSES)} (nodes that can be composed)"
                )
            out.append((name, []))
        elif not out:
            raise ParameterError(f"{a!r}: arguments start with --node NAME")
        else:
            out[-1][1].append(a)
    if not out:
        raise ParameterError("no node given: --node NAME [--ros-args ...] (one or more)")
    return out


def node_class(module: str):
    mod = importlib.import_module(f"friction_ros.nodes.{module}")
    cls = getattr(mod, NODE_CLASSES[module], None)
    if cls is None:
        raise ParameterError(f"friction_ros.nodes.{module} has no {NODE_CLASSES[module]}")
    return cls


def main(argv: list[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    if help_requested(["composition", *argv]):
        print(
            f"{purpose(sys.modules[__name__])}\n\nnodes: {', '.join(NODE_CLASSES)} (NODE --help: their parameters)"
        )
        return 0
    try:
        sections = split_sections(argv)
    except ParameterError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    # no global ROS arguments: each node has its own (their parameter files are checked first)
    stop = start_process([sys.argv[0]], [args for _, args in sections])
    if stop is None:
        return 2
    nodes = []
    module, args = sections[0]
    try:
        for module, args in sections:
            nodes.append((module, node_class(module)(cli_args=args, use_global_arguments=False)))
    except (ParameterError, ValueError) as exc:
        print(f"error: {node_label(module, args)}: {exc}", file=sys.stderr)
        for _, n in nodes:
            n.destroy_node()
        rclpy.try_shutdown()
        return 2
    order = sorted(nodes, key=lambda mn: mn[0] not in STOP_FIRST)  # torque commanders stop first
    return spin_until_stopped([n for _, n in order], stop)


def node_label(module: str, args: list[str]) -> str:
    """The node of a section as friction-bringup labels it: ``[namespace/]name`` from the
    section's ``-r __ns:=`` / ``-r __node:=`` (default: the module)."""
    remap = {}
    for i, a in enumerate(args[:-1]):
        if a in ("-r", "--remap") and ":=" in args[i + 1]:
            k, v = args[i + 1].split(":=", 1)
            remap[k] = v
    name = remap.get("__node", module)
    ns = remap.get("__ns", "").strip("/")
    return f"{ns}/{name}" if ns else name


if __name__ == "__main__":
    raise SystemExit(main())
