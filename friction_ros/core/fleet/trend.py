"""Per-joint coefficient trends of a fleet table: series, temperature normalisation, wear alarms.

For every (robot, joint) of the table (:data:`~.table.FLEET_SCHEMA`), the runs fitted without error
of the model friction-fit recommended most often for that joint give one series per tracked
coefficient (default :data:`WEAR_COEFFICIENTS`). The joint's baseline is the runs of its first
``baseline_days`` days (from its first run); on it the temperature/load law of each coefficient is
fitted (:mod:`.temperature_law`), every run is normalised to ``t_ref`` with its uncertainty, and the
upper CUSUM of :mod:`.drift` raises the wear alarm. Drift for ranking the fleet: the mean change of
the normalised coefficient over the last ``recent_days`` days vs the baseline, in baseline sigmas.
"""

from __future__ import annotations

import datetime as dt
import math
from collections import Counter
from dataclasses import dataclass, field

import numpy as np

from friction_ros.core.fleet.drift import DEFAULT_ARL0, Detection, detect
from friction_ros.core.fleet.temperature_law import TemperatureLaw, fit_law
from friction_ros.core.validation import ParameterError

#: the coefficients that wear changes (friction levels and viscous friction)
WEAR_COEFFICIENTS = ("fc", "fs", "fv")
#: columns the trend reads
REQUIRED = (
    "robot",
    "joint",
    "run_time",
    "model",
    "recommended",
    "coef_names",
    "coef_values",
    "coef_stderr",
    "joint_type",
    "error",
    "temperature_mean",
    "load_rms",
)


@dataclass
class TrendOptions:
    """What the trend analysis needs beyond the table."""

    baseline_days: int = 14
    t_ref: float = 25.0  # [degC]
    arl0: float = DEFAULT_ARL0
    coefficients: tuple[str, ...] = WEAR_COEFFICIENTS
    recent_days: int = 7


@dataclass
class CoefficientTrend:
    """One coefficient of one joint over time: raw, normalised (with stderr), law, detection."""

    name: str
    day: np.ndarray  # whole days since the joint's first run
    time: list  # run start datetimes (UTC)
    values: np.ndarray
    stderr: np.ndarray
    temperature: np.ndarray
    normalised: np.ndarray
    normalised_se: np.ndarray
    baseline: np.ndarray  # bool per run
    law: TemperatureLaw
    detection: Detection

    @property
    def alarm_time(self) -> dt.datetime | None:
        a = self.detection.alarm
        return None if a is None else self.time[a]

    @property
    def change_percent(self) -> np.ndarray:
        """100 (c_n / mu_0 - 1) per run [%]."""
        return 100.0 * (self.normalised / self.detection.mu0 - 1.0)

    def recent(self, days: int) -> tuple[float, float]:
        """(mean change [%], mean change [baseline sigmas, not clipped]) over the last ``days`` days."""
        sel = (self.day > self.day.max() - days) & np.isfinite(self.normalised)
        if not sel.any() or not math.isfinite(self.detection.mu0):
            return math.nan, math.nan
        d = self.detection
        return float(np.mean(self.change_percent[sel])), float(
            (np.mean(self.normalised[sel]) - d.mu0) / d.sigma0
        )


@dataclass
class JointTrend:
    """The trends of one joint of one robot."""

    robot: str
    joint: str
    model: str
    joint_type: str
    runs: int
    coefficients: list[CoefficientTrend] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)

    def drift(self, days: int) -> tuple[float, str, float]:
        """(largest recent z, its coefficient, its recent change [%]) for ranking the fleet."""
        best = (-math.inf, "", math.nan)
        for c in self.coefficients:
            pct, z = c.recent(days)
            if math.isfinite(z) and z > best[0]:
                best = (z, c.name, pct)
        return best


def check_columns(names) -> None:
    """ParameterError naming the missing columns when ``names`` lacks one of :data:`REQUIRED`."""
    missing = [c for c in REQUIRED if c not in names]
    if missing:
        raise ParameterError(
            f"the table lacks column(s) {', '.join(missing)}: a fleet table (friction-fleet fit --table) has "
            + ", ".join(REQUIRED)
        )


