"""Start and clear events of an axis's fault conditions (pure): every fault logged once each way.

:class:`FaultLog` watches two bit masks per control period — the conditions active now and the
faults latched (drive disabled until ``~/enable``) — and turns their changes into
:class:`FaultEvent` lines for the adapter's logger:

* a condition starts: ``"<kind>: <reason>"`` (plus the action taken, e.g. the drive disabled);
* a condition ends: ``"<kind> cleared after 0.52 s"`` (plus ``"; drive stays disabled until
  ~/enable"`` while the fault is still latched);
* a latched fault reset by ``~/enable`` after its condition ended: ``"<kind> fault reset by ~/enable"``.

A kind may have a hold time: it counts as cleared only after it has been absent that long, so a
flag that toggles every period (a torque limiter at work) gives one line per episode, not per period.
Events carry their level (``"error"``, ``"warning"``, ``"info"``) and time.
"""

from __future__ import annotations

from typing import NamedTuple

# Same values as friction_msgs/msg/DriveState FAULT_* (checked by a test).
FAULT_NONE = 0
FAULT_TELEMETRY_STALE = 1
FAULT_DRIVE_ERROR = 2
FAULT_COMMAND_WATCHDOG = 4
FAULT_COMMAND_REJECTED = 8
FAULT_LIMIT = 16
FAULT_BUS = 32
FAULT_TELEMETRY_IMPLAUSIBLE = 64
LATCHING = FAULT_TELEMETRY_STALE | FAULT_DRIVE_ERROR | FAULT_BUS | FAULT_TELEMETRY_IMPLAUSIBLE

FAULT_NAMES = {
    FAULT_TELEMETRY_STALE: "telemetry_stale",
    FAULT_DRIVE_ERROR: "drive_error",
    FAULT_COMMAND_WATCHDOG: "command_watchdog",
    FAULT_COMMAND_REJECTED: "command_rejected",
    FAULT_LIMIT: "limit",
    FAULT_BUS: "bus",
    FAULT_TELEMETRY_IMPLAUSIBLE: "telemetry_implausible",
}


# Held kinds count as cleared only after being absent this long (one log line per episode).
FAULT_HOLD = {FAULT_LIMIT: 1.0}
DISABLE_ACTION = "drive disabled (zero torque, idle) until ~/enable"


def fault_text(flags: int) -> str:
    return ",".join(name for bit, name in FAULT_NAMES.items() if flags & bit) or "none"


class FaultEvent(NamedTuple):
    t: float
    level: str  # "error" | "warning" | "info"
    kind: str
    text: str


class FaultLog:
    """One instance per axis; ``update`` once per control period (caller holds any lock)."""

    def __init__(self, names: dict[int, str], hold: dict[int, float] | None = None):
        self.names = dict(names)
        self.hold = dict(hold or {})
        self.active = 0  # bits whose condition is active (after hold)
        self.latched = 0
        self.since: dict[int, float] = {}  # start time of each active condition
        self._seen: dict[int, float] = {}  # last time a held condition was present
        self._held = tuple(b for b in self.names if self.hold.get(b, 0.0))  # kinds with a hold time
        self.starts: dict[int, int] = dict.fromkeys(names, 0)  # episodes per kind

    def update(
        self, t: float, active: int, latched: int, reasons: dict[int, str], action: str = ""
    ) -> list[FaultEvent]:
        """Events for the change from the previous call. ``reasons[bit]`` describes a starting
        condition; ``action`` is appended to the start line of a condition that also latched now."""
        if active == self.active and latched == self.latched:  # no change: no event (most periods)
            for bit in self._held:
                if active & bit:
                    self._seen[bit] = t
            return []
        events: list[FaultEvent] = []
        for bit, name in self.names.items():
            now_on = bool(active & bit)
            if now_on:
                self._seen[bit] = t
            was_on = bool(self.active & bit)
            held = self.hold.get(bit, 0.0)
            if now_on and not was_on:
                self.active |= bit
                self.since[bit] = t
                self.starts[bit] += 1
                text = f"{name}: {reasons.get(bit, 'active')}"
                level = "warning"
                if latched & bit and not self.latched & bit:
                    level = "error"
                    if action:
                        text += f"; {action}"
                events.append(FaultEvent(t, level, name, text))
            elif was_on and not now_on and t - self._seen.get(bit, t) >= held:
                self.active &= ~bit
                end = self._seen.get(bit, t) if held else t  # a held condition ended when last seen
                text = f"{name} cleared after {_duration(end - self.since.pop(bit, t))}"
                if latched & bit:
                    text += "; drive stays disabled until ~/enable"
                events.append(FaultEvent(t, "info", name, text))
            elif latched & bit and not self.latched & bit and not now_on and not was_on:
                # latched without a lasting condition (e.g. a one-off report): start line
                self.starts[bit] += 1
                text = f"{name}: {reasons.get(bit, 'fault')}"
                if action:
                    text += f"; {action}"
                events.append(FaultEvent(t, "error", name, text))
            if self.latched & bit and not latched & bit and not now_on:
                events.append(FaultEvent(t, "info", name, f"{name} fault reset by ~/enable"))
        self.latched = latched
        return events


def _duration(s: float) -> str:
    return f"{s * 1e3:.0f} ms" if s < 1.0 else f"{s:.2f} s"
