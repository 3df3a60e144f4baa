"""friction-demo on a multi-joint plant preset (``--preset arm7_plant``): identify and compensate a
whole arm end to end, over real ROS 2 topics, in lockstep (deterministic at any load).

1. identification experiment per joint (friction-experiment with the arm's plant file; a joint
   with a pendulum gravity load keeps to a short travel) -> bag in ``bags/``;
2. ``friction-fit BAG --joint all`` -> one parameter file: each joint's fitted friction and
   compensation mode, or compensation disabled with the reason (the fit failed or explains little),
   and each joint's ``effort_limit``;
3. the arm's own plain PD per joint (tracking design rule, :mod:`~friction_ros.core.experiment.arm_example`)
   alone, then with the friction add-on (compensating_controller, ``mode: compensation_only``,
   ``sum_base_command``: the fitted compensation added to the PD's command); the figures come from
   the controllers' own terms files (every control period);
4. a per-joint table (RMS tracking error without and with the add-on, mode, enabled or refused and
   why), ``tracking_error.png`` (one panel per joint) and ``demo_summary.json``.
"""

from __future__ import annotations

import json
import math
import time
from pathlib import Path

import yaml

from friction_ros.cli.demo_arm_steps import (
    GRAVITY_TRAVEL,
    ArmRun,
    addon_document,
    experiment_argv,
    fit_argv,
    joint_verdicts,
    track_arm,
)
from friction_ros.cli.demo_report import json_default, print_files_and_timings
from friction_ros.cli.demo_results import GRAPH_PERIOD
from friction_ros.cli.demo_steps import say
from friction_ros.core.validation import ParameterError

ROOT = Path(__file__).resolve().parents[2]
#: models fitted per joint (static maps: the add-on feeds them forward from the reference velocity)
ARM_MODELS = ["coulomb_viscous", "stribeck"]
#: an enabled joint may not track worse than the PD alone by more than this (relative RMS) unwarned
WORSE_TOLERANCE = 0.02


def arm_plant_file(preset: str) -> Path | None:
    """The plant_simulator parameter file of ``preset`` when it is a multi-joint plant (``joints``),
    else None (a single-joint preset, or not a preset at all: the single-joint demo says why)."""
    from friction_ros.cli.experiment_arm import PLANT_NODE, file_section
    from friction_ros.core.presets import preset_path

    try:
        path = preset_path(preset)
        return path if file_section([str(path)], PLANT_NODE).get("joints") else None
    except ParameterError:
        return None


def plant_values(plant_file: Path) -> dict:
    doc = yaml.safe_load(plant_file.read_text())
    return next(v["ros__parameters"] for k, v in doc.items() if str(k).split("/")[-1] == "plant_simulator")


class ArmDemoResult:
    """What one arm demo measured (:meth:`summary` is ``demo_summary.json``)."""

    def __init__(self, preset: str, joints: list[str]):
        self.preset, self.joints = preset, joints
        self.bag = self.params_file = self.fit_index = ""
        self.verdicts: dict[str, dict] = {}
        self.runs: dict[str, ArmRun] = {}
        self.warnings: list[str] = []
        self.files: list[str] = []
        self.timings: dict[str, float] = {}

    def rows(self) -> list[dict]:
        pd, addon = self.runs["pd"], self.runs["pd+addon"]
        out = []
        for j in self.joints:
            v = self.verdicts[j]
            a, b = pd.rms(j), addon.rms(j)
            out.append(
                {
                    "joint": j,
                    "rms_pd_mrad": a * 1e3,
                    "rms_addon_mrad": b * 1e3,
                    "max_pd_mrad": pd.max(j) * 1e3,
                    "max_addon_mrad": addon.max(j) * 1e3,
                    "reduction_percent": 100.0 * (1.0 - b / a) if a > 0 else 0.0,
                    **v,
                }
            )
        return out

    def summary(self) -> dict:
        return {
            "preset": self.preset,
            "joints": self.joints,
            "bag": self.bag,
            "params_file": self.params_file,
            "fit_index": self.fit_index,
            "control_period": GRAPH_PERIOD,
            "table": self.rows(),
            "runs": {
                k: {"wall_seconds": r.wall_seconds, "samples": int(r.t.size)} for k, r in self.runs.items()
            },
            "warnings": self.warnings,
            "files": self.files,
            "timings_s": self.timings,
        }


