"""Reference generators: position, velocity and acceleration at time t (or on an array of times).

Every generator is built from a config dict (one section of a ROS parameter YAML) with
:func:`reference_from_config` and returns ``(pos, vel, acc)`` in rad, rad/s, rad/s^2:

* ``sample(t) -> (pos, vel, acc)`` (floats) for the control loop,
* ``arrays(t) -> (pos, vel, acc)`` (numpy arrays) for tests, benchmarks and plotting.

Types (``type`` key):

``constant``           hold ``offset``.
``step``               ``offset`` until ``start_time``, then ``offset + amplitude``; with
                       ``rise_time > 0`` the step is a bang-bang (triangular velocity) move so
                       velocity and acceleration are finite (point-to-point, seed 003 Fig. 11).
``ramp``               ``offset + slope * (t - start_time)`` for ``0 <= t - start_time <= ramp_time``.
``sinusoid``           ``offset + amplitude * sin(2 pi f (t - start_time) + phase)`` (seed 004 1 Hz sines).
``velocity_reversals`` trapezoidal velocity alternating +-``velocity`` every ``half_period`` s with
                       ``acceleration`` ramps, starting from rest (stick-slip / reversal tests).
``band_limited_random`` seed 003 A.5: white noise through a 4th-order digital Butterworth low-pass
                       (``cutoff`` = 1 Hz), scaled so that max |pos - offset| = ``amplitude``.
``chirp``              seed 001 section 8.1: ``(amplitude - amplitude_decay t) sin(phi(t))`` with the
                       frequency swept linearly from ``omega_start`` to ``omega_end`` rad/s over
                       ``sweep_time`` (phi = w0 t + (w1 - w0) t^2 / (2 T)).
``parabola``           seed 001 App. C Table C.1: C^1 composition of up/down parabolas; each row
                       ``[dt, dA, end_t]`` rises 2 dA in 2 dt; rows with dt = dA = 0 hold to end_t.
``random_steps``       seed 001 section 8.3: a new uniform random value in [low, high] every
                       ``hold`` seconds (piecewise constant, seeded).

Time before ``start_time`` holds the initial value for every type.

One concept in one module (slightly over 500 lines): the nine generators share the base class,
its validation and the config factory, and each is short; a reader compares them side by side.
"""

from __future__ import annotations

import inspect
import math
from abc import ABC, abstractmethod
from collections.abc import Mapping
from typing import Any

import numpy as np

from friction_ros.core.validation import (
    ParameterError,
    check_choice,
    check_int,
    check_keys,
    check_real,
)

__all__ = [
    "REFERENCE_TYPES",
    "Reference",
    "reference_from_config",
    "SEED001_PARABOLA_TABLE",
]

#: Seed 001 App. C Table C.1: (dt [s], dA [rad], end time [s]); dt = dA = 0 is a hold.
SEED001_PARABOLA_TABLE: tuple[tuple[float, float, float], ...] = (
    (3.5, 1.0, 7.0),
    (3.5, 1.0, 14.0),
    (3.5, 1.0, 21.0),
    (3.5, 1.0, 28.0),
    (2.1, 1.0, 32.2),
    (0.7, 1.0, 33.6),
    (3.5, 1.0, 40.6),
    (3.5, 0.6, 47.6),
    (3.5, 0.2, 54.6),
    (3.5, 1.0, 61.6),
    (2.1, 0.6, 65.8),
    (0.7, 0.2, 67.2),
    (0.0, 0.0, 72.0),
    (3.5, -1.0, 79.0),
    (3.5, -1.0, 86.0),
    (3.5, -1.0, 93.0),
    (3.5, -1.0, 100.0),
    (2.1, -1.0, 104.2),
    (0.7, -1.0, 105.6),
    (3.5, -1.0, 112.6),
    (3.5, -0.6, 119.6),
    (3.5, -0.2, 126.6),
    (3.5, -1.0, 133.6),
    (2.1, -0.6, 137.8),
    (0.7, -0.2, 139.2),
    (0.0, 0.0, 141.0),
)


