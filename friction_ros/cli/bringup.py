"""friction-bringup: start a set of friction_ros nodes as separate processes (no ros2 launch needed).

Examples::

    # one simulated joint: plant + controller + estimator, real time, 30 s
    friction-bringup --preset abb_m19s --duration 30

    # lockstep (deterministic, faster than real time) with a controller parameter file
    friction-bringup --preset abb_m19s --mode lockstep --params params/controller_abb_m19s.yaml

    # several joints side by side, one namespace each (Tilakaratna et al. 2004 Cartesian manipulator)
    friction-bringup --config params/bringup_cartesian_xyz.yaml

    # a 7-joint arm: one plant, a plain PD and the friction add-on (lockstep, composed)
    friction-bringup --config params/bringup_arm7.yaml --duration 20

Before starting, every node is printed with its namespace, name, parameter files, remappings and
parameter overrides; at the end of a run with controllers, one line per controller node from its
last diagnostics status (level, text, compensation state per joint).

``--compose`` runs the nodes in one process with one executor (as composable components on a
robot): fewer wake-ups per cycle on the plant -> controller -> plant chain.

Ctrl-C (or the end of ``--duration``) stops the controllers first, so the last command every
actuator receives is zero torque, then the other nodes (SIGTERM; the nodes run in their own process
group, so a terminal's Ctrl-C reaches only this command and the order holds); a node that does not
exit within the grace period is killed. When a node fails (e.g. refuses its parameters) the others
are stopped the same way, quietly, and the first failing node's reason is printed as one line
``error: <node>: <reason>``, with or without ``--quiet``. Exit code: 0, 2 when a node refused its
input (bad parameters, exit 2) or the arguments are bad, 1 when a node failed otherwise.
"""

from __future__ import annotations

import argparse
import math
import os
import signal
import subprocess
import sys
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path

from friction_ros.cli.composed_output import LineRouter
from friction_ros.core.validation import ParameterError
from friction_ros.core.yaml_files import check_parameter_file, load_yaml

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
    name: str = ""  # node name ('' = the executable's own): two controllers in one namespace
    remaps: dict[str, str] = field(default_factory=dict)  # topic remappings (joint_commands: pd_command)

    def ros_args(self) -> list[str]:
        """The ``--ros-args`` section: namespace, name, remappings, parameter files, overrides."""
        if self.node not in NODES:
            raise ParameterError(
                f"node {self.node!r} is not a friction_ros node: must be one of {', '.join(NODES)}"
            )
        out = ["--ros-args"]
        if self.namespace:
            out += ["-r", f"__ns:=/{self.namespace.strip('/')}"]
        if self.name:
            out += ["-r", f"__node:={self.name}"]
        for src, dst in self.remaps.items():
            out += ["-r", f"{src}:={dst}"]
        for p in self.params:
            check_parameter_file(p)  # one line for a missing file or one that is not a parameter YAML
            out += ["--params-file", str(p)]
        for key, value in self.overrides.items():
            out += ["-p", f"{key}:={_ros_value(value)}"]
        return out

    def command(self) -> list[str]:
        return [sys.executable, "-m", f"friction_ros.nodes.{self.node}", *self.args, *self.ros_args()]

    @property
    def label(self) -> str:
        name = self.name or self.node
        return f"{self.namespace.strip('/')}/{name}" if self.namespace else name


@dataclass
class ComposedSpec(NodeSpec):
    """Several nodes in one process (:mod:`friction_ros.nodes.composition`)."""

    members: list[NodeSpec] = field(default_factory=list)

    def command(self) -> list[str]:
        cmd = [sys.executable, "-m", "friction_ros.nodes.composition"]
        for m in self.members:
            if m.args:
                raise ParameterError(
                    f"{m.label} takes process options ({' '.join(m.args)}): it cannot be composed"
                )
            cmd += ["--node", m.node, *m.ros_args()]
        return cmd

    @property
    def label(self) -> str:
        return "composed[" + ",".join(m.label for m in self.members) + "]"


def members(spec: NodeSpec) -> list[NodeSpec]:
    """The nodes a process runs: a composed process's members, else the node itself."""
    return list(spec.members) if isinstance(spec, ComposedSpec) else [spec]


def composed_spec(specs: list[NodeSpec]) -> NodeSpec:
    """One process for ``specs`` (stopped first: it holds the torque commanders)."""
    return ComposedSpec("compensating_controller", members=list(specs))


def _ros_value(value: object) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, (list, tuple)):
        return "[" + ",".join(_ros_value(v) for v in value) + "]"
    return str(value)


