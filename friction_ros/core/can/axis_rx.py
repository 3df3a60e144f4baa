"""Receive side of :class:`~friction_ros.core.can.axis.DriveAxis`: telemetry frames -> motor-side
telemetry, through the telemetry gate (joint side: ``q = d * q_m / r - q_0``, ``dq = d * dq_m / r``,
``tau = d * tau_m * r``, see :mod:`~friction_ros.core.can.joint`).

Two paths with the same checks, counters and results (tests compare them frame by frame):

* general: the protocol's ``decode`` -> :class:`~friction_ros.core.can.protocol.DriveTelemetry`;
* fast, for the telemetry frames of every period: one dict lookup by arbitration id, then either an
  inline unpack of two float32 (``float_pairs``: ODrive encoder estimates and Iq) or the protocol's
  report handler returning a plain tuple (``fast_reports``: CiA 402 TPDO1 and TPDO2). No report
  object, no conversion calls: per-period CPU of ``bench/can_decode.py``.
"""

from __future__ import annotations

import struct

from friction_ros.core.can.frame import DecodeStats
from friction_ros.core.can.protocol import MOTION_PAIR, MOTION_REPORT, DriveTelemetry

_F2 = struct.Struct("<ff")


class AxisReceiver:
    """Mixin of DriveAxis (its lock, telemetry, counters, gate, protocol and conversion)."""

    def _bind_receive(self) -> None:
        """The per-frame state taken from the protocol once (at construction)."""
        p = self.protocol
        self._fast = {i: (kind, None) for i, kind in p.float_pairs().items()}
        self._fast.update(p.fast_reports())
        self._channel = p.gated_ids()
        self._reports_state = p.reports_state
        self._decode = p.decode

    def _bind_conversion(self) -> None:
        """Conversion factors of the fast path (at construction and on every reconfiguration)."""
        c = self.conv
        self._scale = self.protocol.motion_scale  # motor rad per wire unit (float pairs)
        self._turn = c.direction * self._scale / c.ratio  # joint units per wire unit
        self._amp = c.direction * c.torque_constant * c.ratio  # joint effort per A
        self._dir, self._ratio, self._zero = c.direction, c.ratio, c.zero_offset
        self._effort_current = self.protocol.effort_source == "current"

    @property
    def decode_stats(self) -> DecodeStats:
        return self.decoder.stats

    def _admit(self, r: DriveTelemetry, t: float) -> bool:
        """Pass a decoded report through the telemetry gate (lock held): position with torque as one
        reading, position alone as motion, current or torque as effort."""
        c, gate = self.conv, self.gate
        if r.position is not None:
            q, v = c.joint_position(r.position), c.joint_velocity(r.velocity)
            if r.torque is not None:
                return gate.reading(q, v, c.joint_torque(r.torque), t)
            return gate.motion(q, v, t)
        if r.current is not None:
            a = c.joint_torque_from_current(r.current)
            if r.current_setpoint is None:
                return gate.effort(t, a)
            return gate.effort(t, c.joint_torque_from_current(r.current_setpoint), a)
        if r.torque is not None:
            a = c.joint_torque(r.torque)
            return gate.effort(t, a if r.torque_target is None else c.joint_torque(r.torque_target), a)
        return True

    def on_frame(
        self, arb_id: int, data: bytes, is_remote: bool, is_extended: bool, is_error: bool, t: float
    ):
        """Feed one received frame (control or reader thread). ``t`` is the receive time."""
        fast = self._fast.get(arb_id)
        if fast is not None and not (is_remote or is_extended or is_error):
            kind, report = fast
            if report is not None:
                r = report(data)  # None: the general path decides (and counts)
                if r is not None:  # stored as the general path stores the same DriveTelemetry
                    tel, c = self.telemetry, self.counters
                    d, ratio = self._dir, self._ratio
                    with self._lock:
                        self.decoder.stats.decoded += 1
                        c.frames_rx += 1
                        if kind == MOTION_REPORT:  # (position, velocity, current)
                            p, v, i = r
                            if not self.gate.motion(d * p / ratio - self._zero, d * v / ratio, t):
                                return
                            tel.motor_position, tel.motor_velocity, tel.encoder_time = p, v, t
                            c.encoder_frames += 1
                            tel.current_measured, tel.iq_time = i, t
                            if self._effort_current:
                                c.effort_frames += 1
                        else:  # EFFORT_REPORT: (torque, state, error)
                            tau, state, error = r
                            a = d * tau * ratio
                            if not self.gate.effort(t, a, a):
                                return
                            tel.torque_estimate, tel.torque_time = tau, t
                            if not self._effort_current:
                                c.effort_frames += 1
                            tel.axis_state, tel.heartbeat_time = state, t
                            c.heartbeat_frames += 1
                            if t >= self._ignore_errors_until:
                                tel.axis_error = error
                    return
            elif len(data) == 8:
                a, b = _F2.unpack_from(data)
                if a - a == 0.0 and b - b == 0.0:  # both finite (inf - inf and NaN - NaN are NaN)
                    tel, c = self.telemetry, self.counters
                    with self._lock:
                        self.decoder.stats.decoded += 1
                        c.frames_rx += 1
                        if kind == MOTION_PAIR:
                            k = self._turn
                            if not self.gate.motion(a * k - self._zero, b * k, t):
                                return
                            s = self._scale
                            tel.motor_position, tel.motor_velocity = a * s, b * s
                            tel.encoder_time = t
                            c.encoder_frames += 1
                        else:
                            if not self.gate.effort(t, a * self._amp, b * self._amp):
                                return
                            tel.current_setpoint, tel.current_measured, tel.iq_time = a, b, t
                            if self._effort_current:
                                c.effort_frames += 1
                    return
        rejected = self.decoder.stats.rejected
        r = self._decode(arb_id, data, is_remote, is_extended, is_error)
        if r is None:
            channel = self._channel.get(arb_id)
            if channel is not None and self.decoder.stats.rejected > rejected:
                with self._lock:
                    self.gate.undecodable(channel, self.decoder.stats.last_reject_reason, t)
            return
        tel, c = self.telemetry, self.counters
        with self._lock:
            c.frames_rx += 1
            if not self._admit(r, t):
                return
            if r.position is not None:
                tel.motor_position, tel.motor_velocity, tel.encoder_time = r.position, r.velocity, t
                c.encoder_frames += 1
            if r.current is not None:
                if r.current_setpoint is not None:
                    tel.current_setpoint = r.current_setpoint
                tel.current_measured, tel.iq_time = r.current, t
                if self._effort_current:
                    c.effort_frames += 1
            if r.torque is not None:
                if r.torque_target is not None:
                    tel.torque_target = r.torque_target
                tel.torque_estimate, tel.torque_time = r.torque, t
                if not self._effort_current:
                    c.effort_frames += 1
            if r.state is not None:
                tel.axis_state, tel.heartbeat_time = r.state, t
                c.heartbeat_frames += 1
            elif not self._reports_state:
                tel.axis_state = 1 if self.enabled else 0
            if r.error is not None and t >= self._ignore_errors_until:
                tel.axis_error = r.error
            if r.bus_voltage is not None:
                tel.bus_voltage = r.bus_voltage
