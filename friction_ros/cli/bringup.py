"""friction-bringup: start a set of friction_ros nodes as separate processes (no ros2 launch needed).

Examples::

    # one simulated joint: plant + controller + estimator, real time, 30 s
    friction-bringup --preset abb_m19s --duration 30

    # lockstep (deterministic, faster than real time) with a controller parameter file
    friction-bringup --preset abb_m19s --mode lockstep --params params/controller_abb_m19s.yaml

    # several joints side by side, one namespace each (seed 002 Cartesian manipulator)
    friction-bringup --config params/bringup_cartesian_xyz.yaml

Ctrl-C (or the end of ``--duration``) stops the controllers first, so the last command every
actuator receives is zero torque, then the other nodes; a node that does not exit within the grace
period is killed. The exit code is non-zero if a node failed to start (e.g. invalid parameters).
"""

from __future__ import annotations

import argparse
import os
import signal
import subprocess
import sys
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path

import yaml

from friction_ros.core.validation import ParameterError

NODES = (
    "simulated_drive",
    "plant_simulator",
    "compensating_controller",
    "friction_estimator",
    "drive_interface",
    "bag_recorder",
    "identification_experiment",
)
# Stop order: whatever commands torque goes first, so it can publish zero before the rest exits.
STOP_ORDER = (
    "identification_experiment",
    "compensating_controller",
    "friction_estimator",
    "bag_recorder",
    "drive_interface",
    "simulated_drive",
    "plant_simulator",
)


@dataclass
class NodeSpec:
    """One node process: executable, namespace, parameter files and single overrides."""

    node: str
    namespace: str = ""
    params: list[str] = field(default_factory=list)
    overrides: dict[str, object] = field(default_factory=dict)
    args: list[str] = field(default_factory=list)  # node options before --ros-args (simulated_drive)

    def command(self) -> list[str]:
        if self.node not in NODES:
            raise ParameterError(
                f"node {self.node!r} is not a friction_ros node: must be one of {', '.join(NODES)}"
            )
        cmd = [sys.executable, "-m", f"friction_ros.nodes.{self.node}", *self.args, "--ros-args"]
        if self.namespace:
            cmd += ["-r", f"__ns:=/{self.namespace.strip('/')}"]
        for p in self.params:
            if not Path(p).is_file():
                raise ParameterError(f"parameter file {p} does not exist")
            cmd += ["--params-file", str(p)]
        for key, value in self.overrides.items():
            cmd += ["-p", f"{key}:={_ros_value(value)}"]
        return cmd

    @property
    def label(self) -> str:
        return f"{self.namespace.strip('/')}/{self.node}" if self.namespace else self.node


def _ros_value(value: object) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, (list, tuple)):
        return "[" + ",".join(_ros_value(v) for v in value) + "]"
    return str(value)


class Bringup:
    """Start, watch and stop node processes; forward their output with a label prefix."""

    def __init__(self, specs: list[NodeSpec], quiet: bool = False, env: dict[str, str] | None = None):
        self.specs = specs
        self.quiet = quiet
        self.env = dict(os.environ if env is None else env)
        self.procs: list[tuple[NodeSpec, subprocess.Popen]] = []
        self.output: dict[str, list[str]] = {}

    def start(self) -> None:
        for spec in self.specs:
            cmd = spec.command()
            proc = subprocess.Popen(
                cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, env=self.env, bufsize=1
            )
            self.procs.append((spec, proc))
            self.output[spec.label] = []
            threading.Thread(target=self._pump, args=(spec.label, proc), daemon=True).start()

    def _pump(self, label: str, proc: subprocess.Popen) -> None:
        for line in proc.stdout:
            self.output[label].append(line.rstrip())
            if not self.quiet:
                print(f"[{label}] {line.rstrip()}", flush=True)

    def failed(self) -> list[tuple[str, int]]:
        """Nodes that exited on their own with a non-zero code (e.g. refused to start)."""
        return [(s.label, p.returncode) for s, p in self.procs if p.poll() not in (None, 0)]

    def wait(self, duration: float | None, stop_event: threading.Event) -> None:
        end = None if duration is None else time.monotonic() + duration
        while not stop_event.is_set() and (end is None or time.monotonic() < end):
            if self.failed() or all(p.poll() is not None for _, p in self.procs):
                return
            time.sleep(0.05)

    def stop(self, grace: float = 5.0) -> None:
        order = {name: i for i, name in enumerate(STOP_ORDER)}
        for spec, proc in sorted(self.procs, key=lambda sp: order.get(sp[0].node, 99)):
            if proc.poll() is None:
                proc.send_signal(signal.SIGINT)
                try:
                    proc.wait(timeout=grace)
                except subprocess.TimeoutExpired:
                    print(
                        f"[bringup] {spec.label} did not stop within {grace:g} s: killing it", file=sys.stderr
                    )
                    proc.kill()
                    proc.wait()