class Bringup:
    """Start, watch and stop node processes; forward their output with a label prefix.

    Each node runs in its own process group (a terminal's Ctrl-C reaches only the parent, which
    stops the nodes in :data:`STOP_ORDER`). Exits are timed by the output pumps, so
    :meth:`first_failure` names the node that failed first on its own (not one that was stopped).
    """

    def __init__(self, specs: list[NodeSpec], quiet: bool = False, env: dict[str, str] | None = None):
        self.specs = specs
        self.quiet = quiet
        self.env = dict(os.environ if env is None else env)
        self.procs: list[tuple[NodeSpec, subprocess.Popen]] = []
        self.output: dict[str, list[str]] = {}
        self.ended: dict[str, float] = {}  # label -> monotonic time its process ended
        self.stopping: float | None = None  # monotonic time stop() began
        self.routers: dict[str, LineRouter] = {}  # composed process label -> its lines' nodes

    def start(self) -> None:
        for spec in self.specs:
            cmd = spec.command()
            proc = subprocess.Popen(
                cmd,
                stdout=subprocess.PIPE,
                stderr=subprocess.STDOUT,
                text=True,
                env=self.env,
                bufsize=1,
                process_group=0,
            )
            self.procs.append((spec, proc))
            self.output[spec.label] = []
            labels = [m.label for m in members(spec)]
            if isinstance(spec, ComposedSpec):
                self.routers[spec.label] = LineRouter(labels, spec.label)
                self.output.update({lbl: [] for lbl in labels})
            threading.Thread(target=self._pump, args=(spec.label, proc, labels), daemon=True).start()

    def _pump(self, label: str, proc: subprocess.Popen, labels: list[str]) -> None:
        """Forward and keep a process's lines, each under the node it is about (composed: :class:`LineRouter`)."""
        router = self.routers.get(label)
        for line in proc.stdout:
            who, text = router.route(line.rstrip()) if router else (label, line.rstrip())
            self.output[who].append(text)
            if not self.quiet:
                print(f"[{who}] {text}", flush=True)
        proc.wait()
        now = time.monotonic()
        for lbl in {label, *labels}:
            self.ended[lbl] = now

    def _failed_label(self, spec: NodeSpec) -> str:
        """The node a process failed for: a composed process's node of the last ``error:`` line,
        else of its last line; a node's own process: its label."""
        router = self.routers.get(spec.label)
        if router is None:
            return spec.label
        return router.last_error or router.current

    def failed(self) -> list[tuple[str, int]]:
        """Nodes that exited on their own with a non-zero code (e.g. refused to start)."""
        return [
            (self._failed_label(s), p.returncode)
            for s, p in self.procs
            if p.poll() not in (None, 0)
            and (self.stopping is None or self.ended.get(s.label, time.monotonic()) < self.stopping)
        ]

    def reason(self, label: str) -> str:
        """Why the node ``label`` ended: its last ``error:`` line, else its last line of output."""
        lines = [ln.strip() for ln in self.output.get(label, []) if ln.strip()]
        node = label.rsplit("/", 1)[-1]
        for ln in reversed(lines):
            if ln.startswith("error:"):
                text = ln.removeprefix("error:").strip()
                return text.removeprefix(f"{node}: ")  # the label names the node already
        code = dict((s.label, p.returncode) for s, p in self.procs).get(label)
        last = lines[-1] if lines else "no output"
        return f"exited with code {code}: {last}"

    def first_failure(self) -> tuple[str, int, str] | None:
        """``(label, exit code, reason)`` of the node that failed first on its own, or None."""
        failed = self.failed()
        if not failed:
            return None
        deadline = time.monotonic() + 1.0  # its pump reads the last line, then times the exit
        while time.monotonic() < deadline and any(lbl not in self.ended for lbl, _ in failed):
            time.sleep(0.01)
        label, code = min(failed, key=lambda lc: self.ended.get(lc[0], math.inf))
        return label, code, self.reason(label)

    def wait(self, duration: float | None, stop_event: threading.Event) -> None:
        end = None if duration is None else time.monotonic() + duration
        while not stop_event.is_set() and (end is None or time.monotonic() < end):
            if self.failed() or all(p.poll() is not None for _, p in self.procs):
                return
            time.sleep(0.05)

    def stop(self, grace: float = 5.0) -> None:
        """SIGTERM every node still running, torque commanders first; kill after ``grace`` s."""
        if self.stopping is None:
            self.stopping = time.monotonic()
        order = {name: i for i, name in enumerate(STOP_ORDER)}
        for spec, proc in sorted(self.procs, key=lambda sp: order.get(sp[0].node, 99)):
            if proc.poll() is None:
                proc.send_signal(signal.SIGTERM)
                try:
                    proc.wait(timeout=grace)
                except subprocess.TimeoutExpired:
                    print(f"[bringup] {spec.label} did not stop within {grace:g} s: killing it", flush=True)
                    proc.kill()
                    proc.wait()


