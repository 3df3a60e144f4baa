"""Why a fit explains little: what the validation residual of the recommended model follows.

A model with a validation NMSE above 30 % should not be deployed silently. The residual
``e = tau - tau_hat`` is regressed, one candidate group at a time, on the columns of what the model
lacks; the share of its variance a group explains (R^2 of a least-squares fit with an intercept)
names the missing structure:

* ``gravity``: sin q, cos q (a gravity load, m g l sin(q + q0));
* ``offset``: a constant (a torque-sensor or current offset, a constant load);
* ``spring``: q (cables, a spring);
* ``load-dependent friction``: abs(tau) sgn(v) (friction growing with the transmitted torque);
* ``position-dependent friction``: sgn(v) cos(k q), sgn(v) sin(k q), k = 1..4 (gear ripple);
* ``history``: the velocity low-passed at 20 ms and 200 ms and the direction of the last motion
  (hysteresis, presliding, effects a static map cannot capture: a dynamic model or a learned
  residual).

Data problems are named too: torque saturation (many samples at the extreme value), too few
velocity reversals or a narrow speed range (more excitation needed).
"""

from __future__ import annotations

import numpy as np
from scipy.signal import lfilter

#: a candidate group explaining at least this share of the residual variance is named
MIN_SHARE = 0.1


def _history(v: np.ndarray, dt: float) -> np.ndarray:
    cols = []
    for tau in (0.02, 0.2):
        a = dt / (tau + dt)
        cols.append(lfilter([a], [1.0, a - 1.0], v))
    last = np.sign(v)
    nz = last != 0
    idx = np.where(nz, np.arange(v.size), 0)
    np.maximum.accumulate(idx, out=idx)
    cols.append(last[idx])
    return np.column_stack(cols)


def _groups(records, eps: float) -> dict[str, np.ndarray]:
    q = np.concatenate([r.position for r in records])
    v = np.concatenate([r.velocity for r in records])
    tau = np.concatenate([r.torque for r in records])
    sg = np.clip(v / eps, -1.0, 1.0)
    hist = np.vstack([_history(r.velocity, r.dt) for r in records])
    return {
        "gravity": np.column_stack([np.sin(q), np.cos(q)]),
        "offset": np.ones((q.size, 1)),
        "spring": q[:, None],
        "load-dependent friction": (np.abs(tau) * sg)[:, None],
        "position-dependent friction": np.column_stack(
            [sg * f(k * q) for k in range(1, 5) for f in (np.cos, np.sin)]
        ),
        "history": hist,
    }


def explained_shares(records, residual: np.ndarray, eps: float = 1e-3) -> dict[str, float]:
    """Share of the residual's variance [0, 1] each candidate group explains (module docstring)."""
    e = np.asarray(residual, dtype=float)
    var = float(np.var(e))
    out: dict[str, float] = {}
    if e.size < 10 or not var > 0:
        return out
    for name, X in _groups(records, eps).items():
        A = np.column_stack([np.ones(e.size), X])
        coef, *_ = np.linalg.lstsq(A, e, rcond=None)
        out[name] = float(max(0.0, 1.0 - np.var(e - A @ coef) / var))
    # the intercept alone is the offset: its share is the mean's part of the mean square
    out["offset"] = float(np.mean(e) ** 2 / np.mean(e**2)) if np.mean(e**2) > 0 else 0.0
    return out


def data_problems(records) -> list[str]:
    """Problems of the data themselves: torque saturation, little excitation."""
    out = []
    tau = np.concatenate([r.torque for r in records])
    v = np.concatenate([r.velocity for r in records])
    if tau.size:
        for side, x in (("upper", tau.max()), ("lower", tau.min())):
            at = float(np.mean(np.abs(tau - x) <= 1e-9 * max(1.0, abs(x))))
            if at > 0.01 and abs(x) > 0:
                out.append(
                    f"{100 * at:.1f} % of the torque samples sit at the {side} extreme {x:.4g} N*m: the torque "
                    "saturated or was clipped (a sensor or drive limit); those samples are not friction"
                )
    rev = sum(int(np.sum(np.diff(np.sign(r.velocity[np.abs(r.velocity) > 1e-9])) != 0)) for r in records)
    if rev < 4:
        out.append(f"only {rev} velocity reversals: more excitation (motion in both directions) is needed")
    if v.size and np.percentile(np.abs(v), 95) < 1e-3:
        out.append(
            "the joint hardly moves (95th percentile speed below 1e-3 rad/s): more excitation is needed"
        )
    return out


def suggestions(records, residual, used=frozenset(), eps: float = 1e-3) -> list[str]:
    """One line per likely cause, greedily: the group explaining most of the residual first, the
    next one on what it leaves, and so on while a group explains >= MIN_SHARE (``used`` = groups
    the model already has). Then the data problems."""
    e = np.asarray(residual, dtype=float).copy()
    groups = {k: X for k, X in _groups(records, eps).items() if k not in used}
    total = float(np.mean(e**2))
    lines = []
    while groups and total > 0 and e.size >= 10:
        var = float(np.mean(e**2))
        best = None
        for name, X in groups.items():
            A = X if name == "offset" else np.column_stack([np.ones(e.size), X])
            coef, *_ = np.linalg.lstsq(A, e, rcond=None)
            rest = e - A @ coef
            share = 1.0 - float(np.mean(rest**2)) / var
            if best is None or share > best[1]:
                best = (name, share, rest)
        name, share, rest = best
        if share < MIN_SHARE:
            break
        lines.append(
            f"{name} explains {100 * share:.0f} % of the {'residual' if not lines else 'rest'}: {_HINTS[name]}"
        )
        e = rest
        del groups[name]
    return lines + data_problems(records)


_HINTS = {
    "gravity": "fit with a gravity term (--load gravity or --load auto)",
    "offset": "fit with an offset (--load offset), or zero the torque sensor",
    "spring": "fit with a spring term (--load spring)",
    "load-dependent friction": "fit with load-dependent friction (--load load_friction)",
    "position-dependent friction": "fit with position-dependent friction (--load ripple=4)",
    "history": "a dynamic model (lugre, gms4) or a learned residual (--residual auto)",
}
