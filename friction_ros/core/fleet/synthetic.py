"""A synthetic fleet with known truth: robots of 7 joints identified several times a day for D days,
gearbox temperature following a daily cycle, some joints wearing from a known day.

Per joint (a linear track in N and six revolute joints in N*m, scales from 0.8 N*m to 40 N), the
true coefficients of run r on day d at temperature T (laws of :mod:`.temperature_law`, T_ref = 25 degC):

    fc(d, T) = fc_0 (1 + a_c (T - T_ref)) (1 + w (d - d_0)_+ / 100),   a_c ~ -0.004 /K
    fv(T)    = fv_0 exp(-k_v (T - T_ref)),                               k_v ~ 0.02 /K

w = 1 %/day from wear start d_0 on the worn joints (0 on the others). The temperature of a run at
hour t of day d is T = T_d + 12 sin(2 pi (t - 9 h) / 24 h) + T_j + e, with T_d ~ N(30, 2) the
cell's day, T_j ~ N(0, 2) the joint's own heating, e ~ N(0, 0.7) degC: about 15-45 degC.

:func:`table_rows` draws fleet-table rows directly (coefficients = truth x (1 + noise), relative
run-to-run noise :data:`NOISE` as friction-fit's scatter on a 10 s run), so trends and alarms can be
tested and benchmarked over months without running fits; ``bench/_fleet_synth.py`` writes the same
plan as CSV logs for ``friction-fleet fit``. Everything is seeded.
"""

from __future__ import annotations

import datetime as dt
import hashlib
import math
from dataclasses import dataclass, field

import numpy as np

T_REF = 25.0  # [degC]
#: relative run-to-run noise of fitted coefficients (table-level generator)
NOISE = {"fc": 0.008, "fv": 0.015, "J": 0.01}
START = dt.datetime(2026, 1, 5, tzinfo=dt.UTC)


@dataclass(frozen=True)
class JointSpec:
    """A joint's nominal friction at T_ref (joint units), inertia, excitation and temperature law."""

    name: str
    joint_type: str
    fc: float  # [N*m | N]
    fv: float  # [N*m*s/rad | N*s/m]
    inertia: float  # [kg*m^2 | kg]
    stroke: float  # excitation range [rad | m]
    vmax: float  # peak speed [rad/s | m/s]
    a_c: float = -0.004  # [1/K]
    k_v: float = 0.02  # [1/K]

    @property
    def effort_unit(self) -> str:
        return "N" if self.joint_type == "prismatic" else "N*m"


#: a 6-axis arm on a linear track
ARM = (
    JointSpec("track", "prismatic", 40.0, 300.0, 80.0, 0.6, 0.4),
    JointSpec("j1", "revolute", 12.0, 8.0, 2.5, 1.5, 1.5),
    JointSpec("j2", "revolute", 15.0, 10.0, 3.0, 1.2, 1.2),
    JointSpec("j3", "revolute", 8.0, 5.0, 1.2, 1.5, 1.5),
    JointSpec("j4", "revolute", 2.5, 1.0, 0.12, 2.0, 2.5),
    JointSpec("j5", "revolute", 2.0, 0.8, 0.08, 2.0, 2.5),
    JointSpec("j6", "revolute", 0.8, 0.3, 0.02, 3.0, 3.0),
)


@dataclass(frozen=True)
class Wear:
    """Injected wear: ``coefficient`` rises ``rate_percent_per_day`` from ``start_day`` on."""

    robot: str
    joint: str
    start_day: int
    coefficient: str = "fc"
    rate_percent_per_day: float = 1.0

    @property
    def start_date(self) -> str:
        return (START + dt.timedelta(days=self.start_day)).date().isoformat()

    def factor(self, day: float) -> float:
        return 1.0 + self.rate_percent_per_day / 100.0 * max(0.0, day - self.start_day)

    def to_dict(self) -> dict:
        return {
            "robot": self.robot,
            "joint": self.joint,
            "coefficient": self.coefficient,
            "start_day": self.start_day,
            "start_date": self.start_date,
            "rate_percent_per_day": self.rate_percent_per_day,
        }


@dataclass(frozen=True)
class Run:
    """One identification run of one joint."""

    robot: str
    joint: JointSpec
    day: int
    time: dt.datetime
    temperature: float  # [degC]
    a_c: float
    k_v: float
    scale: float  # the robot's joint scale (per-robot spread of nominal friction)

    @property
    def key(self) -> str:
        return f"{self.robot}/{self.time.strftime('%Y-%m-%dT%H%M')}/{self.joint.name}"


