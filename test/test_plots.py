"""Plots of the fit report and the demo: a legend beside the axes (covering no trace), y limits that
one outlier does not stretch, no line across a gap between records or training segments."""

from __future__ import annotations

from pathlib import Path

import matplotlib
import numpy as np
import pytest

from friction_ros.core.plotting import break_at_gaps, robust_limits

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
PENDULUM = ROOT / "test" / "data" / "dfki_pendulum" / "control_method_pd_system_identification.csv"


def test_break_at_gaps_inserts_nan_at_jumps_and_restarts():
    t = np.array([0.0, 0.1, 0.2, 0.3, 5.0, 5.1, 5.2, 0.0, 0.1])
    y = np.arange(t.size, dtype=float)
    tb, yb = break_at_gaps(t, y)
    assert tb.size == t.size + 2
    assert np.flatnonzero(np.isnan(tb)).tolist() == [4, 8]  # before 5.0 and before the restart at 0
    assert np.array_equal(np.isnan(tb), np.isnan(yb))
    np.testing.assert_array_equal(yb[~np.isnan(yb)], y)
    even = np.arange(0.0, 1.0, 0.01)
    assert break_at_gaps(even, even)[0].size == even.size  # no gap: unchanged


def test_robust_limits_ignore_one_outlier_and_keep_clean_data_whole():
    rng = np.random.default_rng(1)
    y = rng.normal(0.0, 1.0, 2000)
    lo, hi = robust_limits(y)
    assert lo <= y.min() and hi >= y.max()  # nothing clipped without outliers
    assert hi - lo < 1.2 * (y.max() - y.min())
    spiked = np.append(y, 1e3)
    lo2, hi2 = robust_limits(spiked)
    assert hi2 < 10.0 and lo2 <= y.min()  # the spike is left out, the clean data still shown whole
    assert robust_limits(np.array([np.nan, np.inf])) is None
    assert robust_limits(np.full(10, 2.0)) == pytest.approx((1.9, 2.1))


def _legend_beside(ax) -> bool:
    ax.figure.canvas.draw()
    leg = ax.get_legend().get_window_extent()
    return leg.x0 >= ax.get_window_extent().x1


def _has_nan_gap(line) -> bool:
    return bool(np.isnan(np.asarray(line.get_ydata(), dtype=float)).any())


def test_demo_tracking_plot(tmp_path):
    from friction_ros.cli.demo_report import plot_tracking, tracking_figure
    from friction_ros.cli.demo_results import DemoResult, TrackingRun

    t = np.concatenate([np.arange(0.0, 2.0, 0.005), np.arange(3.0, 5.0, 0.005)])  # a 1 s gap
    ref = np.sin(t)

    def run(label, scale, spike=0.0):
        err = scale * np.sin(7 * t)
        err[len(t) // 3] += spike
        z = np.zeros_like(t)
        return TrackingRun(label, t, ref, z, ref - err, z, err, z, z, 1.0)

    res = DemoResult(
        preset="p", runs={"none": run("none", 1e-3, spike=1.0), "feedforward": run("feedforward", 5e-4)}
    )
    fig = tracking_figure(res)
    ax_pos, ax_err = fig.axes
    assert ax_err.get_ylim()[1] < 5.0  # mrad: the 1000 mrad spike does not set the scale
    assert ax_err.get_ylim()[1] > 1.0  # the 1 mrad error is shown whole
    assert all(_has_nan_gap(line) for line in ax_err.get_lines())
    assert _legend_beside(ax_pos) and _legend_beside(ax_err)
    plt.close(fig)
    plot_tracking(res, tmp_path / "tracking.png")
    assert (tmp_path / "tracking.png").stat().st_size > 10_000


@pytest.fixture(scope="module")
def pendulum_fit():
    """A real fit of the DFKI pendulum log: training and validation windows with a gap between."""
    from friction_ros.core.identification.data.csv_loading import load_csv
    from friction_ros.core.identification.fit.pipeline import fit_records

    rec = load_csv(PENDULUM)
    return fit_records(
        [rec], ["coulomb_viscous"], identifiability_check=False, train_seconds=1.5, load="none"
    )


def test_report_plots(pendulum_fit, tmp_path):
    from friction_ros.core.identification.data.records import concat_records
    from friction_ros.core.identification.fit.fit_units import units
    from friction_ros.core.identification.report.report_plots import make_plots, residuals_figure

    res = pendulum_fit
    va = concat_records(res.validation)
    assert np.max(np.diff(va.t)) > 10 * va.dt  # the validation data has a gap (the training window)
    names = [n for n, m in res.models.items() if m.status == "fitted"]
    preds = {n: res.models[n].extra["validation_prediction"].copy() for n in names}
    preds[names[0]][va.n // 2] += 1e4  # one wild sample
    fig = residuals_figure(va, preds, names, units("revolute"))
    ax = fig.axes[0]
    assert ax.get_ylim()[1] < 100.0
    assert all(_has_nan_gap(line) for line in ax.get_lines())
    assert _legend_beside(fig.axes[1])
    plt.close(fig)
    files = make_plots(res, tmp_path / "plots")
    assert sorted(files.values()) == [
        "plots/friction_velocity.png",
        "plots/presliding.png",
        "plots/residuals.png",
        "plots/validation.png",
    ]
    for f in files.values():
        assert (tmp_path / f).stat().st_size > 10_000