def specs_from_config(path: str) -> list[NodeSpec]:
    """Read a bring-up YAML: ``joints: [{namespace, nodes, params, overrides}]``."""
    try:
        data = yaml.safe_load(Path(path).read_text())
    except (OSError, yaml.YAMLError) as exc:
        raise ParameterError(f"bring-up file {path}: cannot read it ({exc})") from None
    if not isinstance(data, dict) or not isinstance(data.get("joints"), list):
        raise ParameterError(f"bring-up file {path}: needs a top-level 'joints:' list")
    base = Path(path).parent
    specs = []
    for i, joint in enumerate(data["joints"]):
        if not isinstance(joint, dict):
            raise ParameterError(f"bring-up file {path}: joints[{i}] must be a mapping")
        ns = str(joint.get("namespace", ""))
        params = [str(_resolve(base, p)) for p in joint.get("params", [])]
        for node in joint.get("nodes", ["plant_simulator", "compensating_controller", "friction_estimator"]):
            overrides = dict(joint.get("overrides", {}).get(node, {}))
            specs.append(NodeSpec(node, ns, params, overrides))
    return specs


def _resolve(base: Path, p: str) -> Path:
    q = Path(p)
    if q.is_absolute() or q.exists():
        return q
    return base.parent / q if (base.parent / q).exists() else base / q


#: The latency chain of a simulated joint: the node that publishes joint states and the controller
#: that answers each of them.
LATENCY_CHAIN = ("plant_simulator", "compensating_controller")


def pin_latency_chain(specs: list[NodeSpec], cpus: list[int] | None = None) -> bool:
    """Pin the latency chain to one CPU and the estimator to another (``cpu_affinity`` overrides).

    A message between two processes on one core costs about half the CPU of a wake-up across
    cores on the 2-core VM (bench/loop.py docstring), so the lockstep graph runs ~3.3x instead of
    ~1.9x real time; no root needed (no SCHED_FIFO). Nodes given ``cpu_affinity`` keep it. Returns
    False and changes nothing with fewer than 2 CPUs or with several joints (namespaces).
    """
    cpus = sorted(os.sched_getaffinity(0)) if cpus is None else list(cpus)
    if len(cpus) < 2 or len({s.namespace for s in specs}) > 1:
        return False
    for s in specs:
        if "cpu_affinity" in s.overrides:
            continue
        if s.node in LATENCY_CHAIN:
            s.overrides["cpu_affinity"] = cpus[0]
        elif s.node == "friction_estimator":
            s.overrides["cpu_affinity"] = cpus[1]
    return True


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="friction-bringup",
        description=__doc__.split("\n\n")[0],
        formatter_class=argparse.RawTextHelpFormatter,
    )
    parser.add_argument("--config", help="bring-up YAML with several joints (see params/bringup_*.yaml)")
    parser.add_argument(
        "--nodes",
        default="plant_simulator,compensating_controller,friction_estimator",
        help="comma-separated nodes to start (default: %(default)s)",
    )
    parser.add_argument("--namespace", default="", help="namespace of the joint (default: none)")
    parser.add_argument("--preset", help="plant preset for plant_simulator (e.g. abb_m19s)")
    parser.add_argument("--mode", choices=("realtime", "lockstep"), help="plant_simulator mode")
    parser.add_argument("--params", action="append", default=[], help="parameter YAML passed to every node")
    parser.add_argument("--duration", type=float, help="stop after this many seconds (default: until Ctrl-C)")
    parser.add_argument("--quiet", action="store_true", help="do not forward node output")
    parser.add_argument(
        "--pin",
        choices=("auto", "on", "off"),
        default="auto",
        help="pin plant + controller to one CPU and the estimator to another (auto: in lockstep mode)",
    )
    return parser


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        if args.config:
            specs = specs_from_config(args.config)
        else:
            specs = [
                NodeSpec(n.strip(), args.namespace, list(args.params))
                for n in args.nodes.split(",")
                if n.strip()
            ]
            for s in specs:
                if s.node == "plant_simulator":
                    if args.preset:
                        s.overrides["preset"] = args.preset
                    if args.mode:
                        s.overrides["mode"] = args.mode
                if args.mode == "lockstep" and s.node != "plant_simulator":
                    s.overrides["use_sim_time"] = True
            if args.pin == "on" or (args.pin == "auto" and args.mode == "lockstep"):
                pin_latency_chain(specs)
        for s in specs:
            s.command()  # validate before starting anything
    except ParameterError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    bring = Bringup(specs, quiet=args.quiet)
    stop = threading.Event()
    signal.signal(signal.SIGINT, lambda *_: stop.set())
    signal.signal(signal.SIGTERM, lambda *_: stop.set())
    print(f"[bringup] starting {', '.join(s.label for s in specs)} (Ctrl-C stops them, controllers first)")
    bring.start()
    bring.wait(args.duration, stop)
    failed = bring.failed()
    bring.stop()
    for label, code in failed:
        print(f"[bringup] {label} exited with code {code}", file=sys.stderr)
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
