"""The files of ``friction-fleet trend``: report.md, alarms.json, trends.csv and the plots.

* ``alarms.json``: the design (k, h per baseline size, reference temperature) and every wear alarm
  (:func:`~.trend.alarms`: robot, joint, coefficient, date, size_percent, statistic ...);
* ``trends.csv``: one row per run and coefficient: raw value and stderr, temperature, normalised
  value and its stderr, change vs baseline [%], z and CUSUM statistic;
* ``plots/overview.png``: every joint ranked by drift (recent change in baseline sigmas);
* ``plots/<robot>.png``: one panel per joint, change of each normalised coefficient vs its baseline
  [%] with its uncertainty, the raw (not normalised) change faint behind, alarms marked;
* ``report.md``: the overview table ranked by drift, the alarms, the temperature laws.
"""

from __future__ import annotations

import csv
import json
import math
from pathlib import Path

import numpy as np

from friction_ros.core.fleet.trend import JointTrend, TrendOptions, alarms


def write_report(trends: list[JointTrend], out, options: TrendOptions) -> dict[str, Path]:
    """Write every file into folder ``out`` (created); returns name -> path."""
    out = Path(out)
    (out / "plots").mkdir(parents=True, exist_ok=True)
    found = alarms(trends)
    designs = sorted(
        {
            c.detection.design.baseline_runs: c.detection.design.to_dict()
            for jt in trends
            for c in jt.coefficients
        }.items()
    )
    doc = {
        "reference_temperature_degC": options.t_ref,
        "baseline_days": options.baseline_days,
        "designs": [d for _, d in designs],
        "alarms": found,
    }
    files = {"alarms": out / "alarms.json", "trends": out / "trends.csv", "report": out / "report.md"}
    files["alarms"].write_text(json.dumps(doc, indent=2) + "\n")
    _write_csv(trends, files["trends"])
    ranked = sorted(trends, key=lambda jt: -_finite(jt.drift(options.recent_days)[0]))
    files["overview"] = _plot_overview(ranked, out / "plots" / "overview.png", options)
    for robot in sorted({jt.robot for jt in trends}):
        files[f"plot_{robot}"] = _plot_robot([jt for jt in trends if jt.robot == robot], out / "plots", robot)
    files["report"].write_text(_markdown(ranked, found, options))
    return files


def _finite(x: float) -> float:
    return x if math.isfinite(x) else -math.inf


def _write_csv(trends: list[JointTrend], path: Path) -> None:
    head = [
        "robot",
        "joint",
        "model",
        "coefficient",
        "run_time",
        "value",
        "stderr",
        "temperature_degC",
        "normalised",
        "normalised_stderr",
        "change_percent",
        "z",
        "statistic",
        "baseline",
    ]
    with path.open("w", newline="") as f:
        w = csv.writer(f)
        w.writerow(head)
        for jt in trends:
            for c in jt.coefficients:
                pct = c.change_percent
                for i, t in enumerate(c.time):
                    w.writerow(
                        [
                            jt.robot,
                            jt.joint,
                            jt.model,
                            c.name,
                            t.isoformat(),
                            f"{c.values[i]:.9g}",
                            f"{c.stderr[i]:.6g}",
                            f"{c.temperature[i]:.4g}",
                            f"{c.normalised[i]:.9g}",
                            f"{c.normalised_se[i]:.6g}",
                            f"{pct[i]:.4g}",
                            f"{c.detection.z[i]:.4g}",
                            f"{c.detection.statistic[i]:.4g}",
                            int(c.baseline[i]),
                        ]
                    )


