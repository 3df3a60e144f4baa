"""The table a generator returns (:class:`GauntletLog`), its CSV text, and the shared motion pieces.

* :class:`GauntletLog`: CSV columns (header -> values), their units, the known truth and the
  ``load_csv`` keywords (joint, columns, time scale) a user passes to read it, plus an optional
  separate validation run;
* :func:`multisine`: a smooth excitation q(t) = sum_k A_k sin(2 pi f_k t + phi_k),
  with its exact derivatives, so a log can be sampled at any instant (jittered stamps);
* :func:`track`: a PD position loop with a torque limit around a project plant
  (:class:`~friction_ros.core.plant.servo.GearheadServoPlant`, torque actuation) at a fixed period:
  ``tau = clip(ff + kp (q_ref - q_meas) + kd (v_ref - v_meas), -limit, limit)``.

Everything is seeded: the same arguments give the same arrays and the same CSV bytes.
"""

from __future__ import annotations

import io
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np


@dataclass
class GauntletLog:
    """One synthetic log: ``columns`` (CSV header -> values, in file order) and what is known of it.

    ``units``: header -> unit text; ``truth``: the generating parameters and derived shares;
    ``load``: keywords of :func:`~friction_ros.core.identification.data.csv_loading.load_csv`
    (``joint``, ``columns``, ``time_scale``) that read it, as a user would pass them to friction-fit;
    ``validation``: a second run of the same machine under different excitation (or None).
    """

    name: str
    description: str
    columns: dict[str, np.ndarray]
    units: dict[str, str]
    truth: dict
    load: dict = field(default_factory=dict)
    validation: GauntletLog | None = None

    @property
    def samples(self) -> int:
        return int(len(next(iter(self.columns.values()))))

    @property
    def time_column(self) -> str:
        return (self.load.get("columns") or {}).get("time", next(iter(self.columns)))

    @property
    def seconds(self) -> float:
        t = np.asarray(self.columns[self.time_column], float) * self.load.get("time_scale", 1.0)
        return float(np.nanmax(t) - np.nanmin(t))

    def cli_args(self) -> list[str]:
        """The friction-fit options that read this log (``--joint``, ``--columns``, ``--time-scale``)."""
        args: list[str] = []
        if self.load.get("joint"):
            args += ["--joint", self.load["joint"]]
        if self.load.get("columns"):
            args += ["--columns", ",".join(f"{r}={n}" for r, n in self.load["columns"].items())]
        if self.load.get("time_scale", 1.0) != 1.0:
            args += ["--time-scale", repr(float(self.load["time_scale"]))]
        return args

    def csv_text(self) -> str:
        """Header comment (what the log is, units), header line, one row per sample (``%.17g``;
        NaN is written as an empty cell, a missing value)."""
        names = list(self.columns)
        buf = io.StringIO()
        buf.write(f"# {self.name}: {self.description}\n")
        buf.write("# units: " + ", ".join(f"{n} [{self.units.get(n, '-')}]" for n in names) + "\n")
        buf.write(",".join(names) + "\n")
        table = np.column_stack([np.asarray(self.columns[n], dtype=float) for n in names])
        for row in table:
            buf.write(",".join(f"{x:.17g}" if math.isfinite(x) else "" for x in row) + "\n")
        return buf.getvalue()

    def write_csv(self, path) -> Path:
        """Write :meth:`csv_text` to ``path`` (bytes identical for identical generator arguments)."""
        path = Path(path)
        path.write_text(self.csv_text())
        return path


def multisine(
    rng: np.random.Generator, f_lo: float, f_hi: float, n: int = 6, tilt: float = 0.0
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(A, w, phi) of n sines, frequencies log-spaced in [f_lo, f_hi] Hz (jittered), random phases,
    A_k = w_k^(tilt - 1): velocity amplitudes w_k^tilt (0: equal; > 0: more acceleration)."""
    f = np.geomspace(f_lo, f_hi, n) * rng.uniform(0.9, 1.1, n)
    w = 2.0 * math.pi * f
    return w ** (tilt - 1.0), w, rng.uniform(0.0, 2.0 * math.pi, n)


def sines(t, a: np.ndarray, w: np.ndarray, phi: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """q, dq/dt, d2q/dt2 of sum_k a_k sin(w_k t + phi_k) at times ``t``."""
    arg = np.multiply.outer(np.asarray(t, float), w) + phi
    s, c = np.sin(arg), np.cos(arg)
    return s @ a, c @ (a * w), -(s @ (a * w * w))


def scaled_sines(rng, t, f_lo, f_hi, stroke, vmax, n=6, tilt=0.0):
    """A multisine on ``t`` scaled so that its range is <= ``stroke`` and its peak speed <= ``vmax``;
    returns (q, v, a, (A, w, phi)) with the scale folded into A (for sampling at other instants)."""
    a, w, phi = multisine(rng, f_lo, f_hi, n, tilt)
    q, v, _ = sines(t, a, w, phi)
    c = min(stroke / np.ptp(q), vmax / np.max(np.abs(v)))
    a = a * c
    q, v, acc = sines(t, a, w, phi)
    return q, v, acc, (a, w, phi)


def quantize(x: np.ndarray, step: float) -> np.ndarray:
    """x floored to a multiple of ``step`` (an encoder or an ADC)."""
    return np.floor(np.asarray(x) / step) * step


def track(
    params,
    q_ref: np.ndarray,
    v_ref: np.ndarray,
    dt: float,
    kp: float,
    kd: float,
    limit: float,
    ff: np.ndarray | None = None,
) -> dict[str, np.ndarray]:
    """Run a PD position loop with torque limit ``limit`` around ``GearheadServoPlant(params)``.

    ``params``: :class:`~friction_ros.core.plant.params.PlantParams` with ``actuation="torque"``;
    the loop reads the plant's measured position/velocity (encoder, velocity filter) one period
    late, as a drive does. Returns measured ``position``, ``velocity``, ``effort`` (the plant's current
    reading times its gain), the limiter's output ``command`` and the true ``true_position``,
    ``true_velocity``, ``friction`` (motor- plus load-side), one row per period.
    """
    from friction_ros.core.plant.servo import GearheadServoPlant

    plant = GearheadServoPlant(params)
    plant.reset(float(q_ref[0]), float(v_ref[0]))
    n = len(q_ref)
    keys = ("position", "velocity", "effort", "command", "true_position", "true_velocity", "friction")
    out = {k: np.empty(n) for k in keys}
    ff = np.zeros(n) if ff is None else np.asarray(ff, float)
    qm, vm = float(q_ref[0]), float(v_ref[0])
    for k in range(n):
        u = ff[k] + kp * (q_ref[k] - qm) + kd * (v_ref[k] - vm)
        u = min(max(u, -limit), limit)
        m = plant.step(u, dt)
        qm, vm = m.position, m.velocity
        row = (qm, vm, m.effort, u, m.true_position, m.true_velocity, m.friction_motor + m.friction_load)
        for key, x in zip(keys, row):
            out[key][k] = x
    return out
