"""The demo's outputs for a reader: tracking and friction-map plots, the console table, JSON values."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from friction_ros.cli.demo_results import DemoResult, refusal_warning
from friction_ros.cli.reasons import footnotes, format_values
from friction_ros.core.plotting import break_at_gaps, legend_outside, set_robust_ylim


def _save(fig, path: Path) -> None:
    import matplotlib.pyplot as plt

    fig.savefig(path, dpi=110, bbox_inches="tight")
    plt.close(fig)


def tracking_figure(result: DemoResult):
    """Position against the reference (none and the best mode) and the tracking error of every run;
    legends beside the axes, error limits that one spike does not stretch, lines broken at gaps."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(2, 1, figsize=(10, 6.5), sharex=True)
    base = result.runs["none"]
    axes[0].plot(*break_at_gaps(base.t, base.reference), "k", lw=1, label="reference")
    axes[0].plot(*break_at_gaps(base.t, base.position), lw=0.8, label="no compensation")
    shown = [base.reference, base.position]
    if result.best != "none":
        best = result.runs[result.best]
        axes[0].plot(*break_at_gaps(best.t, best.position), lw=0.8, label=f"{result.best}")
        shown.append(best.position)
    set_robust_ylim(axes[0], *shown)
    axes[0].set_ylabel("position [rad]")
    legend_outside(axes[0])
    for label, run in result.runs.items():
        state = "" if run.enabled else " (refused)"
        axes[1].plot(
            *break_at_gaps(run.t, run.error * 1e3),
            lw=0.7,
            label=f"{label}{state}: RMS {run.rms * 1e3:.3f} mrad",
            alpha=0.9,
        )
    set_robust_ylim(axes[1], *(run.error * 1e3 for run in result.runs.values()))
    axes[1].set_ylabel("tracking error [mrad]")
    axes[1].set_xlabel("time [s]")
    legend_outside(axes[1])
    fig.suptitle(
        f"{result.preset}: tracking error before and after friction compensation "
        + (f"(real time over CAN: {result.can.get('protocol')})" if result.can else "(lockstep ROS graph)")
    )
    fig.tight_layout()
    return fig


def plot_tracking(result: DemoResult, path: Path) -> None:
    _save(tracking_figure(result), path)


def friction_map_figure(fit_result, truth):
    """Plateau means of the bag, the fitted steady-state maps and the preset's true map."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    plateaus = fit_result.plateaus
    fig, ax = plt.subplots(figsize=(8, 5))
    shown = []
    if plateaus:
        v = np.array([p.velocity for p in plateaus])
        f = np.array([p.torque for p in plateaus])
        ax.plot(v, f, "ko", ms=4, label="plateau means (bag)")
        shown.append(f)
        vmax = float(np.max(np.abs(v))) * 1.1
        vmin = max(float(np.min(np.abs(v))) / 10.0, 1e-6)
    else:
        vmax, vmin = 5.0, 1e-3
    grid = np.concatenate([-np.geomspace(vmax, vmin, 200), np.geomspace(vmin, vmax, 200)])
    if truth is not None:
        y = truth.joint_friction(grid)
        ax.plot(grid, y, "k--", lw=1, label=f"truth ({truth.name})")
        shown.append(y)
    for name, m in fit_result.models.items():
        if m.status != "fitted":  # no curve of a model that failed or diverged
            continue
        try:
            y = m.steady_state(grid)
        except Exception:  # a learned model without a steady-state map
            continue
        ax.plot(grid, y, lw=1, label=f"fit: {name}")
        shown.append(y)
    set_robust_ylim(ax, *shown)
    ax.set_xscale("symlog", linthresh=vmin * 10)
    ax.set_xlabel("velocity [rad/s]")
    ax.set_ylabel("friction torque [N m]")
    ax.grid(True, alpha=0.3)
    legend_outside(ax)
    ax.set_title("Steady-state friction map: data, fits and truth")
    fig.tight_layout()
    return fig


def plot_friction_map(fit_result, truth, path: Path) -> None:
    _save(friction_map_figure(fit_result, truth), path)


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
    print(f"  tracking gains {format_values(result.gains)}; reference {result.reference.get('type')}")
    print()
    print(
        "| compensation | state | RMS error [mrad] | max error [mrad] | RMS reduction [%] "
        "| stick fraction | hunting reversals |"
    )
    print("|---|---|---|---|---|---|---|")
    refused = {label: run.reason for label, run in result.runs.items() if label != "none" and not run.enabled}
    markers, notes = footnotes(refused, strip="refused: ")
    for label, run in result.runs.items():
        state = (
            "-" if label == "none" else ("enabled" if run.enabled else f"refused {markers.get(label, '')}")
        )
        print(
            f"| {label} | {state} | {run.rms * 1e3:.4f} | {run.max * 1e3:.4f} | {result.reduction(label):.1f} "
            f"| {run.metrics.get('stick_fraction', math.nan):.3f} | {run.metrics.get('hunting_reversals', 0)} |"
        )
    shown = {refusal_warning(label, reason) for label, reason in refused.items()}
    if notes:
        print("\nrefused by the safety gate (the mode is written disabled):")
        for line in notes:
            print(f"  {line}")
    if result.can:
        computed = ", ".join(
            f"{k} {r.samples} of {r.samples + r.missing_periods}" for k, r in result.runs.items()
        )
        print(
            f"\nreal time over CAN ({result.can['protocol']} on {result.can['bus']}, 1 kHz wall clock, not "
            f"lockstep: figures vary run to run); periods computed: {computed}; the drive reported itself "
            f"disabled after each of the {result.can.get('steps', 0)} steps"
        )
    if result.best == "none":
        print("\nbest: no compensation mode is enabled for this joint")
    else:
        print(f"\nbest enabled mode: {result.best} ({result.reduction(result.best):.1f} % lower RMS error)")
    for w in result.warnings:
        if w not in shown:  # a refusal is listed under the table already
            print(f"WARNING: {w}")


def print_files_and_timings(files, timings: dict) -> None:
    """The end of a demo's output: the files written and the time of each step."""
    print("\nfiles written:")
    for f in files:
        print(f"  {f}")
    steps = ", ".join(f"{k} {v:.0f} s" for k, v in timings.items() if k != "total")
    print(f"\ntotal time {timings['total']:.0f} s ({steps})")


def json_default(x):
    if isinstance(x, (np.floating, np.integer)):
        return x.item()
    if isinstance(x, np.ndarray):
        return x.tolist()
    return str(x)
