"""Reference generators: position, velocity and acceleration at time t (or on an array of times).

Every generator is built from a config dict (one section of a ROS parameter YAML) with
:func:`reference_from_config` and returns ``(pos, vel, acc)`` in rad, rad/s, rad/s^2:

* ``sample(t) -> (pos, vel, acc)`` (floats) for the control loop,
* ``arrays(t) -> (pos, vel, acc)`` (numpy arrays) for tests, benchmarks and plotting.

Types (``type`` key):

``constant``           hold ``offset``.
``step``               ``offset`` until ``start_time``, then ``offset + amplitude``; with
                       ``rise_time > 0`` the step is a bang-bang (triangular velocity) move so
                       velocity and acceleration are finite (point-to-point, ABB M19-S paper Fig. 11).
``ramp``               ``offset + slope * (t - start_time)`` for ``0 <= t - start_time <= ramp_time``.
``sinusoid``           ``offset + amplitude * sin(2 pi f (t - start_time) + phase)`` (AI friction chapter 1 Hz sines).
``velocity_reversals`` trapezoidal velocity alternating +-``velocity`` every ``half_period`` s with
                       ``acceleration`` ramps, starting from rest (stick-slip / reversal tests).
``band_limited_random`` ABB M19-S paper A.5: white noise through a 4th-order digital Butterworth low-pass
                       (``cutoff`` = 1 Hz), scaled so that max |pos - offset| = ``amplitude``.
``chirp``              GA friction thesis 2002 section 8.1: ``(amplitude - amplitude_decay t) sin(phi(t))`` with the
                       frequency swept linearly from ``omega_start`` to ``omega_end`` rad/s over
                       ``sweep_time`` (phi = w0 t + (w1 - w0) t^2 / (2 T)).
``parabola``           GA friction thesis 2002 App. C Table C.1: C^1 composition of up/down parabolas; each row
                       ``[dt, dA, end_t]`` rises 2 dA in 2 dt; rows with dt = dA = 0 hold to end_t.
``random_steps``       GA friction thesis 2002 section 8.3: a new uniform random value in [low, high] every
                       ``hold`` seconds (piecewise constant, seeded).

Time before ``start_time`` holds the initial value for every type.

The base class is in :mod:`.reference_base`, the source documents' identification signals (band-limited
random, chirp, parabola, random steps) in :mod:`.source_references`.
"""

from __future__ import annotations

import inspect
import math
from collections.abc import Mapping
from typing import Any

import numpy as np

from friction_ros.core.experiment.reference_base import Reference, _pwl_velocity
from friction_ros.core.experiment.source_references import (  # noqa: F401 (re-exported)
    GA_THESIS_PARABOLA_TABLE,
    BandLimitedRandom,
    Chirp,
    Parabola,
    RandomSteps,
)
from friction_ros.core.validation import (
    ParameterError,
    check_choice,
    check_keys,
    check_real,
)

__all__ = [
    "REFERENCE_TYPES",
    "Reference",
    "reference_from_config",
    "GA_THESIS_PARABOLA_TABLE",
]


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