@dataclass
class FleetPlan:
    """Every run of the fleet, in time order per joint, and the injected wear."""

    robots: list[str]
    runs: list[Run]
    wear: list[Wear]
    days: int
    runs_per_day: int
    seed: int
    joints: tuple[JointSpec, ...] = ARM
    _wear_index: dict = field(default_factory=dict, repr=False)

    def wear_of(self, robot: str, joint: str) -> Wear | None:
        if not self._wear_index:
            self._wear_index.update({(w.robot, w.joint): w for w in self.wear})
        return self._wear_index.get((robot, joint))

    def truth(self, run: Run) -> dict[str, float]:
        """The true coefficients of ``run`` (module docstring)."""
        j = run.joint
        dT = run.temperature - T_REF
        fc = j.fc * run.scale * (1.0 + run.a_c * dT)
        fv = j.fv * run.scale * math.exp(-run.k_v * dT)
        w = self.wear_of(run.robot, j.name)
        if w is not None:
            if w.coefficient == "fc":
                fc *= w.factor(run.day)
            else:
                fv *= w.factor(run.day)
        return {"fc": fc, "fv": fv, "J": j.inertia * run.scale}

    def truth_dict(self) -> dict:
        """What a truth file holds: the plan's size, seed, reference temperature and worn joints."""
        return {
            "robots": len(self.robots),
            "joints": [j.name for j in self.joints],
            "days": self.days,
            "runs_per_day": self.runs_per_day,
            "seed": self.seed,
            "start_date": START.date().isoformat(),
            "reference_temperature_degC": T_REF,
            "wear": [w.to_dict() for w in self.wear],
        }


def fleet_plan(
    robots: int = 20,
    days: int = 60,
    runs_per_day: int = 4,
    seed: int = 0,
    worn: int | None = None,
    first_wear_day: int = 20,
    joints: tuple[JointSpec, ...] = ARM,
) -> FleetPlan:
    """The runs of ``robots`` x ``joints`` x ``days`` x ``runs_per_day`` and ``worn`` joints wearing
    (default: one per 4 robots, at least 1) from a day drawn in [first_wear_day, days - 8]."""
    rng = np.random.default_rng(seed)
    names = [f"robot{i:02d}" for i in range(robots)]
    worn = max(1, robots // 4) if worn is None else worn
    last = max(first_wear_day, days - 8)
    picks = rng.choice(robots * len(joints), size=min(worn, robots * len(joints)), replace=False)
    wear = [
        Wear(
            names[p // len(joints)], joints[p % len(joints)].name, int(rng.integers(first_wear_day, last + 1))
        )
        for p in sorted(picks)
    ]
    hours = [2.0 + 24.0 * i / runs_per_day for i in range(runs_per_day)]
    runs: list[Run] = []
    for robot in names:
        scale = rng.uniform(0.8, 1.2, len(joints))
        heat = rng.normal(0.0, 2.0, len(joints))
        a_c = rng.normal(-0.004, 0.001, len(joints))
        k_v = rng.normal(0.02, 0.004, len(joints))
        t_day = rng.normal(30.0, 2.0, days)
        for d in range(days):
            for h in hours:
                cycle = 12.0 * math.sin(2.0 * math.pi * (h - 9.0) / 24.0)
                when = START + dt.timedelta(days=d, hours=h)
                for i, j in enumerate(joints):
                    temp = float(np.clip(t_day[d] + cycle + heat[i] + rng.normal(0.0, 0.7), 10.0, 50.0))
                    runs.append(Run(robot, j, d, when, temp, float(a_c[i]), float(k_v[i]), float(scale[i])))
    return FleetPlan(names, runs, wear, days, runs_per_day, seed, joints)


def table_rows(plan: FleetPlan, seed: int | None = None, noise: dict | None = None) -> list[dict]:
    """Fleet-table rows of every run of ``plan`` (schema :data:`~.table.FLEET_SCHEMA`): the
    recommended ``coulomb_viscous`` (fc, fv, J) and a ``coulomb`` row (fc, J), coefficients drawn
    as truth x (1 + noise x N(0, 1)), stderr = noise x truth x U(0.8, 1.2)."""
    rng = np.random.default_rng(plan.seed + 1000 if seed is None else seed)
    noise = {**NOISE, **(noise or {})}
    fitted_at = START + dt.timedelta(days=plan.days)
    rows = []
    for run in plan.runs:
        truth = plan.truth(run)
        j = run.joint
        common = {
            "robot": run.robot,
            "joint": j.name,
            "run_time": run.time,
            "joint_type": j.joint_type,
            "effort_unit": j.effort_unit,
            "explains": "friction and inertia",
            "error": "",
            "temperature_mean": run.temperature,
            "temperature_min": run.temperature - 0.3,
            "temperature_max": run.temperature + 0.3,
            "load_rms": truth["fc"] * 1.3 * (1 + 0.02 * rng.standard_normal()),
            "speed_rms": j.vmax / 2.5,
            "samples": 5000,
            "duration_s": 10.0,
            "software_version": "synthetic",
            "source_path": f"{run.key}.csv",
            "source_sha256": hashlib.sha256(run.key.encode()).hexdigest(),
            "fitted_at": fitted_at,
        }
        for model, names, rec in (
            ("coulomb_viscous", ("fc", "fv", "J"), True),
            ("coulomb", ("fc", "J"), False),
        ):
            values = [truth[n] * (1.0 + noise[n] * rng.standard_normal()) for n in names]
            stderr = [noise[n] * truth[n] * rng.uniform(0.8, 1.2) for n in names]
            rows.append(
                {
                    **common,
                    "model": model,
                    "recommended": rec,
                    "coef_names": list(names),
                    "coef_values": values,
                    "coef_stderr": stderr,
                    "validation_rms": 0.02 * truth["fc"],
                    "validation_nmse_percent": 2.0 if rec else 6.0,
                    "compensate": rec,
                    "verdict": "compensate" if rec else "viscous friction unexplained",
                }
            )
    return rows