def specs_from_config(path: str) -> list[NodeSpec]:
    """Read a bring-up YAML: ``joints: [{namespace, nodes, params, overrides}]`` (``groups:`` is the
    same list under another name). A ``nodes`` entry is a node name or a mapping ``{node, name,
    remap: {topic: topic}}`` (two controllers in one namespace: a PD and an add-on);
    ``overrides`` are keyed by the node's name. ``compose: true`` at the top runs every node in one
    process (``--compose``)."""
    data = load_yaml(path, "bring-up file")
    key = "groups" if isinstance(data, dict) and "groups" in data else "joints"
    if not isinstance(data, dict) or not isinstance(data.get(key), list):
        raise ParameterError(f"bring-up file {path}: needs a top-level 'joints:' (or 'groups:') list")
    base = Path(path).parent
    specs = []
    for i, joint in enumerate(data[key]):
        if not isinstance(joint, dict):
            raise ParameterError(f"bring-up file {path}: {key}[{i}] must be a mapping")
        ns = str(joint.get("namespace", ""))
        params = [str(_resolve(base, p)) for p in joint.get("params", [])]
        for entry in joint.get("nodes", ["plant_simulator", "compensating_controller", "friction_estimator"]):
            if isinstance(entry, dict):
                node, name = str(entry.get("node", "")), str(entry.get("name", ""))
                remaps = {str(k): str(v) for k, v in (entry.get("remap") or {}).items()}
                unknown = set(entry) - {"node", "name", "remap"}
                if unknown:
                    raise ParameterError(
                        f"bring-up file {path}: {key}[{i}].nodes entry has unknown key(s) "
                        f"{', '.join(sorted(unknown))}: allowed are node, name, remap"
                    )
            else:
                node, name, remaps = str(entry), "", {}
            overrides = dict(joint.get("overrides", {}).get(name or node, {}))
            specs.append(NodeSpec(node, ns, params, overrides, name=name, remaps=remaps))
    if data.get("compose"):
        specs = [composed_spec(specs)]
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
        allow_abbrev=False,
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
        "--compose",
        action="store_true",
        help="run the nodes in one process with one executor (fewer wake-ups per control cycle)",
    )
    parser.add_argument(
        "--pin",
        choices=("auto", "on", "off"),
        default="auto",
        help="pin plant + controller to one CPU and the estimator to another (auto: in lockstep mode)",
    )
    return parser


def main(argv: list[str] | None = None) -> int:
    # Ctrl-C from the first instant: validation imports the model library (seconds on a loaded
    # machine), and a SIGINT then must stop the run quietly, not print an import traceback
    stop = threading.Event()
    signal.signal(signal.SIGINT, lambda *_: stop.set())
    signal.signal(signal.SIGTERM, lambda *_: stop.set())
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
            preset_effort_limit(specs, args.preset or "abb_m19s", list(args.params))
            if args.pin == "on" or (args.pin == "auto" and args.mode == "lockstep"):
                pin_latency_chain(specs)
        if args.compose and not (len(specs) == 1 and isinstance(specs[0], ComposedSpec)):
            specs = [composed_spec(specs)]
        for s in specs:
            s.command()  # validate before starting anything
            check_preset(s)
    except ParameterError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    if stop.is_set():  # stopped while validating: nothing was started
        return 0
    from friction_ros.cli.bringup_summary import DiagnosticsWatch, plan_lines

    bring = Bringup(specs, quiet=args.quiet)
    print(f"[bringup] starting {', '.join(s.label for s in specs)} (Ctrl-C stops them, controllers first)")
    for line in plan_lines(specs):
        print(f"[bringup] {line}")
    watch = DiagnosticsWatch(specs)
    watch.start()
    bring.start()
    bring.wait(args.duration, stop)
    first = bring.first_failure()
    summary = watch.summary_lines()  # the statuses of the run, before the stop's zero-torque goodbyes
    watch.stop()
    bring.stop()
    if watch.nodes and first is None:
        print("[bringup] controllers at the end of the run (last diagnostics status):")
        for line in summary:
            print(f"[bringup]   {line}")
    if first is None:
        return 0
    label, code, reason = first
    print(f"error: {label}: {reason}", file=sys.stderr)
    return 2 if code == 2 else 1


def preset_effort_limit(specs: list[NodeSpec], preset: str, params: list[str]) -> None:
    """A controller started beside a simulated plant gets the plant preset's torque limit as its
    ``effort_limit`` unless a parameter file gives one (the controller refuses to run without)."""
    if not any(s.node == "plant_simulator" for s in specs):
        return
    for path in params:
        doc = load_yaml(path, "parameter file")
        for key, section in (doc or {}).items() if isinstance(doc, dict) else []:
            values = (section or {}).get("ros__parameters", {}) if isinstance(section, dict) else {}
            if "compensating_controller" in str(key) and isinstance(values, dict):
                gains = values.get("gains") or {}
                if (
                    "effort_limit" in values
                    or "u_clamp_max" in values
                    or (
                        isinstance(gains, dict)
                        and any(isinstance(g, dict) and "effort_limit" in g for g in gains.values())
                    )
                ):
                    return
    from friction_ros.core.experiment.joint_scale import JointScale
    from friction_ros.core.presets import load_preset

    limit = float(JointScale.from_preset(load_preset(preset)).torque_limit)
    for s in specs:
        if s.node == "compensating_controller" and "effort_limit" not in s.overrides:
            s.overrides["effort_limit"] = limit


def check_preset(spec: NodeSpec) -> None:
    """A plant preset given as an override is loaded here first: a bad one is one line, exit 2,
    before any process starts."""
    preset = spec.overrides.get("preset")
    if spec.node == "plant_simulator" and isinstance(preset, str) and preset:
        from friction_ros.core.presets import load_preset

        load_preset(preset)


if __name__ == "__main__":
    sys.exit(main())
