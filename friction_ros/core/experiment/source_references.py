"""The identification signals of the source documents as references (:mod:`.references` builds them from a
config): band-limited random (ABB M19-S paper A.5), chirp (GA friction thesis 2002 section 8.1), the parabola composition
(GA friction thesis 2002 App. C Table C.1) and random steps (GA friction thesis 2002 section 8.3)."""

from __future__ import annotations

import math

import numpy as np

from friction_ros.core.validation import (
    ParameterError,
    check_int,
    check_real,
)

from .butterworth import butter_lowpass_sos, sosfilt
from .reference_base import Reference, _pwl_velocity

#: GA friction thesis 2002 App. C Table C.1: (dt [s], dA [rad], end time [s]); dt = dA = 0 is a hold.
GA_THESIS_PARABOLA_TABLE: tuple[tuple[float, float, float], ...] = (
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


class BandLimitedRandom(Reference):
    """ABB M19-S paper A.5: seeded white noise -> 4th-order digital Butterworth low-pass (1 Hz), scaled.

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
        sos = butter_lowpass_sos(self.order, self.cutoff, 1.0 / self.sample_time)
        x = sosfilt(sos, rng.standard_normal(N))
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
    """GA friction thesis 2002 section 8.1 (variant A): (A0 - r t) sin(w0 t + (w1 - w0) t^2 / (2 T))."""

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
    """GA friction thesis 2002 App. C: each section (dt, dA) is A0 + dA (tau/dt)^2 then A0 + 2dA - dA ((2dt - tau)/dt)^2."""

    kind = "parabola"

    def __init__(self, sections=None, **kw):
        super().__init__(**kw)
        rows = GA_THESIS_PARABOLA_TABLE if sections is None else sections
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
    """GA friction thesis 2002 section 8.3: piecewise constant, a new U(low, high) value every ``hold`` seconds."""

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
