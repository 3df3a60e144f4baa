"""The fit report's PNG plots: friction-velocity map, presliding hysteresis, time-domain validation,
residuals (``<out>/plots/*.png``).

Legends sit beside the axes, y limits come from the data without their outliers
(:func:`~friction_ros.core.plotting.robust_limits`) and a trace against time is broken where the
records or training segments it concatenates have a gap (:func:`~friction_ros.core.plotting.break_at_gaps`).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from friction_ros.core.identification.data.records import concat_records
from friction_ros.core.identification.fit.fit_units import fit_joint_type, units
from friction_ros.core.plotting import break_at_gaps, legend_outside, set_robust_ylim


def _save(fig, path: Path) -> None:
    import matplotlib.pyplot as plt

    fig.tight_layout()
    fig.savefig(path, dpi=110, bbox_inches="tight")
    plt.close(fig)


def friction_map_figure(res, tr, names, u):
    """Samples ``tau - J a`` of the training data, plateau means and each model's steady-state map."""
    import matplotlib.pyplot as plt

    J = res.inertia
    fig, ax = plt.subplots(figsize=(8, 5))
    step = max(tr.n // 4000, 1)
    samples = (tr.torque - J * tr.acceleration)[::step]
    ax.plot(tr.velocity[::step], samples, ".", ms=1.5, color="0.7", label="samples (tau - J a)")
    curves = [samples]
    if res.plateaus:
        means = [p.torque for p in res.plateaus]
        ax.errorbar(
            [p.velocity for p in res.plateaus],
            means,
            yerr=[p.torque_std for p in res.plateaus],
            fmt="ko",
            ms=4,
            label="plateau means",
        )
        curves.append(np.asarray(means))
    g = None
    for n in names:
        g = res.models[n].extra.get("steady_state_grid")
        if g:
            ax.plot(g["velocity"], g["friction"], label=n)
            curves.append(np.asarray(g["friction"]))
    ax.set_xscale("symlog", linthresh=max(1e-3, float(np.min(np.abs(g["velocity"]))) if g else 1e-3))
    set_robust_ylim(ax, *curves)
    ax.set_xlabel(f"velocity [{u['velocity']}]")
    ax.set_ylabel(f"friction [{u['friction']}]")
    ax.set_title("Steady-state friction-velocity map")
    ax.grid(True, alpha=0.3)
    legend_outside(ax)
    return fig


def presliding_figure(res, va, preds, names, low_idx, u):
    """Friction against position in a 2 s low-velocity window of the validation data."""
    import matplotlib.pyplot as plt

    J = res.inertia
    fig, ax = plt.subplots(figsize=(7, 5))
    if low_idx.size > 10:
        i0 = int(low_idx[low_idx.size // 2])
        sl = slice(max(i0 - int(1.0 / va.dt), 0), min(i0 + int(1.0 / va.dt), va.n))
        x = va.position[sl] - va.position[sl].mean()
        measured = (va.torque - J * va.acceleration)[sl]
        ax.plot(x * 1e3, measured, "k.", ms=2, label="measured")
        curves = [measured]
        for n in names:
            jm = res.models[n].coefficients.get("J", 0.0)
            y = (preds[n] - jm * va.acceleration)[sl]
            _, xs, ys = break_at_gaps(va.t[sl], x * 1e3, y)
            ax.plot(xs, ys, lw=1, label=n)
            curves.append(y)
        set_robust_ylim(ax, *curves)
    ax.set_xlabel(f"position - mean [m{u['position']}]")
    ax.set_ylabel(f"friction [{u['friction']}]")
    ax.set_title("Presliding hysteresis (2 s low-velocity window, validation)")
    ax.grid(True, alpha=0.3)
    legend_outside(ax)
    return fig


def validation_figure(va, preds, names, high_idx, low_idx, effort):
    """Measured and predicted torque in a 1 s window at high and at low velocity."""
    import matplotlib.pyplot as plt

    fig, axs = plt.subplots(2, 1, figsize=(9, 6))
    for ax, idx, title in ((axs[0], high_idx, "high velocity"), (axs[1], low_idx, "low velocity")):
        if idx.size > 10:
            i0 = int(idx[idx.size // 2])
            sl = slice(max(i0 - int(0.5 / va.dt), 0), min(i0 + int(0.5 / va.dt), va.n))
            t, y = break_at_gaps(va.t[sl], va.torque[sl])
            ax.plot(t, y, "k", lw=1.5, label="measured")
            for n in names:
                ax.plot(*break_at_gaps(va.t[sl], preds[n][sl]), lw=0.8, label=n)
            set_robust_ylim(ax, va.torque[sl], *(preds[n][sl] for n in names))
        ax.set_title(f"validation, {title}")
        ax.set_ylabel(effort)
        ax.grid(True, alpha=0.3)
    axs[1].set_xlabel("time [s]")
    legend_outside(axs[0], fontsize=7)
    return fig


def residuals_figure(va, preds, names, u):
    """Prediction minus measurement over the validation data, and its histogram."""
    import matplotlib.pyplot as plt

    fig, axs = plt.subplots(1, 2, figsize=(10, 4))
    errors = []
    for n in names:
        e = preds[n] - va.torque
        errors.append(e)
        axs[0].plot(*break_at_gaps(va.t, e), lw=0.5, label=n)
        axs[1].hist(e[np.isfinite(e)], bins=80, histtype="step", label=n)
    set_robust_ylim(axs[0], *errors)
    axs[0].set_xlabel("time [s]")
    axs[0].set_ylabel(f"residual [{u['friction']}]")
    axs[1].set_xlabel(f"residual [{u['friction']}]")
    for a in axs:
        a.grid(True, alpha=0.3)
    legend_outside(axs[1], fontsize=7)
    return fig


def make_plots(res, out: Path) -> dict:
    """Write the four plots of a FitResult into ``out``; returns {title: path relative to the report}."""
    import matplotlib

    matplotlib.use("Agg")

    from friction_ros.core.identification.data.velocity_regimes import velocity_envelope

    out.mkdir(parents=True, exist_ok=True)
    names = [n for n, m in res.models.items() if m.status == "fitted"]  # no curve of a failed model
    tr = concat_records(res.train)
    va = concat_records(res.validation)
    u = units(fit_joint_type(res))
    effort = f"{'torque' if u['friction'] == 'N*m' else 'force'} [{u['friction']}]"
    preds = {n: res.models[n].extra["validation_prediction"] for n in names}
    env = velocity_envelope(va.velocity, va.dt)
    low_idx = np.nonzero(env <= res.high_threshold)[0]
    high_idx = np.nonzero(env > res.high_threshold)[0]
    figures = {
        "Friction-velocity map": ("friction_velocity.png", friction_map_figure(res, tr, names, u)),
        "Presliding hysteresis": ("presliding.png", presliding_figure(res, va, preds, names, low_idx, u)),
        "Time-domain validation": (
            "validation.png",
            validation_figure(va, preds, names, high_idx, low_idx, effort),
        ),
        "Residuals": ("residuals.png", residuals_figure(va, preds, names, u)),
    }
    files = {}
    for title, (name, fig) in figures.items():
        _save(fig, out / name)
        files[title] = f"plots/{name}"
    return files
