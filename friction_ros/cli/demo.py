"""friction-demo: identify and compensate a simulated joint end to end, over real ROS 2 topics.

The main job of friction_ros (``make demo``). A plant preset is the hidden truth; every node is a
separate process; lockstep mode (deterministic: the same bag, fit and figures on any machine, at
any load, as fast as the machine allows):

1. identification experiment sized to the joint (plateau speeds, ramp torques, amplitudes and
   loop gains from the preset's scale: breakaway torque, inertia, limits, encoder resolution,
   current lag and delays) -> bag in ``bags/``;
2. offline fit of the candidate models from that bag -> recommended model (the rule that decided
   is printed), a report, and a parameter file in the results folder whose compensation modes
   passed the safety gate (closed-loop check on the identified plant with +-20 % coefficient
   errors; a mode worse than none or not robustly stable is written disabled with the reason);
3. tracking runs with gains from the tuning rule (stated phase margin including the current lag
   and the control-period delay): no compensation, then every mode (feedforward, feedback,
   blended), each marked enabled or refused; every controller sample is read (count checked);
4. a table (RMS and max tracking error, stick-slip and hunting per mode, enabled/refused and why),
   warnings for anything suspicious, plots, ``demo_summary.json``.

``--all-presets`` runs every preset in ``params/`` (top-level ``presets_ok`` in the summary);
``--bag`` fits a bag the user already has (steps 2-4; tracking runs on ``--preset`` as the
stand-in plant); ``--quick`` shortens the fit and the tracking runs (tests, CI).
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
SCHEMES = ("feedforward", "feedback", "blended")
# an enabled mode may not be worse than none by more than this (relative RMS), else it is reported
WORSE_TOLERANCE = 0.02
# the ROS graph's control period (plant_simulator / compensating_controller / experiment default)
GRAPH_PERIOD = 1e-3
# s of wall time between seeing the controller's writer and starting the plant (its writer matches
# this reader a moment later; the experiment node waits alike)
MATCH_GRACE = 0.5


@dataclass
class TrackingRun:
    """One closed-loop tracking run through the ROS graph (every control period, in order)."""

    label: str
    t: np.ndarray
    reference: np.ndarray
    reference_velocity: np.ndarray
    position: np.ndarray
    velocity: np.ndarray
    error: np.ndarray
    command: np.ndarray
    friction: np.ndarray
    wall_seconds: float
    enabled: bool = True
    reason: str = ""
    metrics: dict = field(default_factory=dict)

    @property
    def rms(self) -> float:
        return float(np.sqrt(np.mean(self.error**2)))

    @property
    def max(self) -> float:
        return float(np.max(np.abs(self.error)))

    @property
    def samples(self) -> int:
        return int(self.t.size)

    def fallback_time(self) -> float | None:
        """Time after which the friction terms stayed exactly zero while they were active before
        (the controller's run-time limit-cycle fallback), else None."""
        active = self.friction != 0.0
        if not active.any() or active[-1]:
            return None
        last = int(np.nonzero(active)[0][-1])
        return float(self.t[last + 1]) if last + 1 < self.t.size else None


@dataclass
class DemoResult:
    preset: str = ""
    bag: str = ""
    bag_digest: str = ""
    fit_dir: str = ""
    params_file: str = ""
    model: str = ""
    recommendation: dict = field(default_factory=dict)
    fit_nmse: dict = field(default_factory=dict)
    gate: dict = field(default_factory=dict)
    gains: dict = field(default_factory=dict)
    reference: dict = field(default_factory=dict)
    runs: dict[str, TrackingRun] = field(default_factory=dict)
    encoder_cap: float = 100.0  # largest reduction [%] the encoder lets the measured error show
    warnings: list[str] = field(default_factory=list)
    files: list[str] = field(default_factory=list)
    timings: dict[str, float] = field(default_factory=dict)
    map_error: dict = field(default_factory=dict)

    def reduction(self, label: str) -> float:
        base = self.runs["none"].rms
        return 100.0 * (1.0 - self.runs[label].rms / base) if base > 0 else 0.0

    @property
    def best(self) -> str:
        """The enabled mode with the lowest RMS error ("none" when no mode is enabled)."""
        enabled = [k for k, r in self.runs.items() if k != "none" and r.enabled]
        return min(enabled, key=lambda k: self.runs[k].rms) if enabled else "none"

    def summary(self) -> dict:
        return {
            "preset": self.preset,
            "bag": self.bag,
            "bag_digest": self.bag_digest,
            "model": self.model,
            "recommendation": self.recommendation,
            "fit_nmse_percent": self.fit_nmse,
            "map_error_vs_truth": self.map_error,
            "params_file": self.params_file,
            "control_period": GRAPH_PERIOD,
            "gains": self.gains,
            "reference": self.reference,
            "gate": self.gate,
            "runs": {
                k: {
                    "rms_mrad": r.rms * 1e3,
                    "max_mrad": r.max * 1e3,
                    "wall_seconds": r.wall_seconds,
                    "enabled": r.enabled,
                    "reason": r.reason,
                    "samples": r.samples,
                    "fallback_s": r.fallback_time(),
                    **{f"{m}": v for m, v in r.metrics.items()},
                }
                for k, r in self.runs.items()
            },
            "best": self.best,
            "reduction_percent": {k: self.reduction(k) for k in self.runs},
            "encoder_cap_percent": self.encoder_cap,
            "warnings": self.warnings,
            "timings_s": self.timings,
        }


def _say(msg: str) -> None:
    print(f"[demo] {msg}", flush=True)


# -- step 1 -------------------------------------------------------------------------------------------
def run_experiment(preset: str, profile: str, bag: Path, joint: str, seed: int | None = None) -> None:
    """friction-experiment in lockstep, sized to the preset (its default for a simulated joint)."""
    from friction_ros.cli import experiment

    argv = ["--profile", profile, "--preset", preset, "--mode", "lockstep", "-o", str(bag), "--overwrite"]
    argv += ["--joint", joint]
    if seed is not None:
        argv += ["--set", f"random.seed={int(seed)}"]
    code = experiment.main(argv)
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
) -> dict:
    """compensating_controller parameters (README layout: ``friction`` = model, ``compensation`` = how)."""
    params: dict = {"mode": "pid", "pid": dict(gains), "reference": dict(reference)}
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
) -> TrackingRun:
    """Run plant_simulator + compensating_controller in lockstep for ``duration`` simulated seconds.

    Every controller_state of the run is read (a reliable subscription as deep as the publisher's
    history); a run in which one control period is missing is repeated (up to TRACK_ATTEMPTS runs;
    lockstep makes the repeat identical) and fails after that, so the figures never depend on what
    a loaded machine happened to deliver. Measured under a load average of 9 on 2 cores: the
    controller's writer had not yet matched this reader when the plant started (108 of 4001 states
    missing at the start) although the reader already saw the writer.
    """
    for attempt in range(1, TRACK_ATTEMPTS + 1):
        try:
            return _track_once(preset, params_file, duration, label, joint, period)
        except MissingStates as exc:
            if attempt == TRACK_ATTEMPTS:
                raise RuntimeError(f"{exc} (in each of {TRACK_ATTEMPTS} runs)") from None
            _say(f"  {label}: {exc}; running it again")
    raise AssertionError("unreachable")


