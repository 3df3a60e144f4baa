"""The steps of the arm demo over real ROS 2 processes: the per-joint identification experiment,
``friction-fit --joint all``, the add-on's parameter document and the lockstep tracking runs of the
arm's own PD with and without the add-on (figures from the controllers' own terms files)."""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from friction_ros.cli.demo_steps import say
from friction_ros.core.config import flatten, unflatten
from friction_ros.nodes.terms_file import read_terms_file

NAMESPACE = "arm"
#: travel [rad] of a joint with a pendulum gravity load during identification: a plateau's constant
#: bias holds the load at the start position only, so the load may change little (1 - cos 0.5 = 12 %)
GRAVITY_TRAVEL = 0.5
#: a lockstep tracking run may take this much wall time per simulated second (plus a start margin)
WALL_PER_SIM_SECOND = 30.0


def experiment_argv(
    plant_file: Path, joints: list[str], gravity_joints: list[str], args, bag: Path
) -> list[str]:
    """friction-experiment's arguments: the arm's plant file, lockstep, gravity joints' travel limited.
    ``--quick``: plateaus only, every joint at once (the simulated joints are independent)."""
    argv = ["--params", str(plant_file), "--profile", args.profile, "--mode", "lockstep"]
    argv += ["-o", str(bag), "--overwrite", "--quiet"]
    for j in gravity_joints:
        argv += ["--set", f"limits.{j}.max_travel={GRAVITY_TRAVEL}"]
    if args.quick:
        argv += ["--program", "plateaus", "--joint-sequence", "together", "--set", "plateaus.count=3"]
    if args.seed is not None:
        argv += ["--set", f"random.seed={int(args.seed)}"]
    return argv


def fit_argv(bag: Path, fit_dir: Path, params_file: Path, models: list[str], quick: bool) -> list[str]:
    """friction-fit's arguments: every joint, one parameter file."""
    argv = [str(bag), "--joint", "all", "--out", str(fit_dir), "--params-out", str(params_file), "--force"]
    argv += ["--models", *models, "--jobs", "2", "--quiet"]
    if quick:
        argv += ["--maxiter", "25", "--residual", "none", "--no-plots"]
    return argv


def addon_document(fitted: dict, pd_values: dict) -> dict:
    """``friction_addon``: the fitted compensating_controller section (per-joint layout) as the add-on
    (``mode: compensation_only``, ``sum_base_command``), following the PD's references, each joint's
    sum (PD + compensation) clamped to the PD's effort limit (the joint's)."""
    flat = flatten(fitted["compensating_controller"]["ros__parameters"])
    joints = list(pd_values["joints"])
    flat.pop("effort_limit", None)
    flat.update(mode="compensation_only", sum_base_command=True)
    for j in joints:
        flat[f"gains.{j}.effort_limit"] = float(pd_values["gains"][j]["effort_limit"])
        for k, v in pd_values["reference"][j].items():
            flat[f"reference.{j}.{k}"] = v
    values = unflatten({k: v for k, v in flat.items() if k != "joints"})
    return {"/**/friction_addon": {"ros__parameters": {"joints": joints, **values}}}


@dataclass
class ArmRun:
    """One tracking run: per joint, every control period's terms of the PD (and of the add-on)."""

    label: str
    t: np.ndarray
    pd: dict[str, dict[str, np.ndarray]]
    addon: dict[str, dict[str, np.ndarray]] = field(default_factory=dict)
    wall_seconds: float = 0.0

    def rms(self, joint: str) -> float:
        return float(np.sqrt(np.mean(self.pd[joint]["error"] ** 2)))

    def max(self, joint: str) -> float:
        return float(np.max(np.abs(self.pd[joint]["error"])))


def _columns(
    path: Path, joints: list[str], n: int, period: float, who: str
) -> dict[str, dict[str, np.ndarray]]:
    """{joint: {column: values for periods 0..n}} of a terms file; RuntimeError when a period is missing."""
    rows = read_terms_file(str(path)) if path.exists() else {"stamp_ns": []}
    if not rows["stamp_ns"]:
        raise RuntimeError(f"tracking run: the {who} wrote no terms ({path})")
    out = {}
    for j in joints:
        idx = [i for i, name in enumerate(rows["joint"]) if name == j]
        by_k: dict[int, int] = {}
        for i in idx:
            by_k.setdefault(int(round(rows["stamp_ns"][i] * 1e-9 / period)), i)
        missing = [k for k in range(n + 1) if k not in by_k]
        if missing:
            raise RuntimeError(
                f"tracking run: {len(missing)} of {n + 1} control periods of {j} are not in the {who}'s terms "
                f"(first missing period {missing[0]})"
            )
        order = [by_k[k] for k in range(n + 1)]
        out[j] = {c: np.array([rows[c][i] for i in order]) for c in rows if c not in ("stamp_ns", "joint")}
    return out


