"""friction-demo: identify and compensate a simulated joint end to end, over real ROS 2 topics.

The main job of friction_ros (``make demo``). With the ABB M19-S preset and GMS-4 friction as the
hidden truth, every node a separate process, lockstep mode (deterministic, as fast as the machine
allows):

1. identification experiment (plant_simulator + identification_experiment + bag_recorder) -> bag in
   ``bags/``;
2. offline fit of the candidate models from that bag (friction-fit core) -> parameter file in
   ``params/`` and a report;
3. tracking runs (plant_simulator + compensating_controller) without compensation, then with the
   fitted model as feedforward, as feedback and blended;
4. a table (model chosen, fit NMSE, RMS and max tracking error with and without compensation,
   reduction in percent) and plots (tracking error before/after, friction map with the fit).

Options run the same pipeline on another preset (``--preset``), on a bag the user already has
(``--bag``: steps 2-4; the tracking runs then use ``--preset`` as the stand-in plant), and with
shorter runs (``--quick``, used by the tests and CI).
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from friction_ros.core.validation import ParameterError

ROOT = Path(__file__).resolve().parents[2]
DEFAULT_REFERENCE = {
    "type": "band_limited_random",
    "amplitude": 0.05,
    "cutoff": 1.0,
    "duration": 20.0,
    "seed": 1,
}
# seed 003's PD (Kp = 200 N m/rad, Kd = 0.15 N m s/rad) at 1 kHz
DEFAULT_GAINS = {"p": 200.0, "d": 0.15}
# real time (CAN path): one period of command delay and scheduling jitter -> softer gains
REALTIME_GAINS = {"p": 30.0, "i": 60.0, "d": 0.3}
SCHEMES = ("feedforward", "feedback", "blended")


@dataclass
class TrackingRun:
    """One closed-loop tracking run through the ROS graph."""

    label: str
    t: np.ndarray
    reference: np.ndarray
    position: np.ndarray
    error: np.ndarray
    command: np.ndarray
    wall_seconds: float

    @property
    def rms(self) -> float:
        return float(np.sqrt(np.mean(self.error**2)))

    @property
    def max(self) -> float:
        return float(np.max(np.abs(self.error)))


@dataclass
class DemoResult:
    bag: str = ""
    fit_dir: str = ""
    params_file: str = ""
    model: str = ""
    fit_nmse: dict = field(default_factory=dict)
    runs: dict[str, TrackingRun] = field(default_factory=dict)
    files: list[str] = field(default_factory=list)
    timings: dict[str, float] = field(default_factory=dict)

    def table(self) -> list[list]:
        base = self.runs["none"]
        rows = []
        for label, run in self.runs.items():
            red = 100.0 * (1.0 - run.rms / base.rms) if base.rms > 0 else 0.0
            rows.append([label, run.rms * 1e3, run.max * 1e3, red])
        return rows

    @property
    def best(self) -> str:
        return min((k for k in self.runs if k != "none"), key=lambda k: self.runs[k].rms)


def _say(msg: str) -> None:
    print(f"[demo] {msg}", flush=True)


# -- step 1 -------------------------------------------------------------------------------------------
def run_experiment(preset: str, profile: str, bag: Path) -> None:
    from friction_ros.cli import experiment

    argv = ["--profile", profile, "--preset", preset, "--mode", "lockstep", "-o", str(bag), "--overwrite"]
    code = experiment.main(argv)
    if code != 0:
        raise RuntimeError(f"identification experiment failed (exit code {code})")


# -- step 2 -------------------------------------------------------------------------------------------
def fit(bag: Path, joint: str, models: list[str], out_dir: Path, quick: bool, preset: str):
    from friction_ros.core.identification import fit_bag

    options = {"maxiter": 25} if quick else {}
    return fit_bag([str(bag)], "/joint_states", joint, models, out_dir, plant_preset=preset, **options)


def controller_document(
    model_config: dict | None, inertia: float, scheme: str, reference: dict, gains: dict
) -> dict:
    """compensating_controller parameters (README layout: ``friction`` = model, ``compensation`` = how)."""
    params: dict = {"mode": "pid", "pid": dict(gains), "reference": dict(reference)}
    if model_config is not None:
        params["inertia"] = float(inertia)
        params["friction"] = dict(model_config)
        params["compensation"] = {"source": scheme, "gain": 1.0, "blend": 0.5}
    return {"compensating_controller": {"ros__parameters": params}}


# -- step 3 -------------------------------------------------------------------------------------------
def track(
    preset: str, params_file: Path, duration: float, label: str, joint: str = "joint1", can_path: bool = False
) -> TrackingRun:
    """Run plant_simulator + compensating_controller in lockstep for ``duration`` simulated seconds.

    ``can_path``: instead, the real drive_interface node talks CAN frames to the emulated drive
    (``simulated_drive``) in real time, and the controller runs on the wall clock.
    """
    import threading

    import rclpy
    from friction_msgs.msg import ControllerState
    from rclpy.executors import SingleThreadedExecutor

    from friction_ros.cli.bringup import Bringup, NodeSpec, pin_latency_chain
    from friction_ros.nodes.node_utils import STATE_QOS

    if can_path:
        specs = [
            NodeSpec(
                "simulated_drive",
                "",
                [],
                {"joint_name": joint, "torque_limit": 5.0, "enable_on_start": True},
                args=["--preset", preset],
            ),
            NodeSpec("compensating_controller", "", [str(params_file)], {"joint_name": joint}),
        ]
    else:
        specs = [
            NodeSpec("plant_simulator", "", [], {"preset": preset, "mode": "lockstep", "joint_name": joint}),
            NodeSpec(
                "compensating_controller", "", [str(params_file)], {"use_sim_time": True, "joint_name": joint}
            ),
        ]
        pin_latency_chain(specs)  # lockstep: ~1.7x faster on 2 cores
    if not rclpy.ok():
        rclpy.init()
    node = rclpy.create_node(f"friction_demo_{label.replace('-', '_').replace('+', '_')}")
    states: list = []
    node.create_subscription(ControllerState, "controller_state", states.append, STATE_QOS)
    ex = SingleThreadedExecutor()
    ex.add_node(node)
    stop = threading.Event()

    def spin():
        while not stop.is_set():
            ex.spin_once(timeout_sec=0.05)

    th = threading.Thread(target=spin, daemon=True)
    th.start()
    bring = Bringup(specs, quiet=True)
    t0 = time.monotonic()
    bring.start()
    try:
        last_print = 0.0
        while True:
            if bring.failed():
                out = "\n".join(sum(bring.output.values(), [])[-20:])
                raise RuntimeError(f"tracking run {label}: a node failed\n{out}")
            t_sim = _stamp(states[-1]) - _stamp(states[0]) if states else 0.0
            if t_sim >= duration:
                break
            if time.monotonic() - t0 > 60 + 20 * duration:
                raise RuntimeError(f"tracking run {label}: timed out at t = {t_sim:.2f} s")
            if sys.stdout.isatty() and time.monotonic() - last_print > 1.0:
                last_print = time.monotonic()
                print(f"\r[demo]   {label:<12} t = {t_sim:5.1f} / {duration:g} s", end="", flush=True)
            time.sleep(0.02)
    finally:
        wall = time.monotonic() - t0
        bring.stop()
        stop.set()
        th.join(timeout=2)
        node.destroy_node()
    print(
        f"{chr(13) if sys.stdout.isatty() else ''}[demo]   {label:<12} {duration:g} s simulated in {wall:.1f} s",
        flush=True,
    )
    by_k: dict[int, object] = {}
    t_first = _stamp(states[0]) if states else 0.0
    for m in states:
        by_k[int(round((_stamp(m) - t_first) * 1000))] = m
    ks = sorted(k for k in by_k if k <= duration * 1000)
    msgs = [by_k[k] for k in ks]
    return TrackingRun(
        label=label,
        t=np.array([_stamp(m) - t_first for m in msgs]),
        reference=np.array([m.reference_position for m in msgs]),
        position=np.array([m.position for m in msgs]),
        error=np.array([m.error for m in msgs]),
        command=np.array([m.command for m in msgs]),
        wall_seconds=wall,
    )


def _stamp(m) -> float:
    return m.header.stamp.sec + m.header.stamp.nanosec * 1e-9


# -- step 4 -------------------------------------------------------------------------------------------
def plot_tracking(result: DemoResult, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(2, 1, figsize=(10, 6.5), sharex=True)
    base = result.runs["none"]
    axes[0].plot(base.t, base.reference, "k", lw=1, label="reference")
    axes[0].plot(base.t, base.position, lw=0.8, label="no compensation")
    best = result.runs[result.best]
    axes[0].plot(best.t, best.position, lw=0.8, label=f"{result.best}")
    axes[0].set_ylabel("position [rad]")
    axes[0].legend(loc="upper right", fontsize=8)
    for label, run in result.runs.items():
        axes[1].plot(run.t, run.error * 1e3, lw=0.7, label=f"{label}: RMS {run.rms * 1e3:.3f} mrad")
    axes[1].set_ylabel("tracking error [mrad]")
    axes[1].set_xlabel("time [s]")
    axes[1].legend(loc="upper right", fontsize=8)
    fig.suptitle("Tracking error before and after friction compensation (lockstep ROS graph)")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def plot_friction_map(fit_result, truth, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    plateaus = fit_result.plateaus
    fig, ax = plt.subplots(figsize=(8, 5))
    if plateaus:
        v = np.array([p.velocity for p in plateaus])
        f = np.array([p.torque for p in plateaus])
        ax.plot(v, f, "ko", ms=4, label="plateau means (bag)")
        vmax = float(np.max(np.abs(v))) * 1.1
    else:
        vmax = 5.0
    grid = np.concatenate([-np.geomspace(vmax, 1e-3, 200), np.geomspace(1e-3, vmax, 200)])
    if truth is not None:
        ax.plot(grid, truth.steady_state(grid), "k--", lw=1, label=f"truth ({truth.name})")
    for name, m in fit_result.models.items():
        try:
            ax.plot(grid, m.steady_state(grid), lw=1, label=f"fit: {name}")
        except Exception:  # a learned model without a steady-state map
            continue
    ax.set_xscale("symlog", linthresh=0.05)
    ax.set_xlabel("velocity [rad/s]")
    ax.set_ylabel("friction torque [N m]")
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=8)
    ax.set_title("Steady-state friction map: data, fits and truth")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def print_table(result: DemoResult) -> None:
    nmse = result.fit_nmse
    print()
    print(
        f"Model chosen: {result.model}   fit NMSE (validation): "
        f"high velocity {nmse.get('high', math.nan):.3f} %, low velocity {nmse.get('low', math.nan):.3f} %"
    )
    print()
    print("| compensation | RMS error [mrad] | max error [mrad] | RMS reduction [%] |")
    print("|---|---|---|---|")
    for label, rms, mx, red in result.table():
        print(f"| {label} | {rms:.4f} | {mx:.4f} | {red:.1f} |")
    print(
        f"\nbest: {result.best} ({result.table()[list(result.runs).index(result.best)][3]:.1f} % lower RMS error)"
    )


def run(args) -> DemoResult:
    from friction_ros.core.identification.export import dump_yaml
    from friction_ros.core.presets import load_preset

    stamp = time.strftime("%Y%m%d_%H%M%S")
    preset = load_preset(args.preset)  # validates the name early
    res = DemoResult()
    results_dir = Path(args.results or ROOT / "results" / f"demo_{args.preset}_{stamp}")
    results_dir.mkdir(parents=True, exist_ok=True)
    bag = Path(args.bag) if args.bag else ROOT / "bags" / f"demo_{args.preset}_{stamp}"
    t_all = time.monotonic()
    if not args.bag:
        _say(f"1/4 identification experiment on {args.preset} ({args.profile} profile, lockstep) -> {bag}")
        t = time.monotonic()
        run_experiment(args.preset, args.profile, bag)
        res.timings["experiment"] = time.monotonic() - t
    else:
        _say(f"1/4 using the bag you gave: {bag}")
    res.bag = str(bag)

    _say(f"2/4 fitting {', '.join(args.models)} from the bag")
    t = time.monotonic()
    fit_dir = results_dir / "fit"
    fit_result = fit(bag, args.joint, args.models, fit_dir, args.quick, args.preset)
    res.timings["fit"] = time.monotonic() - t
    res.fit_dir = str(fit_dir)
    name = fit_result.recommended
    if name is None or fit_result.models[name].config is None:
        raise RuntimeError("the fit recommended no model with a parameter set")
    model = fit_result.models[name]
    res.model = name
    res.fit_nmse = {
        "high": float(model.metrics.get("nmse_high_percent", math.nan)),
        "low": float(model.metrics.get("nmse_low_percent", math.nan)),
    }
    inertia = float(model.coefficients.get("J", preset.params.reflected_inertia))
    params_file = ROOT / "params" / f"fitted_{args.preset}.yaml"
    doc = fit_result.parameter_document(name)
    params_file.write_text(
        dump_yaml(doc, f"# Fitted by friction-demo from {bag.name} ({name}); regenerate with `make demo`.")
    )
    res.params_file = str(params_file)
    _say(f"   recommended model: {name}; parameters -> {params_file.relative_to(ROOT)}")

    path = "CAN path, real time" if args.can else "lockstep"
    _say(f"3/4 tracking runs ({args.duration:g} s each, {path}): none, " + ", ".join(SCHEMES))
    reference = dict(DEFAULT_REFERENCE, duration=max(args.duration, 1.0))
    t = time.monotonic()
    runs_spec = [("none", None)] + [(s, model.config) for s in SCHEMES]
    for label, cfg in runs_spec:
        f = results_dir / f"controller_{label}.yaml"
        f.write_text(
            dump_yaml(
                controller_document(
                    cfg, inertia, label, reference, REALTIME_GAINS if args.can else DEFAULT_GAINS
                )
            )
        )
        res.runs[label] = track(args.preset, f, args.duration, label, args.joint, can_path=args.can)
    res.timings["tracking"] = time.monotonic() - t

    _say("4/4 results")
    plot_tracking(res, results_dir / "tracking_error.png")
    plot_friction_map(fit_result, preset.friction, results_dir / "friction_map.png")
    summary = {
        "preset": args.preset,
        "bag": res.bag,
        "model": res.model,
        "fit_nmse_percent": res.fit_nmse,
        "params_file": res.params_file,
        "runs": {
            k: {"rms_mrad": r.rms * 1e3, "max_mrad": r.max * 1e3, "wall_seconds": r.wall_seconds}
            for k, r in res.runs.items()
        },
        "best": res.best,
        "reduction_percent": {row[0]: row[3] for row in res.table()},
        "timings_s": res.timings,
    }
    (results_dir / "demo_summary.json").write_text(json.dumps(summary, indent=2))
    res.files = [
        str(bag),
        str(params_file),
        str(fit_dir / "report.md"),
        str(results_dir / "tracking_error.png"),
        str(results_dir / "friction_map.png"),
        str(results_dir / "demo_summary.json"),
    ]
    res.timings["total"] = time.monotonic() - t_all
    print_table(res)
    print("\nfiles written:")
    for f in res.files:
        print(f"  {f}")
    print(
        f"\ntotal time {res.timings['total']:.0f} s "
        + "("
        + ", ".join(f"{k} {v:.0f} s" for k, v in res.timings.items() if k != "total")
        + ")"
    )
    return res


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="friction-demo", description=__doc__.split("\n\n")[0])
    p.add_argument("--preset", default="abb_m19s", help="plant preset (hidden truth), default abb_m19s")
    p.add_argument("--bag", help="fit this bag instead of running the experiment (rosbag2 dir or .mcap)")
    p.add_argument("--joint", default="joint1", help="joint name in the bag / graph (default joint1)")
    p.add_argument("--profile", default="quick", choices=("quick", "default"), help="experiment profile")
    p.add_argument(
        "--models", nargs="+", default=["coulomb", "stribeck", "lugre", "gms4"], help="models to fit"
    )
    p.add_argument(
        "--duration", type=float, default=10.0, help="simulated seconds per tracking run (default 10)"
    )
    p.add_argument("--results", help="results folder (default results/demo_<preset>_<time>)")
    p.add_argument("--quick", action="store_true", help="shorter fit and tracking runs (tests, CI)")
    p.add_argument(
        "--can",
        action="store_true",
        help="tracking runs on the CAN path: drive_interface + emulated ODrive (real time, simulated_drive)",
    )
    return p


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    if args.quick:
        args.duration = min(args.duration, 4.0)
    try:
        run(args)
    except (ParameterError, RuntimeError, FileNotFoundError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("\ninterrupted", file=sys.stderr)
        return 130
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