def run(args) -> ArmDemoResult:
    """Steps 1-4 (module docstring); RuntimeError/ParameterError naming what failed."""
    from friction_ros.cli import experiment, fit
    from friction_ros.core.experiment.arm_example import arm_parameter_document, joint_presets
    from friction_ros.core.identification.report.export import dump_yaml

    plant_file = arm_plant_file(args.preset)
    values = plant_values(plant_file)
    joints = [str(j) for j in values["joints"]]
    gravity = [j for j, p in joint_presets(values) if float(getattr(p.params, "gravity", 0.0) or 0.0)]
    stamp = time.strftime("%Y%m%d_%H%M%S")
    name = plant_file.stem
    results = Path(args.results or ROOT / "results" / f"demo_{name}_{stamp}")
    results.mkdir(parents=True, exist_ok=True)
    res = ArmDemoResult(name, joints)
    t_all = time.monotonic()
    if args.bag:
        bag = Path(args.bag)
        say(f"1/4 using the bag you gave: {bag}")
    else:
        bag = ROOT / "bags" / f"demo_{name}_{stamp}"
        say(
            f"1/4 identification experiment on {name}: joints {', '.join(joints)} ({args.profile} profile, "
            f"lockstep; joints with a gravity load ({', '.join(gravity) or 'none'}) within {GRAVITY_TRAVEL:g} rad) -> {bag}"
        )
        t = time.monotonic()
        code = experiment.main(experiment_argv(plant_file, joints, gravity, args, bag))
        if code != 0:
            why = (
                "stopped by a safety limit (see the ABORT lines above)"
                if code == 3
                else f"failed (exit code {code})"
            )
            raise RuntimeError(f"identification experiment {why}")
        res.timings["experiment"] = time.monotonic() - t
    res.bag = str(bag)

    models = list(args.models) if args.models else ARM_MODELS
    say(f"2/4 friction-fit --joint all ({', '.join(models)}) from the bag")
    t = time.monotonic()
    fit_dir, params_file = results / "fit", results / "friction_params.yaml"
    code = fit.main(fit_argv(bag, fit_dir, params_file, models, args.quick))
    if code != 0 or not params_file.exists():
        raise RuntimeError(f"friction-fit --joint all failed (exit code {code})")
    res.timings["fit"] = time.monotonic() - t
    res.params_file, res.fit_index = str(params_file), str(fit_dir / "index.md")
    fitted = yaml.safe_load(params_file.read_text())
    index = json.loads((fit_dir / "index.json").read_text())
    res.verdicts = joint_verdicts(fitted, index)
    res.warnings += list(index.get("warnings", []))

    duration = max(float(args.duration), 1.0)
    say(f"3/4 tracking runs ({duration:g} s each, lockstep): the arm's PD alone, then PD + friction add-on")
    t = time.monotonic()
    doc, _ = arm_parameter_document(values, duration=duration)
    pd_file, addon_file = results / "pd_controller.yaml", results / "friction_addon.yaml"
    pd_file.write_text(dump_yaml({"/**/pd_controller": doc["/**/pd_controller"]}))
    addon_file.write_text(dump_yaml(addon_document(fitted, doc["/**/pd_controller"]["ros__parameters"])))
    res.runs["pd"] = track_arm("pd", plant_file, pd_file, None, joints, duration, GRAPH_PERIOD)
    res.runs["pd+addon"] = track_arm(
        "pd_addon", plant_file, pd_file, addon_file, joints, duration, GRAPH_PERIOD
    )
    res.runs["pd+addon"].label = "pd+addon"
    res.timings["tracking"] = time.monotonic() - t
    for row in res.rows():
        if row["enabled"] and row["rms_addon_mrad"] > row["rms_pd_mrad"] * (1.0 + WORSE_TOLERANCE):
            res.warnings.append(
                f"{row['joint']}: the add-on ({row['mode']}) tracked worse than the PD alone "
                f"({row['rms_addon_mrad']:.4g} vs {row['rms_pd_mrad']:.4g} mrad RMS)"
            )
    if not any(v["enabled"] for v in res.verdicts.values()):
        res.warnings.append("no joint is compensated: the add-on passes the PD's command through unchanged")

    say("4/4 results")
    plot_joints(res, results / "tracking_error.png")
    res.timings["total"] = time.monotonic() - t_all
    res.files = [str(bag), str(params_file), res.fit_index, str(pd_file), str(addon_file)]
    res.files += [str(results / "tracking_error.png"), str(results / "demo_summary.json")]
    (results / "demo_summary.json").write_text(json.dumps(res.summary(), indent=2, default=json_default))
    return res


def print_arm_table(res: ArmDemoResult) -> None:
    print()
    print(f"[{res.preset}] the arm's PD without and with the friction add-on (compensation_only, lockstep)")
    print()
    print("| joint | RMS error PD [mrad] | RMS error PD + add-on [mrad] | reduction [%] | mode | state |")
    print("|---|---|---|---|---|---|")
    for r in res.rows():
        state = "enabled" if r["enabled"] else f"refused: {r['reason']}"
        print(
            f"| {r['joint']} | {r['rms_pd_mrad']:.4g} | {r['rms_addon_mrad']:.4g} | {r['reduction_percent']:.1f} "
            f"| {r['mode']} | {state} |"
        )
    for w in res.warnings:
        print(f"WARNING: {w}")


def plot_joints(res: ArmDemoResult, path: Path) -> None:
    """One PNG, one panel per joint: tracking error of the PD alone and with the add-on."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    n = len(res.joints)
    cols = 2 if n > 1 else 1
    rows_n = math.ceil(n / cols)
    fig, axes = plt.subplots(rows_n, cols, figsize=(12, 2.4 * rows_n), sharex=True, squeeze=False)
    for ax, row in zip(axes.flat, res.rows()):
        j = row["joint"]
        for label, run in res.runs.items():
            ax.plot(
                run.t, run.pd[j]["error"] * 1e3, lw=0.7, label=f"{label}: RMS {run.rms(j) * 1e3:.3g} mrad"
            )
        state = row["mode"] if row["enabled"] else "refused"
        ax.set_title(f"{j} ({state})", fontsize=9)
        ax.set_ylabel("error [mrad]", fontsize=8)
        ax.legend(loc="upper right", fontsize=7)
    for ax in list(axes.flat)[n:]:
        ax.set_visible(False)
    for ax in axes[-1]:
        ax.set_xlabel("time [s]")
    fig.suptitle(f"{res.preset}: tracking error of the arm's PD without and with the friction add-on")
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


def main_arm(args) -> ArmDemoResult:
    """The arm demo with its console output (called by friction-demo for a multi-joint preset)."""
    if getattr(args, "all_presets", False):
        raise ParameterError(
            "--all-presets runs the single-joint presets: it cannot be combined with an arm preset"
        )
    res = run(args)
    print_arm_table(res)
    print_files_and_timings(res.files, res.timings)
    return res
