"""Plot helpers shared by the fit report and the demo: axis limits one outlier cannot stretch, no
line drawn across a gap between records or training segments, legends beside the traces.

Numbers only (numpy); :func:`legend_outside` takes a matplotlib axes but imports no matplotlib.
"""

from __future__ import annotations

import numpy as np

#: a time step larger than this many median steps (or a step backwards) is a gap
GAP_STEPS = 3.0


def break_at_gaps(t: np.ndarray, *ys: np.ndarray, gap_steps: float = GAP_STEPS) -> tuple[np.ndarray, ...]:
    """``t`` and each ``y`` with a NaN sample inserted at every gap of ``t`` (matplotlib breaks a
    line at NaN). A gap is a step of ``t`` larger than ``gap_steps`` x its median step, or a step
    backwards (records concatenated back to back, each with its own time)."""
    t = np.asarray(t, dtype=float)
    ys = tuple(np.asarray(y, dtype=float) for y in ys)
    if t.size < 3:
        return (t, *ys)
    dt = np.diff(t)
    positive = dt[dt > 0]
    if positive.size == 0:
        return (t, *ys)
    step = float(np.median(positive))
    cut = np.nonzero((dt > gap_steps * step) | (dt <= 0))[0] + 1
    if cut.size == 0:
        return (t, *ys)
    return tuple(np.insert(a, cut, np.nan) for a in (t, *ys))


def robust_limits(
    *arrays: np.ndarray, pct: float = 0.5, reach: float = 0.5, pad: float = 0.05
) -> tuple[float, float] | None:
    """Axis limits of the finite values of ``arrays`` that a few outliers do not stretch.

    With ``p_lo``/``p_hi`` the ``pct`` and ``100 - pct`` percentiles and ``r = p_hi - p_lo``, the
    limits are ``[max(min, p_lo - reach r), min(max, p_hi + reach r)]`` widened by ``pad`` of their
    span: data without outliers is shown whole, a value further than ``reach`` x the central range
    from it is left outside. None when there is no finite value.
    """
    vals = [np.asarray(a, dtype=float).ravel() for a in arrays]
    v = np.concatenate(vals) if vals else np.zeros(0)
    v = v[np.isfinite(v)]
    if v.size == 0:
        return None
    p_lo, p_hi = np.percentile(v, [pct, 100.0 - pct])
    r = p_hi - p_lo
    lo = max(float(v.min()), p_lo - reach * r)
    hi = min(float(v.max()), p_hi + reach * r)
    span = hi - lo
    if span <= 0:
        span = abs(hi) if hi != 0 else 1.0
    return lo - pad * span, hi + pad * span


def set_robust_ylim(ax, *arrays: np.ndarray, **kw) -> None:
    """``ax.set_ylim`` to :func:`robust_limits` of ``arrays`` (unchanged when they hold no value)."""
    lim = robust_limits(*arrays, **kw)
    if lim is not None:
        ax.set_ylim(*lim)


def legend_outside(ax, fontsize: float = 8, **kw) -> None:
    """The legend to the right of the axes, where it covers no trace (save with ``bbox_inches="tight"``).

    ``loc="best"`` would scan every plotted sample (seconds for long records) and still covers
    traces when they fill the axes."""
    if ax.get_legend_handles_labels()[0]:
        ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), borderaxespad=0.0, fontsize=fontsize, **kw)