class Reference(ABC):
    """Base class: a reference trajectory theta_d(t) with its first two derivatives."""

    kind = "base"

    def __init__(self, offset: float = 0.0, start_time: float = 0.0):
        self.offset = check_real(f"reference.{self.kind}.offset", offset, unit="rad")
        self.start_time = check_real(f"reference.{self.kind}.start_time", start_time, 0.0, unit="s")

    @abstractmethod
    def _eval(self, tau: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Return (pos - offset, vel, acc) at times tau = t - start_time >= 0."""

    def arrays(self, t) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Vectorised reference at times ``t`` (array, s): ``(pos, vel, acc)`` arrays."""
        t = np.asarray(t, dtype=float)
        tau = np.maximum(t - self.start_time, 0.0)
        p, v, a = self._eval(np.atleast_1d(tau))
        before = np.atleast_1d(t) < self.start_time
        if np.any(before):
            p = np.where(before, self._initial(), p)
            v = np.where(before, 0.0, v)
            a = np.where(before, 0.0, a)
        p = p + self.offset
        if t.ndim == 0:
            return float(p[0]), float(v[0]), float(a[0])
        return p.reshape(t.shape), v.reshape(t.shape), a.reshape(t.shape)

    def _initial(self) -> float:
        """Value (relative to offset) held before ``start_time``."""
        return float(self._eval(np.zeros(1))[0][0])

    def sample(self, t: float) -> tuple[float, float, float]:
        """Reference at one time ``t`` (s): ``(pos, vel, acc)`` floats.

        Types with a scalar form (``_scalar``) skip numpy here (the controller calls this every
        period; ~1 us instead of ~10 us); the values equal :meth:`arrays` to rounding.
        """
        t = float(t)
        if t >= self.start_time:
            r = self._scalar(t - self.start_time)
            if r is not None:
                return r[0] + self.offset, r[1], r[2]
        p, v, a = self.arrays(t)
        return float(p), float(v), float(a)

    def _scalar(self, tau: float) -> tuple[float, float, float] | None:
        """(pos - offset, vel, acc) at one tau >= 0 without numpy, or None to use :meth:`_eval`."""
        return None

    __call__ = sample

    def config(self) -> dict[str, Any]:
        """Return the config dict that rebuilds this reference."""
        return {"type": self.kind, "offset": self.offset, "start_time": self.start_time, **self._config()}

    def _config(self) -> dict[str, Any]:
        return {}


def _pwl_velocity(tk: np.ndarray, vk: np.ndarray, tau: np.ndarray):
    """Integrate a piecewise-linear velocity (knots tk, vk) exactly: position, velocity, acceleration.

    Beyond the last knot the velocity is held constant at vk[-1].
    """
    dtk = np.diff(tk)
    slopes = np.where(dtk > 0, np.diff(vk) / np.where(dtk > 0, dtk, 1.0), 0.0)
    areas = 0.5 * (vk[:-1] + vk[1:]) * dtk
    cum = np.concatenate([[0.0], np.cumsum(areas)])
    idx = np.clip(np.searchsorted(tk, tau, side="right") - 1, 0, len(tk) - 1)
    last = idx >= len(tk) - 1
    seg = np.minimum(idx, len(tk) - 2)
    s = tau - tk[seg]
    a = np.where(last, 0.0, slopes[seg])
    v0 = vk[seg]
    pos = np.where(last, cum[-1] + vk[-1] * (tau - tk[-1]), cum[seg] + v0 * s + 0.5 * a * s * s)
    vel = np.where(last, vk[-1], v0 + a * s)
    return pos, vel, a


class Constant(Reference):
    kind = "constant"

    def _eval(self, tau):
        z = np.zeros_like(tau)
        return z, z, z

    def _scalar(self, tau):
        return 0.0, 0.0, 0.0


class Step(Reference):
    """Step of ``amplitude`` at ``start_time``; bang-bang move in ``rise_time`` if > 0."""

    kind = "step"

    def __init__(self, amplitude: float = 0.1, rise_time: float = 0.0, **kw):
        super().__init__(**kw)
        self.amplitude = check_real("reference.step.amplitude", amplitude, unit="rad")
        self.rise_time = check_real("reference.step.rise_time", rise_time, 0.0, unit="s")

    def _initial(self) -> float:
        return 0.0

    def _scalar(self, tau):
        return (self.amplitude, 0.0, 0.0) if self.rise_time == 0.0 else None

    def _eval(self, tau):
        if self.rise_time == 0.0:
            z = np.zeros_like(tau)
            return np.full_like(tau, self.amplitude), z, z
        T = self.rise_time
        vpk = 2.0 * self.amplitude / T
        return _pwl_velocity(np.array([0.0, T / 2, T]), np.array([0.0, vpk, 0.0]), tau)

    def _config(self):
        return {"amplitude": self.amplitude, "rise_time": self.rise_time}


class Ramp(Reference):
    kind = "ramp"

    def __init__(self, slope: float = 0.1, ramp_time: float = math.inf, **kw):
        super().__init__(**kw)
        self.slope = check_real("reference.ramp.slope", slope, unit="rad/s")
        self.ramp_time = check_real(
            "reference.ramp.ramp_time", ramp_time, 0.0, lo_open=True, unit="s", allow_inf=True
        )

    def _eval(self, tau):
        moving = tau <= self.ramp_time
        pos = self.slope * np.minimum(tau, self.ramp_time)
        return pos, np.where(moving, self.slope, 0.0), np.zeros_like(tau)

    def _scalar(self, tau):
        return self.slope * min(tau, self.ramp_time), (self.slope if tau <= self.ramp_time else 0.0), 0.0

    def _config(self):
        return {"slope": self.slope, "ramp_time": self.ramp_time}


class Sinusoid(Reference):
    kind = "sinusoid"

    def __init__(self, amplitude: float = 0.1, frequency: float = 1.0, phase: float = 0.0, **kw):
        super().__init__(**kw)
        self.amplitude = check_real("reference.sinusoid.amplitude", amplitude, unit="rad")
        self.frequency = check_real("reference.sinusoid.frequency", frequency, 0.0, lo_open=True, unit="Hz")
        self.phase = check_real("reference.sinusoid.phase", phase, unit="rad")

    def _eval(self, tau):
        w = 2.0 * math.pi * self.frequency
        ph = w * tau + self.phase
        A = self.amplitude
        return A * np.sin(ph), A * w * np.cos(ph), -A * w * w * np.sin(ph)

    def _scalar(self, tau):
        w = 2.0 * math.pi * self.frequency
        ph = w * tau + self.phase
        A = self.amplitude
        s = math.sin(ph)
        return A * s, A * w * math.cos(ph), -A * w * w * s

    def _config(self):
        return {"amplitude": self.amplitude, "frequency": self.frequency, "phase": self.phase}


class VelocityReversals(Reference):
    """Trapezoidal velocity +V / -V alternating every ``half_period``, from rest, ramps at ``acceleration``."""

    kind = "velocity_reversals"

    def __init__(self, velocity: float = 0.1, half_period: float = 2.0, acceleration: float = 1.0, **kw):
        super().__init__(**kw)
        self.velocity = check_real(
            "reference.velocity_reversals.velocity", velocity, 0.0, lo_open=True, unit="rad/s"
        )
        self.half_period = check_real(
            "reference.velocity_reversals.half_period", half_period, 0.0, lo_open=True, unit="s"
        )
        self.acceleration = check_real(
            "reference.velocity_reversals.acceleration", acceleration, 0.0, lo_open=True, unit="rad/s^2"
        )
        tr = self.velocity / self.acceleration
        if 2.0 * tr > self.half_period:
            raise ParameterError(
                f"reference.velocity_reversals.half_period = {self.half_period:g} is out of range: "
                f"must be >= 2 * velocity / acceleration = {2 * tr:g} [s]"
            )
        h, V = self.half_period, self.velocity
        # one period starting and ending at +0 -> ... ; the first ramp starts from rest
        self._tk = np.array([0.0, tr, h - tr, h + tr, 2 * h - tr, 2 * h + tr])
        self._vk = np.array([0.0, V, V, -V, -V, V])

    def _eval(self, tau):
        h, tr = self.half_period, self.velocity / self.acceleration
        # first half period from rest, then periodic with period 2h starting at t = tr (velocity +V)
        out_p = np.empty_like(tau)
        out_v = np.empty_like(tau)
        out_a = np.empty_like(tau)
        first = tau < tr
        p1, v1, a1 = _pwl_velocity(self._tk[:2], self._vk[:2], tau[first])
        out_p[first], out_v[first], out_a[first] = p1, v1, a1
        rest = ~first
        if np.any(rest):
            p_tr = 0.5 * self.velocity * tr
            per = 2.0 * h
            s = tau[rest] - tr
            k = np.floor(s / per)
            s = s - k * per
            tk = self._tk[1:] - tr
            vk = self._vk[1:]
            pp, vv, aa = _pwl_velocity(tk, vk, s)
            # net displacement per period is zero (symmetric trapezoid)
            out_p[rest], out_v[rest], out_a[rest] = p_tr + pp, vv, aa
        return out_p, out_v, out_a

    def _config(self):
        return {"velocity": self.velocity, "half_period": self.half_period, "acceleration": self.acceleration}


class BandLimitedRandom(Reference):
    """Seed 003 A.5: seeded white noise -> 4th-order digital Butterworth low-pass (1 Hz), scaled.

    The noise is generated on a grid of ``sample_time`` for ``duration`` seconds, filtered with zero
    initial state (so the reference starts at rest at ``offset``), scaled so max |pos| = amplitude.
    Velocity and acceleration are central differences of the filtered signal; values between grid
    points are interpolated linearly, and the last value is held after ``duration``.
    """

    kind = "band_limited_random"

    def __init__(
        self,
        amplitude: float = 0.01,
        cutoff: float = 1.0,
        order: int = 4,
        duration: float = 20.0,
        seed: int = 0,
        sample_time: float = 1e-3,
        **kw,
    ):
        from scipy import signal

        super().__init__(**kw)
        n = "reference.band_limited_random"
        self.amplitude = check_real(f"{n}.amplitude", amplitude, 0.0, lo_open=True, unit="rad")
        self.sample_time = check_real(f"{n}.sample_time", sample_time, 0.0, 0.1, lo_open=True, unit="s")
        self.cutoff = check_real(
            f"{n}.cutoff", cutoff, 0.0, 0.5 / self.sample_time, lo_open=True, hi_open=True, unit="Hz"
        )
        self.order = check_int(f"{n}.order", order, 1, 10)
        self.duration = check_real(f"{n}.duration", duration, 0.0, 3600.0, lo_open=True, unit="s")
        self.seed = check_int(f"{n}.seed", seed, 0)
        N = int(round(self.duration / self.sample_time)) + 1
        rng = np.random.default_rng(self.seed)
        sos = signal.butter(self.order, self.cutoff, fs=1.0 / self.sample_time, output="sos")
        x = signal.sosfilt(sos, rng.standard_normal(N))
        x *= self.amplitude / max(np.max(np.abs(x)), 1e-300)
        self._t = np.arange(N) * self.sample_time
        self._p = x
        self._v = np.gradient(x, self.sample_time)
        self._a = np.gradient(self._v, self.sample_time)
        self._lists = (self._t.tolist(), x.tolist(), self._v.tolist(), self._a.tolist())

    def _scalar(self, tau):
        """Linear interpolation on the uniform grid (np.interp's formula), held past the end."""
        t, p, v, a = self._lists
        k = int(tau / self.sample_time)
        if k >= len(t) - 1:
            return (p[-1], 0.0, 0.0) if tau > t[-1] else (p[-1], v[-1], a[-1])
        if t[k] > tau:  # rounding of tau / sample_time
            k -= 1
        elif t[k + 1] <= tau:
            k += 1
            if k >= len(t) - 1:
                return (p[-1], 0.0, 0.0) if tau > t[-1] else (p[-1], v[-1], a[-1])
        f = (tau - t[k]) / (t[k + 1] - t[k])
        return (
            (p[k + 1] - p[k]) * f + p[k],
            (v[k + 1] - v[k]) * f + v[k],
            (a[k + 1] - a[k]) * f + a[k],
        )

    def _eval(self, tau):
        return (
            np.interp(tau, self._t, self._p),
            np.interp(tau, self._t, self._v, right=0.0),
            np.interp(tau, self._t, self._a, right=0.0),
        )

    def _config(self):
        return {
            "amplitude": self.amplitude,
            "cutoff": self.cutoff,
            "order": self.order,
            "duration": self.duration,
            "seed": self.seed,
            "sample_time": self.sample_time,
        }


class Chirp(Reference):
    """Seed 001 section 8.1 (variant A): (A0 - r t) sin(w0 t + (w1 - w0) t^2 / (2 T))."""

    kind = "chirp"

    def __init__(
        self,
        amplitude: float = math.pi,
        amplitude_decay: float = 0.01,
        omega_start: float = 0.3,
        omega_end: float = 1.5,
        sweep_time: float = 200.0,
        **kw,
    ):
        super().__init__(**kw)
        n = "reference.chirp"
        self.amplitude = check_real(f"{n}.amplitude", amplitude, unit="rad")
        self.amplitude_decay = check_real(f"{n}.amplitude_decay", amplitude_decay, unit="rad/s")
        self.omega_start = check_real(f"{n}.omega_start", omega_start, 0.0, unit="rad/s")
        self.omega_end = check_real(f"{n}.omega_end", omega_end, 0.0, unit="rad/s")
        self.sweep_time = check_real(f"{n}.sweep_time", sweep_time, 0.0, lo_open=True, unit="s")

    def _eval(self, tau, sin=np.sin, cos=np.cos):
        w0, k = self.omega_start, (self.omega_end - self.omega_start) / self.sweep_time
        ph = w0 * tau + 0.5 * k * tau * tau
        dph = w0 + k * tau
        A = self.amplitude - self.amplitude_decay * tau
        dA = -self.amplitude_decay
        s, c = sin(ph), cos(ph)
        return A * s, dA * s + A * c * dph, 2.0 * dA * c * dph - A * s * dph * dph + A * c * k

    def _scalar(self, tau):
        return self._eval(tau, math.sin, math.cos)

    def _config(self):
        return {
            "amplitude": self.amplitude,
            "amplitude_decay": self.amplitude_decay,
            "omega_start": self.omega_start,
            "omega_end": self.omega_end,
            "sweep_time": self.sweep_time,
        }


class Parabola(Reference):
    """Seed 001 App. C: each section (dt, dA) is A0 + dA (tau/dt)^2 then A0 + 2dA - dA ((2dt - tau)/dt)^2."""

    kind = "parabola"

    def __init__(self, sections=None, **kw):
        super().__init__(**kw)
        rows = SEED001_PARABOLA_TABLE if sections is None else sections
        tk, vk = [0.0], [0.0]
        t = 0.0
        clean = []
        for i, row in enumerate(rows):
            if len(row) != 3:
                raise ParameterError(f"reference.parabola.sections[{i}] = {row!r} must be [dt, dA, end_time]")
            dt = check_real(f"reference.parabola.sections[{i}].dt", row[0], 0.0, unit="s")
            dA = check_real(f"reference.parabola.sections[{i}].dA", row[1], unit="rad")
            end = check_real(f"reference.parabola.sections[{i}].end_time", row[2], t, unit="s")
            clean.append((dt, dA, end))
            if dt > 0.0:
                tk += [t + dt, t + 2 * dt]
                vk += [2.0 * dA / dt, 0.0]
                t += 2 * dt
            if end > t + 1e-9:
                tk.append(end)
                vk.append(0.0)
                t = end
        self.sections = clean
        self._tk = np.array(tk)
        self._vk = np.array(vk)

    def _eval(self, tau):
        return _pwl_velocity(self._tk, self._vk, tau)

    def _config(self):
        return {"sections": [list(r) for r in self.sections]}


class RandomSteps(Reference):
    """Seed 001 section 8.3: piecewise constant, a new U(low, high) value every ``hold`` seconds."""

    kind = "random_steps"

    def __init__(self, hold: float = 2.0, low: float = -1.0, high: float = 1.0, seed: int = 0, **kw):
        super().__init__(**kw)
        self.hold = check_real("reference.random_steps.hold", hold, 0.0, lo_open=True, unit="s")
        self.low = check_real("reference.random_steps.low", low, unit="rad")
        self.high = check_real("reference.random_steps.high", high, self.low, unit="rad")
        self.seed = check_int("reference.random_steps.seed", seed, 0)
        self._values = np.zeros(0)

    def _value(self, k: np.ndarray) -> np.ndarray:
        need = int(np.max(k)) + 1 if k.size else 0
        if need > self._values.size:
            n = max(need, 2 * self._values.size, 64)
            rng = np.random.default_rng(self.seed)
            self._values = rng.uniform(self.low, self.high, n)
        return self._values[k]

    def _eval(self, tau):
        k = np.floor(tau / self.hold).astype(int)
        z = np.zeros_like(tau)
        return self._value(k), z, z

    def _config(self):
        return {"hold": self.hold, "low": self.low, "high": self.high, "seed": self.seed}


_TYPES: dict[str, type[Reference]] = {
    c.kind: c
    for c in (
        Constant,
        Step,
        Ramp,
        Sinusoid,
        VelocityReversals,
        BandLimitedRandom,
        Chirp,
        Parabola,
        RandomSteps,
    )
}
#: Names accepted by ``reference_from_config({"type": ...})``.
REFERENCE_TYPES: tuple[str, ...] = tuple(_TYPES)


def reference_from_config(config: Mapping[str, Any] | Reference) -> Reference:
    """Build a reference from ``{"type": <name>, <key>: value, ...}`` (see the module docstring)."""
    if isinstance(config, Reference):
        return config
    if not isinstance(config, Mapping):
        raise ParameterError(f"reference = {config!r} must be a mapping with a 'type' key")
    cfg = dict(config)
    kind = check_choice("reference.type", cfg.pop("type", None), REFERENCE_TYPES)
    cls = _TYPES[kind]
    allowed = ["offset", "start_time"] + [
        p for p in inspect.signature(cls.__init__).parameters if p not in ("self", "kw")
    ]
    check_keys(f"reference ({kind})", cfg, allowed)
    return cls(**cfg)
