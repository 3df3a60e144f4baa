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

``--all-presets`` runs every preset in ``params/`` (top-level ``presets_ok`` in the summary),
``--presets A B ...`` the presets named, one after another, with the same summary;
``--bag`` fits a bag the user already has (steps 2-4; tracking runs on ``--preset`` as the
stand-in plant); ``--quick`` shortens the fit and the tracking runs (tests, CI).

``--can PROTOCOL`` (a registered drive protocol: ``odrive_cansimple``, ``mit``, ``cia402``): the same
four steps with the preset's plant behind an emulated drive (``drive_emulator``) and
``drive_interface`` on the ``friction_local`` CAN bus, as on a robot (:mod:`friction_ros.cli.demo_can`).
A CAN bus has no lockstep: the experiment and the tracking runs are real time (1 kHz wall clock);
a step whose drive faulted or whose telemetry went stale stops the demo with the reason.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from pathlib import Path

from friction_ros.cli.demo_report import (
    json_default,
    plot_friction_map,
    plot_tracking,
    print_files_and_timings,
    print_table,
)
from friction_ros.cli.demo_results import (
    ENCODER_CAP_WARN,
    GRAPH_PERIOD,
    DemoResult,
    encoder_cap,
    excited_speeds,
    map_error_vs_truth,
    refusal_warning,
    run_metrics,
)
from friction_ros.cli.demo_steps import controller_document, fit, run_experiment, say, track
from friction_ros.cli.reasons import grouped
from friction_ros.core.identification.fit.gating import preset_lags
from friction_ros.core.validation import ParameterError

ROOT = Path(__file__).resolve().parents[2]
SCHEMES = ("feedforward", "feedback", "blended")
DEFAULT_MODELS = ["coulomb", "stribeck", "lugre", "gms4"]
# an enabled mode may not be worse than none by more than this (relative RMS), else it is reported
WORSE_TOLERANCE = 0.02
# a real-time (CAN) run that missed more than this fraction of its periods is not a measurement
MISSING_INVALID = 0.10


def _resolution(preset_obj) -> float:
    p = preset_obj.params
    if p.encoder_cpr <= 0:
        return 0.0
    per_rev = 2.0 * math.pi / p.encoder_cpr
    return per_rev / p.ratio if p.encoder_location == "motor" else per_rev


def new_bag_dir(parent: Path, name: str) -> Path:
    """``parent/name``, created empty for this run (``name_2``, ``name_3`` ... when taken): two demos
    started in the same second never write one bag."""
    parent.mkdir(parents=True, exist_ok=True)
    for n in range(1, 1000):
        path = parent / (name if n == 1 else f"{name}_{n}")
        try:
            path.mkdir()
            return path
        except FileExistsError:
            continue
    raise RuntimeError(f"no free bag name {name}_N in {parent}: remove old demo bags")