def analyse(table, options: TrendOptions | None = None) -> list[JointTrend]:
    """The trends of every joint of ``table`` (a pyarrow Table with :data:`REQUIRED` columns)."""
    options = options or TrendOptions()
    check_columns(table.column_names)
    cols = {c: table.column(c).to_pylist() for c in REQUIRED}
    groups: dict[tuple[str, str], list[int]] = {}
    for i, (robot, joint, err) in enumerate(zip(cols["robot"], cols["joint"], cols["error"], strict=True)):
        if not err:
            groups.setdefault((robot, joint), []).append(i)
    if not groups:
        raise ParameterError(
            "the table has no fitted run (every row is empty or has an error): nothing to trend"
        )
    return [_joint_trend(key, rows, cols, options) for key, rows in sorted(groups.items())]


def _joint_trend(key, rows: list[int], cols: dict, options: TrendOptions) -> JointTrend:
    votes = Counter(cols["model"][i] for i in rows if cols["recommended"][i])
    model = (
        votes.most_common(1)[0][0] if votes else Counter(cols["model"][i] for i in rows).most_common(1)[0][0]
    )
    rows = sorted((i for i in rows if cols["model"][i] == model), key=lambda i: cols["run_time"][i])
    jt = JointTrend(key[0], key[1], model, cols["joint_type"][rows[0]] or "revolute", len(rows))
    times = [cols["run_time"][i] for i in rows]
    first = times[0]
    day = np.array([(t - first).total_seconds() // 86400 for t in times], dtype=int)
    baseline = day < options.baseline_days
    temp = np.array([_num(cols["temperature_mean"][i]) for i in rows])
    load = np.array([_num(cols["load_rms"][i]) for i in rows])
    names_in = {n for i in rows for n in (cols["coef_names"][i] or [])}
    for name in [c for c in options.coefficients if c in names_in]:
        values = np.array([_coef(cols, i, name, "coef_values") for i in rows])
        stderr = np.array([_coef(cols, i, name, "coef_stderr") for i in rows])
        law = fit_law(name, values[baseline], temp[baseline], load[baseline], t_ref=options.t_ref)
        cn, se_n = law.normalise(values, stderr, temp, load)
        det = detect(day, cn, se_n, baseline, arl0=options.arl0)
        jt.notes += [f"{name}: {n}" for n in det.notes]
        jt.coefficients.append(
            CoefficientTrend(name, day, times, values, stderr, temp, cn, se_n, baseline, law, det)
        )
    if not jt.coefficients:
        jt.notes.append(
            f"model {model} has none of the tracked coefficients ({', '.join(options.coefficients)})"
        )
    if day.max() < options.baseline_days:
        jt.notes.append(f"runs span {day.max() + 1} day(s), within the {options.baseline_days}-day baseline")
    return jt


def _num(x) -> float:
    return math.nan if x is None else float(x)


def _coef(cols: dict, i: int, name: str, column: str) -> float:
    names = cols["coef_names"][i] or []
    vals = cols[column][i] or []
    if name not in names:
        return math.nan
    k = names.index(name)
    return _num(vals[k]) if k < len(vals) else math.nan


def alarms(trends: list[JointTrend]) -> list[dict]:
    """Every alarm as a dict: robot, joint, coefficient, model, date, change start, size [%],
    statistic and threshold [baseline sigmas], in date order."""
    out = []
    for jt in trends:
        for c in jt.coefficients:
            d = c.detection
            if d.alarm is None:
                continue
            out.append(
                {
                    "robot": jt.robot,
                    "joint": jt.joint,
                    "coefficient": c.name,
                    "model": jt.model,
                    "date": c.time[d.alarm].date().isoformat(),
                    "time": c.time[d.alarm].isoformat(),
                    "change_start": c.time[d.start].date().isoformat(),
                    "size_percent": round(d.size_percent, 3),
                    "statistic": round(float(d.statistic[d.alarm]), 3),
                    "threshold": round(d.design.h, 3),
                    "baseline": d.mu0,
                    "baseline_sigma": d.sigma0,
                }
            )
    return sorted(out, key=lambda a: (a["time"], a["robot"], a["joint"], a["coefficient"]))