def _markdown(ranked: list[JointTrend], found: list[dict], options: TrendOptions) -> str:
    lines = [
        "# Fleet friction trends",
        "",
        f"{len(ranked)} joint(s) of {len({jt.robot for jt in ranked})} robot(s); coefficients normalised to "
        f"{options.t_ref:g} degC; baseline: each joint's first {options.baseline_days} days; wear alarm: upper "
        f"CUSUM with k = 1 baseline sigma, h for {options.arl0:.3g} in-control runs between false alarms.",
        "",
        f"## Alarms ({len(found)})",
        "",
    ]
    if found:
        lines += [
            "| date | robot | joint | coefficient | size [%] | change start | statistic / threshold |",
            "|---|---|---|---|---|---|---|",
        ]
        lines += [
            f"| {a['date']} | {a['robot']} | {a['joint']} | {a['coefficient']} | {a['size_percent']:+.1f} | "
            f"{a['change_start']} | {a['statistic']:.1f} / {a['threshold']:.1f} |"
            for a in found
        ]
    else:
        lines.append("No wear alarm.")
    lines += [
        "",
        f"## Joints ranked by drift (last {options.recent_days} days vs baseline)",
        "",
        "![overview](plots/overview.png)",
        "",
        "| robot | joint | model | runs | coefficient | change [%] | drift [sigma] | CUSUM / h | law: per K at T_ref | notes |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for jt in ranked:
        for c in jt.coefficients:
            pct, z = c.recent(options.recent_days)
            d = c.detection
            law = c.law
            slope = f"{100 * law.slope_per_k:+.2f} %/K" if math.isfinite(law.slope_per_k) else "-"
            stat = f"{d.statistic[-1]:.1f} / {d.design.h:.1f}"
            lines.append(
                f"| {jt.robot} | {jt.joint} | {jt.model} | {jt.runs} | {c.name} | {pct:+.2f} | {z:+.2f} | "
                f"{stat} | {slope} | {'; '.join(jt.notes)} |"
            )
        if not jt.coefficients:
            lines.append(
                f"| {jt.robot} | {jt.joint} | {jt.model} | {jt.runs} | - | - | - | - | - | {'; '.join(jt.notes)} |"
            )
    lines += ["", "## Per robot", ""]
    lines += [f"![{r}](plots/{r}.png)" for r in sorted({jt.robot for jt in ranked})]
    return "\n".join(lines) + "\n"


def _plot_overview(ranked: list[JointTrend], path: Path, options: TrendOptions) -> Path:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = [
        (f"{jt.robot}/{jt.joint} {d[1]}", d[0], any(c.detection.alarm is not None for c in jt.coefficients))
        for jt in ranked
        for d in [jt.drift(options.recent_days)]
        if math.isfinite(d[0])
    ]
    fig, ax = plt.subplots(figsize=(7, max(2.5, 0.16 * len(rows) + 1)))
    y = np.arange(len(rows))[::-1]
    ax.barh(y, [r[1] for r in rows], color=["tab:red" if r[2] else "tab:blue" for r in rows])
    ax.set_yticks(y, [r[0] for r in rows], fontsize=5 if len(rows) > 40 else 7)
    ax.axvline(0, color="k", lw=0.5)
    ax.set_xlabel(f"mean change over the last {options.recent_days} days [baseline sigmas] (red: wear alarm)")
    ax.set_title("Fleet friction drift, temperature-normalised")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def _plot_robot(trends: list[JointTrend], folder: Path, robot: str) -> Path:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from friction_ros.core.plotting import legend_outside

    n = len(trends)
    fig, axes = plt.subplots(n, 1, figsize=(8, 1.9 * n + 0.6), sharex=True, squeeze=False)
    for ax, jt in zip(axes[:, 0], trends, strict=True):
        for k, c in enumerate(jt.coefficients):
            color = f"C{k}"
            mu = c.detection.mu0
            if not math.isfinite(mu) or mu == 0:
                continue
            days = np.array([(t - c.time[0]).total_seconds() / 86400 for t in c.time])
            ax.plot(days, 100 * (c.values / mu - 1), ".", color=color, alpha=0.15, ms=2)
            ax.errorbar(
                days,
                c.change_percent,
                yerr=100 * c.normalised_se / abs(mu),
                fmt=".",
                color=color,
                ms=3,
                elinewidth=0.5,
                alpha=0.8,
                label=f"{c.name} ({c.law.form} law)",
            )
            if c.detection.alarm is not None:
                ax.axvline(days[c.detection.alarm], color=color, ls="--", lw=1)
        if jt.coefficients and jt.coefficients[0].baseline.any():
            c = jt.coefficients[0]
            end = (c.time[int(np.nonzero(c.baseline)[0][-1])] - c.time[0]).total_seconds() / 86400
            ax.axvspan(0, end, color="0.9", zorder=0)
        ax.axhline(0, color="k", lw=0.5)
        ax.set_ylabel(f"{jt.joint}\nchange [%]", fontsize=8)
        if jt.coefficients:
            legend_outside(ax, fontsize=7)
    axes[-1, 0].set_xlabel(
        "days since first run (grey: baseline; faint: raw, not normalised; dashed: wear alarm)"
    )
    fig.suptitle(f"{robot}: friction coefficients normalised to the reference temperature vs baseline")
    fig.tight_layout()
    path = folder / f"{robot}.png"
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path