def run_preset(args, preset_name: str, results_dir: Path) -> DemoResult:
    """Steps 1-4 for one preset; raises RuntimeError/ParameterError naming what failed."""
    from friction_ros.core.experiment.joint_scale import JointScale
    from friction_ros.core.experiment.tracking_design import tracking_gains, tracking_reference
    from friction_ros.core.identification.report.export import dump_yaml
    from friction_ros.core.presets import load_preset

    preset = load_preset(preset_name)  # validates the name early
    args.models = args.models or DEFAULT_MODELS
    scale = JointScale.from_preset(preset, period=GRAPH_PERIOD)  # the ROS graph runs at 1 kHz
    res = DemoResult(preset=preset_name)
    can, timing, lags = None, "lockstep", preset_lags(preset)
    if args.can:
        from dataclasses import replace

        from friction_ros.cli.demo_can import EXTRA_DELAY_PERIODS, can_joint

        can = can_joint(preset, preset_name, args.can, args.joint)
        timing = f"real time, 1 kHz wall clock, over CAN: {args.can} on friction_local"
        res.timing, res.can = "real time", {"protocol": args.can, "bus": "friction_local"}
        # the CAN path's delay: telemetry up to a period old, the command sent at the drive node's next period
        lags["delay"] += EXTRA_DELAY_PERIODS * GRAPH_PERIOD
        scale = replace(scale, delay=scale.delay + EXTRA_DELAY_PERIODS * GRAPH_PERIOD)
    results_dir.mkdir(parents=True, exist_ok=True)
    stamp = time.strftime("%Y%m%d_%H%M%S")
    bag = Path(args.bag) if args.bag else new_bag_dir(ROOT / "bags", f"demo_{preset_name}_{stamp}")
    t_all = time.monotonic()
    if not args.bag:
        say(f"1/4 identification experiment on {preset_name} ({args.profile} profile, {timing}) -> {bag}")
        t = time.monotonic()
        run_experiment(preset_name, args.profile, bag, args.joint, args.seed, can=can)
        res.timings["experiment"] = time.monotonic() - t
    else:
        say(f"1/4 using the bag you gave: {bag}")
    res.bag = str(bag)
    from friction_ros.core.bag import content_digest

    res.bag_digest = content_digest(bag, ["/joint_states", "/experiment_events"])[0] if not args.bag else ""

    say(f"2/4 fitting {', '.join(args.models)} from the bag")
    t = time.monotonic()
    fit_dir = results_dir / "fit"
    params_file = results_dir / "friction_params.yaml"
    gains = tracking_gains(scale)
    reference = tracking_reference(scale, duration=max(args.duration, 1.0))
    res.gains, res.reference = dict(gains), dict(reference)
    gate = {"scale": scale, **lags, "gains": gains, "reference": reference}
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
    res.map_error = map_error_vs_truth(
        model.steady_state,
        preset.joint_friction,
        fit_result.plateaus,
        excited_speeds([*fit_result.train, *fit_result.validation]),
    )
    verdicts = fit_result.gate
    res.gate = {m: v.as_dict() for m, v in verdicts.items()}
    res.params_file = str(params_file)
    say(f"   recommended model: {name}; parameters -> {params_file}")
    save_partial(res, results_dir, "")  # the experiment and the fit are kept whatever comes next
    for modes, reason in grouped({m: v.reason for m, v in verdicts.items()}):
        say(f"   {modes}: {reason}")
    res.warnings += [refusal_warning(m, v.reason) for m, v in verdicts.items() if not v.enabled]

    say(
        f"3/4 tracking runs ({args.duration:g} s each, {timing}): none, "
        + ", ".join(SCHEMES)
        + " (refused modes run only to show why)"
    )
    t = time.monotonic()
    runs_spec = [("none", None)] + [(s, model.config) for s in SCHEMES]
    for label, cfg in runs_spec:
        f = results_dir / f"controller_{label}.yaml"
        refused = label != "none" and not verdicts[label].enabled
        doc = controller_document(
            cfg,
            inertia,
            label,
            reference,
            gains,
            load_feedforward=-scale.load,
            allow_refused=refused,
            effort_limit=can.drive_params["torque_limit"] if can else scale.torque_limit,
        )
        f.write_text(dump_yaml(doc))
        try:
            run = track(preset_name, f, args.duration, label, args.joint, GRAPH_PERIOD, can=can)
        except (RuntimeError, ParameterError) as exc:  # what is done so far stays on disk, said so
            raise RuntimeError(f"{exc}\n{save_partial(res, results_dir, f'tracking run {label}')}") from None
        if label != "none":
            run.enabled = bool(verdicts[label].enabled)
            run.reason = verdicts[label].reason
        run.metrics = run_metrics(run, _resolution(preset))
        res.runs[label] = run
    res.timings["tracking"] = time.monotonic() - t
    if can is not None:
        can_checks(res, can, results_dir)
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

    say("4/4 results")
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
    summary = {**res.summary(), "status": "complete"}
    (results_dir / "demo_summary.json").write_text(json.dumps(summary, indent=2, default=json_default))
    return res


def can_checks(res: DemoResult, can, results_dir: Path) -> None:
    """After the CAN runs: the drive must have reported itself disabled after every step (else
    RuntimeError: never a success); periods a run did not compute are warned about beyond 2 %."""
    left = [step for step, disabled in can.disabled_after if not disabled]
    res.can["steps"] = len(can.disabled_after)
    res.can["drive_disabled_after_every_step"] = not left
    if left:
        kept = save_partial(res, results_dir, "the drive's shutdown")
        raise RuntimeError(f"the drive did not report itself disabled after: {', '.join(left)}\n{kept}")
    for label, run in res.runs.items():
        expected = run.samples + run.missing_periods
        if run.missing_periods > MISSING_INVALID * expected:
            run.invalid = (
                f"the drive node's telemetry was late for {run.missing_periods} of {expected} periods "
                "(a busy machine): not a measurement, run the demo again on a quieter machine"
            )
            res.warnings.append(f"{label}: {run.invalid}")
        elif run.missing_periods > 0.02 * expected:
            res.warnings.append(
                f"{label}: the controller computed {run.samples} of {expected} periods (real time: late "
                "telemetry on a busy machine); the figures are of those periods"
            )
    if any(r.invalid for r in res.runs.values()):
        res.warnings.append("runs whose telemetry was late are left out of the best mode")


