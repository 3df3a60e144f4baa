"""The steps of the demo over real ROS 2 processes: the identification experiment, the offline fit,
the controller's parameter document and the closed-loop tracking runs (every sample read)."""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np

from friction_ros.cli.demo_results import TrackingRun
from friction_ros.nodes.terms_file import read_terms_file


def say(msg: str) -> None:
    print(f"[demo] {msg}", flush=True)


# -- step 1 -------------------------------------------------------------------------------------------
def run_experiment(
    preset: str, profile: str, bag: Path, joint: str, seed: int | None = None, can=None
) -> None:
    """friction-experiment in lockstep, sized to the preset (its default for a simulated joint);
    ``can`` (a :class:`~friction_ros.cli.demo_can.CanJoint`): in real time on the preset's plant
    behind an emulated drive on a CAN bus instead."""
    from friction_ros.cli import experiment

    argv = ["--profile", profile, "-o", str(bag), "--overwrite", "--joint", joint]
    if seed is not None:
        argv += ["--set", f"random.seed={int(seed)}"]
    if can is not None:
        from friction_ros.cli.demo_can import run_experiment_can

        code = run_experiment_can(can, argv)
    else:
        code = experiment.main([*argv, "--preset", preset, "--mode", "lockstep"])
    if code == 3:
        raise RuntimeError("identification experiment stopped by a safety limit (see the ABORT lines above)")
    if code != 0:
        raise RuntimeError(f"identification experiment failed (exit code {code})")


# -- step 2 -------------------------------------------------------------------------------------------
def fit(
    bag: Path,
    joint: str,
    models: list[str],
    out_dir: Path,
    quick: bool,
    preset: str,
    params_file: Path,
    gate: dict | None = None,
):
    from friction_ros.core.identification import fit_bag

    options = {"maxiter": 25} if quick else {}
    return fit_bag(
        [str(bag)],
        "/joint_states",
        joint,
        models,
        out_dir,
        plant_preset=preset,
        params_file=str(params_file),
        gate=gate,
        **options,
    )


def controller_document(
    model_config: dict | None,
    inertia: float,
    scheme: str,
    reference: dict,
    gains: dict,
    *,
    load_feedforward: float = 0.0,
    allow_refused: bool = False,
    effort_limit: float,
) -> dict:
    """compensating_controller parameters (README layout: ``friction`` = model, ``compensation`` = how);
    ``effort_limit``: the joint's torque limit (the preset's drive limit)."""
    params: dict = {
        "mode": "pid",
        "effort_limit": float(effort_limit),
        "pid": dict(gains),
        "reference": dict(reference),
    }
    if load_feedforward:
        params["load_feedforward"] = float(load_feedforward)
    if model_config is not None:
        params["inertia"] = float(inertia)
        params["friction"] = dict(model_config)
        params["compensation"] = {"source": scheme, "gain": 1.0, "blend": 0.5}
        if allow_refused:  # the demo runs a refused mode on the simulated joint only to show why
            params["compensation"]["allow_refused"] = True
    return {"compensating_controller": {"ros__parameters": params}}


# -- step 3 -------------------------------------------------------------------------------------------
class MissingStates(RuntimeError):
    """A tracking run whose controller states did not all arrive."""


#: tracking runs repeated when states went missing (the run is deterministic: a repeat is the same run)
TRACK_ATTEMPTS = 3


def track(
    preset: str,
    params_file: Path,
    duration: float,
    label: str,
    joint: str = "joint1",
    period: float = 1e-3,
    can=None,
) -> TrackingRun:
    """Run plant_simulator + compensating_controller (composed: one process) in lockstep for ``duration``
    simulated seconds; ``can`` (a :class:`~friction_ros.cli.demo_can.CanJoint`): the controller on
    the preset's plant behind an emulated drive on a CAN bus, in real time, instead
    (:func:`~friction_ros.cli.demo_can.track_realtime`).

    The figures come from the controller's own terms file (``terms_file``: one row per computed
    period, :mod:`friction_ros.nodes.terms_file`), not from a subscription that a busy machine can
    leave behind: the lockstep graph computes every period exactly once, so the run's data are the
    same bytes under any load. A run whose file misses a period (a controller killed before it
    flushed) is repeated, up to TRACK_ATTEMPTS runs, and fails after that.
    """
    if can is not None:
        from friction_ros.cli.demo_can import track_realtime

        return track_realtime(can, params_file, duration, label, period)
    for attempt in range(1, TRACK_ATTEMPTS + 1):
        try:
            return _track_once(preset, params_file, duration, label, joint, period)
        except MissingStates as exc:
            if attempt == TRACK_ATTEMPTS:
                raise RuntimeError(f"{exc} (in each of {TRACK_ATTEMPTS} runs)") from None
            say(f"  {label}: {exc}; running it again")
    raise AssertionError("unreachable")