def _track_once(
    preset: str, params_file: Path, duration: float, label: str, joint: str, period: float
) -> TrackingRun:
    import threading

    import rclpy
    from friction_msgs.msg import ControllerState
    from rclpy.executors import SingleThreadedExecutor

    from friction_ros.cli.bringup import Bringup, NodeSpec, pin_latency_chain
    from friction_ros.nodes.node_utils import RECORDED_QOS

    specs = [
        NodeSpec("plant_simulator", "", [], {"preset": preset, "mode": "lockstep", "joint_name": joint}),
        NodeSpec(
            "compensating_controller", "", [str(params_file)], {"use_sim_time": True, "joint_name": joint}
        ),
    ]
    pin_latency_chain(specs)
    if not rclpy.ok():
        rclpy.init()
    node = rclpy.create_node(f"friction_demo_{label.replace('-', '_').replace('+', '_')}")
    states: list = []
    sub = node.create_subscription(ControllerState, "controller_state", states.append, RECORDED_QOS)
    ex = SingleThreadedExecutor()
    ex.add_node(node)
    stop = threading.Event()

    def spin():
        while not stop.is_set():
            ex.spin_once(timeout_sec=0.05)

    th = threading.Thread(target=spin, daemon=True)
    th.start()
    # the controller first; the plant (which steps the run) only once this subscription is matched to
    # the controller's publisher, so that no state of the run is published before we listen (a late
    # match under load used to shift the evaluated window: figures then depended on machine speed)
    bring_ctrl = Bringup(specs[1:], quiet=True)
    bring_plant = Bringup(specs[:1], quiet=True)
    t0 = time.monotonic()
    bring_ctrl.start()
    n_periods = int(round(duration / period))
    try:
        while sub.get_publisher_count() < 1:
            if bring_ctrl.failed():
                out = "\n".join(sum(bring_ctrl.output.values(), [])[-20:])
                raise RuntimeError(f"tracking run {label}: the controller failed\n{out}")
            if time.monotonic() - t0 > 60:
                raise RuntimeError(f"tracking run {label}: controller_state not matched within 60 s")
            time.sleep(0.01)
        time.sleep(MATCH_GRACE)  # the controller's writer matches this reader a moment later
        bring_plant.start()
        last_print = 0.0
        while True:
            if bring_ctrl.failed() or bring_plant.failed():
                out = "\n".join(sum([*bring_ctrl.output.values(), *bring_plant.output.values()], [])[-20:])
                raise RuntimeError(f"tracking run {label}: a node failed\n{out}")
            t_sim = _stamp(states[-1]) - _stamp(states[0]) if states else 0.0
            if t_sim >= duration + 2 * period:
                break
            if time.monotonic() - t0 > 60 + 20 * duration:
                raise RuntimeError(f"tracking run {label}: timed out at t = {t_sim:.2f} s")
            if sys.stdout.isatty() and time.monotonic() - last_print > 1.0:
                last_print = time.monotonic()
                print(f"\r[demo]   {label:<12} t = {t_sim:5.1f} / {duration:g} s", end="", flush=True)
            time.sleep(0.02)
    finally:
        wall = time.monotonic() - t0
        bring_ctrl.stop()  # the torque commander first
        bring_plant.stop()
        stop.set()
        th.join(timeout=2)
        node.destroy_node()
    print(
        f"{chr(13) if sys.stdout.isatty() else ''}[demo]   {label:<12} {duration:g} s simulated in {wall:.1f} s",
        flush=True,
    )
    if not states:
        raise MissingStates(f"tracking run {label}: no controller state was received")
    # the lockstep clock starts at 0: index by simulated time, so states missed at the start count
    t_first = min(_stamp(states[0]), period)
    by_k: dict[int, object] = {}
    for m in states:
        by_k.setdefault(int(round((_stamp(m) - t_first) / period)), m)
    missing = [k for k in range(n_periods + 1) if k not in by_k]
    if missing:
        raise MissingStates(
            f"tracking run {label}: {len(missing)} of {n_periods + 1} controller states were not received "
            f"(first missing period {missing[0]}): the figures would not be of the whole run"
        )
    msgs = [by_k[k] for k in range(n_periods + 1)]
    col = lambda name: np.array([getattr(m, name) for m in msgs])  # noqa: E731
    return TrackingRun(
        label=label,
        t=np.arange(n_periods + 1) * period,
        reference=col("reference_position"),
        reference_velocity=col("reference_velocity"),
        position=col("position"),
        velocity=col("velocity"),
        error=col("error"),
        command=col("command"),
        friction=col("friction_feedforward") + col("friction_feedback"),
        wall_seconds=wall,
    )