def save_partial(res: DemoResult, results_dir: Path, failed: str) -> str:
    """Write ``demo_summary.json`` with what is done so far (``status``: ``incomplete``, the step
    that failed, or ``running``); returns a line saying what was kept."""
    try:
        doc = res.summary()
    except (KeyError, ValueError, ZeroDivisionError):  # a summary of partial runs: the plain facts
        doc = {"preset": res.preset, "bag": res.bag, "model": res.model, "params_file": res.params_file}
    doc["status"] = f"incomplete: {failed} failed" if failed else "running"
    doc["completed_runs"] = list(res.runs)
    path = results_dir / "demo_summary.json"
    path.write_text(json.dumps(doc, indent=2, default=json_default))
    kept = ", ".join(
        x for x in (res.bag and f"bag {res.bag}", res.params_file and f"fit {res.params_file}") if x
    )
    runs = f", tracking runs {', '.join(res.runs)}" if res.runs else ""
    return f"kept: {kept}{runs} (summary {path})"


def run(args):
    """One preset (a DemoResult); with ``--all-presets``/``--presets`` several (a summary dict); a
    multi-joint plant preset (``arm7_plant``) the arm demo (:mod:`friction_ros.cli.demo_arm`)."""
    from friction_ros.cli.demo_arm import arm_plant_file, main_arm
    from friction_ros.core.presets import PRESET_NAMES, load_preset

    if not args.all_presets and not args.presets and arm_plant_file(args.preset) is not None:
        if args.can:
            raise ParameterError(
                f"--can runs one joint behind one drive: {args.preset} is a multi-joint plant"
            )
        return main_arm(args)
    stamp = time.strftime("%Y%m%d_%H%M%S")
    names = list(PRESET_NAMES) if args.all_presets else list(dict.fromkeys(args.presets or []))
    for name in names:
        load_preset(name)  # a misspelt name stops the run before any preset starts
    if not names:
        load_preset(args.preset)
        results_dir = Path(args.results or ROOT / "results" / f"demo_{Path(args.preset).stem}_{stamp}")
        res = run_preset(args, args.preset, results_dir)
        print_table(res)
        print_files_and_timings(res.files, res.timings)
        return res
    results_dir = Path(args.results or ROOT / "results" / f"demo_all_{stamp}")
    results_dir.mkdir(parents=True, exist_ok=True)
    out: dict = {"presets": {}, "presets_ok": [], "presets_failed": {}}
    for name in names:
        say(f"=== preset {name} ===")
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
    out["presets_total"] = len(names)
    (results_dir / "demo_summary.json").write_text(json.dumps(out, indent=2, default=json_default))
    print(
        f"\npresets ok: {len(out['presets_ok'])} of {len(names)}; summary {results_dir / 'demo_summary.json'}"
    )
    return out


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        allow_abbrev=False, prog="friction-demo", description=__doc__.split("\n\n")[0]
    )
    p.add_argument(
        "--preset",
        default="abb_m19s",
        help="plant preset (hidden truth), default abb_m19s; a multi-joint plant (arm7_plant) runs the arm demo",
    )
    several = p.add_mutually_exclusive_group()
    several.add_argument(
        "--all-presets", action="store_true", help="run every preset in params/ one after another"
    )
    several.add_argument(
        "--presets",
        nargs="+",
        metavar="PRESET",
        help="run these presets one after another (summary as --all-presets)",
    )
    p.add_argument("--bag", help="fit this bag instead of running the experiment (rosbag2 dir or .mcap)")
    p.add_argument("--joint", default="joint1", help="joint name in the bag / graph (default joint1)")
    p.add_argument("--profile", default="quick", choices=("quick", "default"), help="experiment profile")
    p.add_argument(
        "--models",
        nargs="+",
        help="models to fit (default coulomb stribeck lugre gms4; a multi-joint preset: coulomb_viscous stribeck)",
    )
    p.add_argument(
        "--duration", type=float, default=10.0, help="simulated seconds per tracking run (default 10)"
    )
    p.add_argument("--results", help="results folder (default results/demo_<preset>_<time>)")
    p.add_argument(
        "--can",
        metavar="PROTOCOL",
        help="the joint behind an emulated drive on a CAN bus (friction_local), real time: "
        "a registered drive protocol (odrive_cansimple, mit, cia402)",
    )
    p.add_argument("--quick", action="store_true", help="shorter fit and tracking runs (tests, CI)")
    p.add_argument(
        "--seed", type=int, help="seed of the experiment's random excitation (default: the profile's)"
    )
    return p


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    if args.can is not None:
        from friction_ros.core.can.protocol import protocol_names

        if args.can not in protocol_names():
            print(
                f"error: --can {args.can!r}: not a drive protocol; allowed: {', '.join(protocol_names())}",
                file=sys.stderr,
            )
            return 2
    if args.quick:
        args.duration = min(args.duration, 4.0)
    if (args.all_presets or args.presets) and args.bag:
        print(
            "error: --all-presets and --presets run the experiment on each preset: they cannot be combined with --bag",
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
