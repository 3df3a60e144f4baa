"""What the plant's sensors report: encoder quantisation, differenced and filtered velocity, current
noise/offset and measurement delay (all seeded), plus the current-sensor calibration of AI friction chapter.

:class:`Sensors` turns the true values at the end of a control period into a :class:`Measurement`:

* position: the encoder (``encoder_cpr`` quadrature counts per revolution of its shaft, the motor or
  the joint, times ``encoder_ratio`` for a belt) floors the shaft angle to a count; 0 = ideal;
* velocity: the difference of two positions over the control period, low-pass filtered at
  ``velocity_filter_hz`` (first order; 0 = raw difference);
* current: the true current plus ``current_offset`` plus white noise of ``current_noise_std``;
  effort = Kt r eta * current (the joint torque the current stands for);
* ``measurement_delay``: whole control periods the readings lag behind.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass

import numpy as np

from friction_ros.core.plant.params import PlantParams

# AI friction chapter eq. (13): I_s = 7.8555 V_s - 19.6544
AI_CHAPTER_CURRENT_SENSOR_GAIN = 7.8555
AI_CHAPTER_CURRENT_SENSOR_OFFSET = -19.6544


def current_from_sensor_voltage(
    v, gain: float = AI_CHAPTER_CURRENT_SENSOR_GAIN, offset: float = AI_CHAPTER_CURRENT_SENSOR_OFFSET
):
    """Current-sensor calibration of AI friction chapter eq. (13): I = gain * V + offset [A]."""
    return gain * np.asarray(v, dtype=float) + offset


def sensor_voltage_from_current(
    i, gain: float = AI_CHAPTER_CURRENT_SENSOR_GAIN, offset: float = AI_CHAPTER_CURRENT_SENSOR_OFFSET
):
    """Inverse of :func:`current_from_sensor_voltage`: V = (I - offset) / gain [V]."""
    return (np.asarray(i, dtype=float) - offset) / gain


@dataclass(slots=True)
class Measurement:
    """What the sensors report after one control period (joint frame) plus the true values."""

    time: float
    position: float
    velocity: float
    effort: float
    motor_current: float
    true_position: float
    true_velocity: float
    true_effort: float
    true_motor_current: float
    motor_position: float
    motor_velocity: float
    friction_motor: float
    friction_load: float


class Sensors:
    """The sensing of one plant (see the module docstring); stateful, reset with the plant."""

    def __init__(self, params: PlantParams) -> None:
        self.params = params
        self._delay = 0
        self.reset()

    def reset(self, velocity: float = 0.0) -> None:
        """Forget the past readings (the velocity filter starts at ``velocity``); re-seed the noise."""
        self._rng = np.random.default_rng(self.params.seed)
        self._vfilt = velocity
        self._last_pos = None
        self._queue: deque = deque()

    def set_period(self, dt: float) -> None:
        """The control period ``dt`` [s]: the measurement delay rounded to whole periods."""
        self._delay = round(self.params.measurement_delay / dt)

    def read(self, t: float, true: list, dt: float) -> Measurement:
        """The readings at time ``t`` from the true values ``true`` = (motor angle, motor velocity,
        joint position, joint velocity, current, motor-side friction, load-side friction) at the end
        of a control period ``dt``, delayed by the measurement delay."""
        m = self._measure(t, true, dt)
        if self._delay:
            self._queue.append(m)
            if len(self._queue) > self._delay:
                return self._queue.popleft()
            return self._queue[0]
        return m

    def _measure(self, t: float, o: list, dt: float) -> Measurement:
        p = self.params
        thm, wm, q, wl, cur = o[0], o[1], o[2], o[3], o[4]
        r = p.ratio
        out_gain = p.torque_constant * r * p.gear_efficiency
        # encoder
        if p.encoder_cpr > 0:
            shaft = thm if p.encoder_location == "motor" else q
            cnt_per_rad = p.encoder_cpr * p.encoder_ratio / (2.0 * math.pi)
            x = shaft * cnt_per_rad
            shaft_q = (
                math.floor(x) / cnt_per_rad if math.isfinite(x) else shaft
            )  # no crash on a diverged state
            pos = shaft_q / r if p.encoder_location == "motor" else shaft_q
        else:
            pos = q
        if self._last_pos is None:
            vraw = wl
        else:
            vraw = (pos - self._last_pos) / dt
        self._last_pos = pos
        if p.velocity_filter_hz > 0:
            a = 1.0 - math.exp(-2.0 * math.pi * p.velocity_filter_hz * dt)
            self._vfilt += a * (vraw - self._vfilt)
            vel = self._vfilt
        else:
            vel = vraw
        im = cur + p.current_offset
        if p.current_noise_std > 0:
            im += p.current_noise_std * self._rng.standard_normal()
        return Measurement(
            t,
            pos,
            vel,
            out_gain * im,
            im,
            q,
            wl,
            out_gain * cur,
            cur,
            thm,
            wm,
            o[5],
            o[6],
        )