def _stamp(m) -> float:
    return m.header.stamp.sec + m.header.stamp.nanosec * 1e-9


def run_metrics(run: TrackingRun, resolution: float) -> dict:
    """Stick-slip and hunting of one run from the measured signals (harness.tracking_metrics)."""
    from friction_ros.core.harness import tracking_metrics

    v_stick = max(2.0 * resolution / 0.01, 1e-4)  # under two counts per 10 ms counts as stuck
    m = tracking_metrics(
        run.t,
        run.reference,
        run.position,
        run.velocity,
        run.reference_velocity,
        v_stick=v_stick,
        resolution=2.0 * resolution,
    )
    return {
        "stick_fraction": m["stick_fraction"],
        "stick_events": m["stick_events"],
        "hunting_reversals": m["hunting_reversals"],
        "hunting_amplitude_mrad": m["hunting_amplitude"] * 1e3,
    }


# -- step 4 -------------------------------------------------------------------------------------------
def plot_tracking(result: DemoResult, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(2, 1, figsize=(10, 6.5), sharex=True)
    base = result.runs["none"]
    axes[0].plot(base.t, base.reference, "k", lw=1, label="reference")
    axes[0].plot(base.t, base.position, lw=0.8, label="no compensation")
    if result.best != "none":
        best = result.runs[result.best]
        axes[0].plot(best.t, best.position, lw=0.8, label=f"{result.best}")
    axes[0].set_ylabel("position [rad]")
    axes[0].legend(loc="upper right", fontsize=8)
    for label, run in result.runs.items():
        state = "" if run.enabled else " (refused)"
        axes[1].plot(
            run.t, run.error * 1e3, lw=0.7, label=f"{label}{state}: RMS {run.rms * 1e3:.3f} mrad", alpha=0.9
        )
    axes[1].set_ylabel("tracking error [mrad]")
    axes[1].set_xlabel("time [s]")
    axes[1].legend(loc="upper right", fontsize=8)
    fig.suptitle(
        f"{result.preset}: tracking error before and after friction compensation (lockstep ROS graph)"
    )
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
        vmin = max(float(np.min(np.abs(v))) / 10.0, 1e-6)
    else:
        vmax, vmin = 5.0, 1e-3
    grid = np.concatenate([-np.geomspace(vmax, vmin, 200), np.geomspace(vmin, vmax, 200)])
    if truth is not None:
        ax.plot(grid, truth.joint_friction(grid), "k--", lw=1, label=f"truth ({truth.name})")
    for name, m in fit_result.models.items():
        try:
            ax.plot(grid, m.steady_state(grid), lw=1, label=f"fit: {name}")
        except Exception:  # a learned model without a steady-state map
            continue
    ax.set_xscale("symlog", linthresh=vmin * 10)
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

    def fmt(x):
        return "n/a" if x is None or not math.isfinite(x) else f"{x:.3f} %"

    print()
    print(
        f"[{result.preset}] Model chosen: {result.model}   fit NMSE (validation): "
        f"high velocity {fmt(nmse.get('high'))}, low velocity {fmt(nmse.get('low'))}"
    )
    if result.recommendation.get("rule"):
        print(f"  chosen by: {result.recommendation['rule']}")
    print(f"  tracking gains {result.gains}; reference {result.reference.get('type')}")
    print()
    print(
        "| compensation | state | RMS error [mrad] | max error [mrad] | RMS reduction [%] "
        "| stick fraction | hunting reversals |"
    )
    print("|---|---|---|---|---|---|---|")
    for label, run in result.runs.items():
        state = "-" if label == "none" else ("enabled" if run.enabled else run.reason)
        print(
            f"| {label} | {state} | {run.rms * 1e3:.4f} | {run.max * 1e3:.4f} | {result.reduction(label):.1f} "
            f"| {run.metrics.get('stick_fraction', math.nan):.3f} | {run.metrics.get('hunting_reversals', 0)} |"
        )
    if result.best == "none":
        print("\nbest: no compensation mode is enabled for this joint")
    else:
        print(f"\nbest enabled mode: {result.best} ({result.reduction(result.best):.1f} % lower RMS error)")
    for w in result.warnings:
        print(f"WARNING: {w}")


def _resolution(preset_obj) -> float:
    p = preset_obj.params
    if p.encoder_cpr <= 0:
        return 0.0
    per_rev = 2.0 * math.pi / p.encoder_cpr
    return per_rev / p.ratio if p.encoder_location == "motor" else per_rev


def run_preset(args, preset_name: str, results_dir: Path) -> DemoResult:
    """Steps 1-4 for one preset; raises RuntimeError/ParameterError naming what failed."""
    from friction_ros.core.experiment.joint_scale import JointScale
    from friction_ros.core.experiment.tracking_design import tracking_gains, tracking_reference
    from friction_ros.core.identification.export import dump_yaml
    from friction_ros.core.presets import load_preset

    preset = load_preset(preset_name)  # validates the name early
    scale = JointScale.from_preset(preset, period=GRAPH_PERIOD)  # the ROS graph runs at 1 kHz
    res = DemoResult(preset=preset_name)
    results_dir.mkdir(parents=True, exist_ok=True)
    stamp = time.strftime("%Y%m%d_%H%M%S")
    bag = Path(args.bag) if args.bag else ROOT / "bags" / f"demo_{preset_name}_{stamp}"
    t_all = time.monotonic()
    if not args.bag:
        _say(f"1/4 identification experiment on {preset_name} ({args.profile} profile, lockstep) -> {bag}")
        t = time.monotonic()
        run_experiment(preset_name, args.profile, bag, args.joint, args.seed)
        res.timings["experiment"] = time.monotonic() - t
    else:
        _say(f"1/4 using the bag you gave: {bag}")
    res.bag = str(bag)
    from friction_ros.core.bag import content_digest

    res.bag_digest = content_digest(bag, ["/joint_states", "/experiment_events"])[0] if not args.bag else ""

    _say(f"2/4 fitting {', '.join(args.models)} from the bag")
    t = time.monotonic()
    fit_dir = results_dir / "fit"
    params_file = results_dir / "friction_params.yaml"
    p = preset.params
    gains = tracking_gains(scale)
    reference = tracking_reference(scale, duration=max(args.duration, 1.0))
    res.gains, res.reference = dict(gains), dict(reference)
    gate = {
        "scale": scale,
        "current_lag": p.current_time_constant if p.actuation == "current" else 0.0,
        "delay": p.measurement_delay + p.actuation_delay,
        "velocity_filter_hz": p.velocity_filter_hz,
        "gains": gains,
        "reference": reference,
    }
    fit_result = fit(bag, args.joint, args.models, fit_dir, args.quick, preset_name, params_file, gate)
    res.timings["fit"] = time.monotonic() - t
    res.fit_dir = str(fit_dir)
    name = fit_result.recommended
    if name is None or fit_result.models[name].config is None:
        raise RuntimeError("the fit recommended no model with a parameter set")
    model = fit_result.models[name]
    res.model = name
    res.recommendation = dict(getattr(fit_result, "recommendation", {}) or {})
    res.fit_nmse = {
        "high": float(model.metrics.get("nmse_high_percent", math.nan)),
        "low": float(model.metrics.get("nmse_low_percent", math.nan)),
        "all": float(model.metrics.get("nmse_percent", math.nan)),
    }
    res.warnings += list(fit_result.warnings)
    for key, text in (("high", "high-velocity"), ("low", "low-velocity")):
        if not math.isfinite(res.fit_nmse[key]):
            note = model.metrics.get(f"nmse_{key}_note", "no signal above the noise in that subset")
            res.warnings.append(f"{text} NMSE not available: {note}")
    inertia = float(model.coefficients.get("J", 0.0) or scale.inertia)
    res.map_error = map_error_vs_truth(model.steady_state, preset.joint_friction, fit_result.plateaus)
    verdicts = fit_result.gate
    res.gate = {m: v.as_dict() for m, v in verdicts.items()}
    res.params_file = str(params_file)
    _say(f"   recommended model: {name}; parameters -> {params_file}")
    for m, v in verdicts.items():
        _say(f"   {m:<12} {v.reason}")
        if not v.enabled:
            res.warnings.append(f"{m} compensation refused by the safety gate: {v.reason}")

    _say(
        f"3/4 tracking runs ({args.duration:g} s each, lockstep): none, "
        + ", ".join(SCHEMES)
        + " (refused modes run only to show why)"
    )
    t = time.monotonic()
    runs_spec = [("none", None)] + [(s, model.config) for s in SCHEMES]
    for label, cfg in runs_spec:
        f = results_dir / f"controller_{label}.yaml"
        refused = label != "none" and not verdicts[label].enabled
        doc = controller_document(
            cfg, inertia, label, reference, gains, load_feedforward=-scale.load, allow_refused=refused
        )
        f.write_text(dump_yaml(doc))
        run = track(preset_name, f, args.duration, label, args.joint, GRAPH_PERIOD)
        if label != "none":
            run.enabled = bool(verdicts[label].enabled)
            run.reason = verdicts[label].reason
        run.metrics = run_metrics(run, _resolution(preset))
        res.runs[label] = run
    res.timings["tracking"] = time.monotonic() - t
    base = res.runs["none"]
    for label, run in res.runs.items():
        if label == "none":
            continue
        fb = run.fallback_time()
        if fb is not None:
            res.warnings.append(
                f"{label}: the controller detected a compensation-induced limit cycle and fell back to no "
                f"friction compensation at t = {fb:.3f} s"
            )
        if run.enabled and run.rms > base.rms * (1.0 + WORSE_TOLERANCE):
            res.warnings.append(
                f"{label} was enabled by the gate but tracked worse than no compensation "
                f"({run.rms * 1e3:.3f} vs {base.rms * 1e3:.3f} mrad)"
            )
    res.encoder_cap = encoder_cap(base, _resolution(preset))
    if res.encoder_cap < ENCODER_CAP_WARN:
        q = _resolution(preset)
        res.warnings.append(
            f"the encoder ({q:.3g} rad per count) caps what any compensation can show on the measured error at "
            f"-{res.encoder_cap:.0f} %: perfect tracking of this reference still reads "
            f"{base.rms * (1 - res.encoder_cap / 100) * 1e3:.3g} mrad RMS"
        )
    if res.best == "none":
        res.warnings.append("no compensation mode is enabled: the parameter file compensates nothing")
    elif res.reduction(res.best) < 10.0:
        res.warnings.append(
            f"friction compensation barely changes the tracking error on this joint (best {res.best}: "
            f"{res.reduction(res.best):.1f} %): friction is a small part of it (loop bandwidth, backlash, "
            "encoder resolution or an unmodelled effect dominate), or the fitted model explains little"
        )

    _say("4/4 results")
    plot_tracking(res, results_dir / "tracking_error.png")
    plot_friction_map(fit_result, preset, results_dir / "friction_map.png")
    res.timings["total"] = time.monotonic() - t_all
    res.files = [
        str(bag),
        str(params_file),
        str(fit_dir / "report.md"),
        str(results_dir / "tracking_error.png"),
        str(results_dir / "friction_map.png"),
        str(results_dir / "demo_summary.json"),
    ]
    (results_dir / "demo_summary.json").write_text(json.dumps(res.summary(), indent=2, default=_json_default))
    return res


#: an encoder cap below this [%] is named in the demo's warnings
ENCODER_CAP_WARN = 90.0


def encoder_cap(run: TrackingRun, resolution: float) -> float:
    """The largest RMS reduction [%] any controller can show on this run's measured error: even a
    joint that tracked perfectly reads ``ref - q round(ref / q)`` through an encoder of resolution
    ``q``, so ``100 (1 - RMS(that) / RMS(run))`` (100 without an encoder)."""
    if resolution <= 0 or not run.rms > 0:
        return 100.0
    ref = np.asarray(run.reference, dtype=float)
    floor = float(np.sqrt(np.mean((ref - resolution * np.round(ref / resolution)) ** 2)))
    return 100.0 * (1.0 - floor / run.rms)


def map_error_vs_truth(fitted, truth, plateaus) -> dict:
    """Steady-state map of the fit against the preset's truth (both directions).

    ``sliding_percent``: largest |f_fit(v) - f_true(v)| / |f_true(v)| over the plateau speed range
    (lowest to highest plateau speed); ``static_peak_percent``: signed relative error of the static
    peak, the largest |f(v)| for speeds from 1e-6 up to the lowest plateau speed (fs for a Stribeck
    curve), as (fit - truth) / truth, the worse direction.
    """
    speeds = sorted(abs(p.velocity) for p in plateaus if abs(p.velocity) > 0)
    lo, hi = (speeds[0], speeds[-1]) if speeds else (1e-2, 1.0)
    out = {"v_min": lo, "v_max": hi, "sliding_percent": math.nan, "static_peak_percent": math.nan}
    slide, peak = [], []
    for sign in (1.0, -1.0):
        v = sign * np.geomspace(lo, max(hi, lo * 1.0001), 200)
        ft, ff = np.asarray(truth(v)), np.asarray(fitted(v))
        ok = np.abs(ft) > 0
        if ok.any():
            slide.append(float(np.max(np.abs(ff[ok] - ft[ok]) / np.abs(ft[ok]))))
        vs = sign * np.geomspace(1e-6, lo, 200)
        pt, pf = float(np.max(np.abs(truth(vs)))), float(np.max(np.abs(fitted(vs))))
        if pt > 0:
            peak.append((pf - pt) / pt)
    if slide:
        out["sliding_percent"] = 100.0 * max(slide)
    if peak:
        out["static_peak_percent"] = 100.0 * max(peak, key=abs)
    return out


def _json_default(x):
    if isinstance(x, (np.floating, np.integer)):
        return x.item()
    if isinstance(x, np.ndarray):
        return x.tolist()
    return str(x)


def run(args) -> DemoResult | dict:
    """One preset (a DemoResult) or, with ``--all-presets``, every preset (a summary dict)."""
    from friction_ros.core.presets import PRESET_NAMES, load_preset

    stamp = time.strftime("%Y%m%d_%H%M%S")
    if not args.all_presets:
        load_preset(args.preset)
        results_dir = Path(args.results or ROOT / "results" / f"demo_{Path(args.preset).stem}_{stamp}")
        res = run_preset(args, args.preset, results_dir)
        print_table(res)
        print("\nfiles written:")
        for f in res.files:
            print(f"  {f}")
        print(
            f"\ntotal time {res.timings['total']:.0f} s ("
            + ", ".join(f"{k} {v:.0f} s" for k, v in res.timings.items() if k != "total")
            + ")"
        )
        return res
    results_dir = Path(args.results or ROOT / "results" / f"demo_all_{stamp}")
    results_dir.mkdir(parents=True, exist_ok=True)
    out: dict = {"presets": {}, "presets_ok": [], "presets_failed": {}}
    for name in PRESET_NAMES:
        _say(f"=== preset {name} ===")
        try:
            res = run_preset(args, name, results_dir / name)
        except (ParameterError, RuntimeError, FileNotFoundError) as exc:
            out["presets_failed"][name] = str(exc).splitlines()[0]
            print(f"error: {name}: {exc}", file=sys.stderr)
            continue
        print_table(res)
        s = res.summary()
        out["presets"][name] = s
        worse = [
            k
            for k, r in res.runs.items()
            if k != "none" and r.enabled and r.rms > res.runs["none"].rms * 1.02
        ]
        if not worse:
            out["presets_ok"].append(name)
    out["presets_total"] = len(PRESET_NAMES)
    (results_dir / "demo_summary.json").write_text(json.dumps(out, indent=2, default=_json_default))
    print(
        f"\npresets ok: {len(out['presets_ok'])} of {len(PRESET_NAMES)}; summary {results_dir / 'demo_summary.json'}"
    )
    return out


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="friction-demo", description=__doc__.split("\n\n")[0])
    p.add_argument("--preset", default="abb_m19s", help="plant preset (hidden truth), default abb_m19s")
    p.add_argument("--all-presets", action="store_true", help="run every preset in params/ one after another")
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
        "--seed", type=int, help="seed of the experiment's random excitation (default: the profile's)"
    )
    return p


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    if args.quick:
        args.duration = min(args.duration, 4.0)
    if args.all_presets and args.bag:
        print(
            "error: --all-presets runs the experiment on every preset: it cannot be combined with --bag",
            file=sys.stderr,
        )
        return 2
    try:
        out = run(args)
    except (ParameterError, RuntimeError, FileNotFoundError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("\ninterrupted", file=sys.stderr)
        return 130
    if isinstance(out, dict) and out.get("presets_failed"):
        return 1
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
