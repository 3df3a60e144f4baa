"""Health of one drive axis for a diagnostics status: level, one-line message and values."""

from __future__ import annotations

import math

from friction_ros.core.can.axis import DriveAxis
from friction_ros.core.can.faults import LATCHING, fault_text

OK, WARN, ERROR = 0, 1, 2  # the levels of diagnostic_msgs/DiagnosticStatus


class AxisHealth:
    """Status of one :class:`DriveAxis`; frame and command rates are taken between two reports."""

    def __init__(self):
        self._prev: tuple[float, int, int, int, int] | None = None

    def report(self, axis: DriveAxis, flags: int, now: float) -> tuple[int, str, dict]:
        """Level (:data:`OK`, :data:`WARN`, :data:`ERROR`), message and values of ``axis``, whose
        last period raised fault ``flags``, at monotonic time ``now``."""
        c, st = axis.counters, axis.decode_stats
        cur = (now, c.frames_rx, c.frames_tx, c.encoder_frames, c.commands)
        rates = [math.nan] * 4
        if self._prev is not None and now > self._prev[0]:
            dt = now - self._prev[0]
            rates = [(a - b) / dt for a, b in zip(cur[1:], self._prev[1:])]
        self._prev = cur
        latched = axis.latched
        if latched & LATCHING:
            level, message = ERROR, f"fault: {axis.fault_reason}"
        elif flags:
            level, message = WARN, f"{'enabled' if axis.enabled else 'disabled'}, flags {fault_text(flags)}"
        elif axis.telemetry.encoder_time is None:
            level, message = WARN, "disabled, no telemetry yet"
        else:
            level, message = OK, "enabled" if axis.enabled else "disabled (telemetry ok)"
        values = {
            "enabled": axis.enabled,
            "fault_flags": fault_text(flags),
            "latched_faults": fault_text(latched),
            "fault_reason": axis.fault_reason,
            "rx_frame_rate_hz": rates[0],
            "tx_frame_rate_hz": rates[1],
            "encoder_rate_hz": rates[2],
            "command_rate_hz": rates[3],
            "frames_decoded": st.decoded,
            "frames_ignored": st.ignored,
            "frames_rejected": st.rejected,
            "last_reject_reason": st.last_reject_reason,
            "commands_rejected": c.commands_rejected,
            "telemetry_rejected": axis.gate.total,
            **axis.gate.log.values("telemetry_rejected."),
            "telemetry_last_rejection": axis.gate.last_detail,
            "telemetry_timeout_ms": axis.cfg.stale_after * 1e3,
            "telemetry_age_max_ms": axis.take_age_max() * 1e3,
            "telemetry_age_max_total_ms": c.telemetry_age_max * 1e3,
            "stale_faults": c.stale_faults,
            "telemetry_late_periods": c.late_periods,
            "watchdog_trips": c.watchdog_trips,
            "fault_trips": c.fault_trips,
            "limit_hits": c.limit_hits,
            "bus_faults": c.bus_errors,
            "axis_state": axis.telemetry.axis_state,
            "axis_error": f"0x{axis.telemetry.axis_error:X}",
        }
        return level, message, values