def _track_once(
    preset: str, params_file: Path, duration: float, label: str, joint: str, period: float
) -> TrackingRun:
    import threading

    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    from rosgraph_msgs.msg import Clock

    from friction_ros.cli.bringup import Bringup, NodeSpec, composed_spec
    from friction_ros.nodes.qos import STATE_QOS

    # the figures come from the controller's own terms file: one row per computed period, whatever
    # this process manages to read on a busy machine; this process follows the run on the plant's
    # /clock only (every 10 ms simulated, not every period: no wake-up of a third process per step)
    terms_path = Path(params_file).with_name(f"terms_{label}.csv")
    specs = [
        NodeSpec("plant_simulator", "", [], {"preset": preset, "mode": "lockstep", "joint_name": joint}),
        NodeSpec(
            "compensating_controller",
            "",
            [str(params_file)],
            {"use_sim_time": True, "joint_name": joint, "terms_file": str(terms_path)},
        ),
    ]
    if not rclpy.ok():
        rclpy.init()
    node = rclpy.create_node(f"friction_demo_{label.replace('-', '_').replace('+', '_')}")
    clock = [0.0]  # the latest simulated time the plant published [s]

    def on_clock(msg) -> None:
        clock[0] = max(clock[0], msg.clock.sec + msg.clock.nanosec * 1e-9)

    sub = node.create_subscription(Clock, "/clock", on_clock, STATE_QOS)
    ex = SingleThreadedExecutor()
    ex.add_node(node)
    stop = threading.Event()

    def spin():
        while not stop.is_set():
            ex.spin_once(timeout_sec=0.05)

    th = threading.Thread(target=spin, daemon=True)
    th.start()
    # plant and controller in one process, one executor (as composable components on a robot): a
    # period costs ~40 % less CPU than across two processes; in lockstep the plant re-sends its first
    # state until the controller answers it, so no start order or late match changes a byte of the run
    bring = Bringup([composed_spec(specs)], quiet=True)
    t0 = time.monotonic()
    bring.start()
    n_periods = int(round(duration / period))
    try:
        last_print = 0.0
        # the plant publishes /clock = t only after the command for t - period: once it passed the
        # run's end by two periods, the controller has computed (and written) every period of the run
        while clock[0] < duration + 2 * period - 1e-9:
            if bring.failed():
                out = "\n".join(sum(bring.output.values(), [])[-20:])
                raise RuntimeError(f"tracking run {label}: a node failed\n{out}")
            if time.monotonic() - t0 > 60 + 20 * duration:
                raise RuntimeError(f"tracking run {label}: timed out at t = {clock[0]:.2f} s")
            if sys.stdout.isatty() and time.monotonic() - last_print > 1.0:
                last_print = time.monotonic()
                print(f"\r[demo]   {label:<12} t = {clock[0]:5.1f} / {duration:g} s", end="", flush=True)
            time.sleep(0.02)
    finally:
        wall = time.monotonic() - t0
        bring.stop()  # the torque commander stops first inside
        stop.set()
        th.join(timeout=2)
        node.destroy_subscription(sub)
        node.destroy_node()
    print(
        f"{chr(13) if sys.stdout.isatty() else ''}[demo]   {label:<12} {duration:g} s simulated in {wall:.1f} s",
        flush=True,
    )
    rows = read_terms_file(str(terms_path)) if terms_path.exists() else {"stamp_ns": []}
    if not rows["stamp_ns"]:
        raise MissingStates(f"tracking run {label}: the controller wrote no terms")
    # the lockstep clock starts at 0: index by simulated time
    stamps = rows["stamp_ns"]
    t_first = min(stamps[0] * 1e-9, period)
    by_k: dict[int, int] = {}
    for i, ns in enumerate(stamps):
        by_k.setdefault(int(round((ns * 1e-9 - t_first) / period)), i)
    missing = [k for k in range(n_periods + 1) if k not in by_k]
    if missing:
        raise MissingStates(
            f"tracking run {label}: {len(missing)} of {n_periods + 1} control periods are not in the "
            f"controller's terms (first missing period {missing[0]}): the figures would not be of the whole run"
        )
    index = [by_k[k] for k in range(n_periods + 1)]
    col = lambda name: np.array([rows[name][i] for i in index])  # noqa: E731
    return TrackingRun.from_terms(label, np.arange(n_periods + 1) * period, col, wall)