def track_arm(
    label: str,
    plant_file: Path,
    pd_file: Path,
    addon_file: Path | None,
    joints: list[str],
    duration: float,
    period: float,
) -> ArmRun:
    """The arm's plant and PD (and the add-on summing the PD's command) in lockstep for ``duration``
    simulated seconds; the figures come from the controllers' terms files (one row per computed
    period and joint, whatever the load), the run's end from the plant's ``/clock``."""
    import threading

    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    from rosgraph_msgs.msg import Clock

    from friction_ros.cli.bringup import Bringup, NodeSpec
    from friction_ros.nodes.qos import STATE_QOS

    out_dir = pd_file.parent
    pd_terms, addon_terms = out_dir / f"terms_{label}_pd.csv", out_dir / f"terms_{label}_addon.csv"
    sim = {"use_sim_time": True}
    pd_remap = {"joint_commands": "pd_command"} if addon_file else {}
    controllers = [
        NodeSpec(
            "compensating_controller",
            NAMESPACE,
            [str(pd_file)],
            {**sim, "terms_file": str(pd_terms)},
            name="pd_controller",
            remaps=pd_remap,
        )
    ]
    if addon_file:
        controllers.append(
            NodeSpec(
                "compensating_controller",
                NAMESPACE,
                [str(addon_file)],
                {**sim, "terms_file": str(addon_terms)},
                name="friction_addon",
                remaps={"base_command": "pd_command", "controller_state": "compensation_state"},
            )
        )
    # /clock every 10 ms of simulated time: the run's progress without a reader that must keep up
    plant = [
        NodeSpec("plant_simulator", NAMESPACE, [str(plant_file)], {"mode": "lockstep", "clock_period": 0.01})
    ]
    if not rclpy.ok():
        rclpy.init()
    node = rclpy.create_node(f"friction_demo_arm_{label}")
    now = [0.0]

    def on_clock(m) -> None:
        now[0] = max(now[0], m.clock.sec + m.clock.nanosec * 1e-9)

    node.create_subscription(Clock, "/clock", on_clock, STATE_QOS)
    ex = SingleThreadedExecutor()
    ex.add_node(node)
    stop = threading.Event()

    def spin() -> None:
        while not stop.is_set():
            ex.spin_once(timeout_sec=0.05)

    th = threading.Thread(target=spin, daemon=True)
    th.start()
    ctrl, plant_proc = Bringup(controllers, quiet=True), Bringup(plant, quiet=True)
    t0 = time.monotonic()
    try:
        ctrl.start()
        plant_proc.start()  # lockstep: the plant re-sends its first state until every joint is answered
        while now[0] < duration + 3 * period:
            failed = ctrl.failed() or plant_proc.failed()
            if failed:
                out = "\n".join(sum([*ctrl.output.values(), *plant_proc.output.values()], [])[-20:])
                raise RuntimeError(f"tracking run {label}: a node failed ({failed[0][0]})\n{out}")
            if time.monotonic() - t0 > 60 + WALL_PER_SIM_SECOND * duration:
                raise RuntimeError(f"tracking run {label}: timed out at t = {now[0]:.2f} s")
            time.sleep(0.02)
    finally:
        wall = time.monotonic() - t0
        ctrl.stop()  # the torque commanders first: their terms files are flushed on the way out
        plant_proc.stop()
        stop.set()
        th.join(timeout=2)
        node.destroy_node()
    say(f"  {label:<10} {duration:g} s simulated in {wall:.1f} s")
    n = int(round(duration / period))
    run = ArmRun(
        label, np.arange(n + 1) * period, _columns(pd_terms, joints, n, period, "PD"), wall_seconds=wall
    )
    if addon_file:
        run.addon = _columns(addon_terms, joints, n, period, "add-on")
    return run


def joint_verdicts(fitted: dict, index: dict) -> dict[str, dict[str, Any]]:
    """Per joint: the compensation mode the fit enabled, or ``refused`` with the reason (from the
    parameter file the controller reads and friction-fit's index)."""
    cc = fitted["compensating_controller"]["ros__parameters"]
    comp = cc.get("compensation") or {}
    out = {}
    for j in cc["joints"]:
        own = {**{k: v for k, v in comp.items() if not isinstance(v, dict)}, **(comp.get(j) or {})}
        source = str(own.get("source", "feedforward"))
        info = (index.get("joints") or {}).get(j, {})
        reasons = own.get("refused_reasons") or []
        enabled = source != "none"
        out[j] = {
            "mode": source if enabled else "none",
            "enabled": enabled,
            "reason": "" if enabled else (reasons[0] if reasons else f"the fit {info.get('verdict', '?')}"),
            "model": (cc.get("friction") or {}).get(j, {}).get("model", "none"),
            "verdict": info.get("verdict", ""),
            "nmse_percent": info.get("nmse_percent"),
            "effort_limit_fitted": _gain(cc, j, "effort_limit"),
        }
    return out


def _gain(cc: dict, joint: str, key: str):
    g = (cc.get("gains") or {}).get(joint) or {}
    return g.get(key, cc.get(key))
