"""Static friction map straight from an identification bag (pure core, no rclpy).

``plateau_map(bag_or_path, joint)`` reads the joint states and the ``experiment_events`` markers of a
bag recorded by ``friction-experiment`` (or any bag with ``plateau`` START/END markers) and returns
one row per constant-velocity plateau: mean velocity and torque with their spread (standard
deviation over the plateau, first ``settle`` seconds discarded), plus :meth:`PlateauMap.aggregate`,
the AI friction chapter "mean over the repeats per set-point" with the spread across repeats.

It reuses the offline fitting's data preparation (:func:`friction_ros.core.identification.data.bag_loading.load_bag`:
uniform grid, Savitzky-Golay velocity from position, torque from ``effort``) and its event-based
plateau extraction (:func:`friction_ros.core.identification.data.plateau_detection.find_plateaus`), so the map printed
after an experiment is exactly what ``friction-fit`` fits. ``settle`` defaults to what each
plateau's START note says (``settle=<s>``, sized per plateau by the runner), else AI friction chapter's 0.2 s.

``breakaway_torques(bag_or_path)`` lists the breakaway torques the runner detected (END events of
``breakaway`` segments carry the torque in ``target``), ``experiment_events(...)`` all markers.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass, field

import numpy as np

from friction_ros.core.experiment.events import ABORT, END, START, Event, completed_segments, start_settle
from friction_ros.core.identification.data.bag_loading import load_bag
from friction_ros.core.identification.data.plateau_detection import find_plateaus
from friction_ros.core.identification.data.records import ExcitationError


@dataclass
class PlateauRow:
    """One plateau: set-point (``target``), measured means and spreads (SI)."""

    index: int
    segment: str
    target: float
    velocity: float
    velocity_std: float
    torque: float
    torque_std: float
    n: int
    t_start: float
    t_end: float


@dataclass
class PlateauMap:
    """Rows of :class:`PlateauRow` plus array views; ``aggregate()`` groups the repeats."""

    rows: list[PlateauRow]
    joint: str
    settle: float
    source: str = ""
    aborted: list[str] = field(default_factory=list)

    def __len__(self) -> int:
        return len(self.rows)

    def column(self, name: str) -> np.ndarray:
        return np.array([getattr(r, name) for r in self.rows], dtype=float)

    @property
    def velocity(self) -> np.ndarray:
        return self.column("velocity")

    @property
    def torque(self) -> np.ndarray:
        return self.column("torque")

    @property
    def torque_std(self) -> np.ndarray:
        return self.column("torque_std")

    def aggregate(self) -> list[dict]:
        """Per set-point: mean velocity/torque over the repeats, spread across repeats, count."""
        groups: dict[float, list[PlateauRow]] = {}
        for r in self.rows:
            key = round(r.target, 9) if math.isfinite(r.target) else round(r.velocity, 3)
            groups.setdefault(key, []).append(r)
        out = []
        for key in sorted(groups):
            g = groups[key]
            tq = np.array([r.torque for r in g])
            vv = np.array([r.velocity for r in g])
            out.append(
                {
                    "target": key,
                    "velocity": float(vv.mean()),
                    "torque": float(tq.mean()),
                    "torque_spread": float(tq.std(ddof=1)) if len(g) > 1 else float(g[0].torque_std),
                    "repeats": len(g),
                }
            )
        return out

    def to_text(self, truth=None) -> str:
        """A table; ``truth(v) -> torque`` adds the reference friction and the relative error."""
        head = f"{'segment':>18} {'v [rad/s]':>11} {'sd v':>8} {'tau [N*m]':>10} {'sd tau':>8} {'n':>6}"
        if truth is not None:
            head += f" {'truth':>9} {'error':>8}"
        lines = [head]
        for r in self.rows:
            line = (
                f"{r.segment:>18} {r.velocity:>+11.4f} {r.velocity_std:>8.4f} {r.torque:>+10.4f} "
                f"{r.torque_std:>8.4f} {r.n:>6d}"
            )
            if truth is not None:
                ref = float(truth(r.velocity))
                line += f" {ref:>+9.4f} {100 * (r.torque - ref) / ref:>+7.2f}%"
            lines.append(line)
        return "\n".join(lines)


def _path(bag_or_path) -> str:
    p = getattr(bag_or_path, "path", bag_or_path)
    return os.fspath(p)


def _settle_from(events: list[Event]) -> float | None:
    vals = [start_settle(e, math.nan) for e in events if e.event == START]
    vals = [v for v in vals if math.isfinite(v)]
    return max(vals) if vals else None


def experiment_events(
    bag_or_path, joint: str | None = None, events_topic: str = "/experiment_events"
) -> list[Event]:
    """All ExperimentEvent markers of the bag (times in s from the first joint state)."""
    return load_bag(_path(bag_or_path), joint=joint, events_topic=events_topic).events


def plateau_map(
    bag_or_path,
    joint: str | None = None,
    *,
    topic: str = "/joint_states",
    events_topic: str = "/experiment_events",
    settle: float | None = None,
) -> PlateauMap:
    """Plateau means and spreads from the START/END markers of a bag (see the module docstring).

    Raises :class:`~friction_ros.core.identification.data.records.ExcitationError` (a ParameterError) with a
    clear message when the bag is unreadable, lacks the topic/joint, or has no plateau markers.
    """
    path = _path(bag_or_path)
    data = load_bag(path, topic=topic, joint=joint, events_topic=events_topic)
    pairs = completed_segments(data.events, "plateau")
    if not pairs:
        raise ExcitationError(
            f"bag {path}: no plateau START/END markers on {events_topic}: record the 'plateaus' "
            "program with friction-experiment (or use friction-fit's automatic plateau detection)"
        )
    plateaus = find_plateaus(data, settle=settle)
    rows = []
    for p in plateaus:
        mid = 0.5 * (p.t_start + p.t_end)
        match = next(((s, e) for s, e in pairs if s.time <= mid <= e.time), None)
        s = match[0] if match else None
        rows.append(
            PlateauRow(
                s.index if s else -1,
                s.segment if s else "plateau",
                s.target if s else math.nan,
                p.velocity,
                p.velocity_std,
                p.torque,
                p.torque_std,
                p.n,
                p.t_start,
                p.t_end,
            )
        )
    aborted = [f"{e.segment}: {e.note}" for e in data.events if e.event == ABORT]
    shown = settle if settle is not None else (_settle_from(data.events) or 0.2)  # the longest one
    return PlateauMap(rows, joint or "", shown, path, aborted)


def breakaway_torques(
    bag_or_path, joint: str | None = None, events_topic: str = "/experiment_events"
) -> list[tuple[str, float]]:
    """(segment, breakaway torque N*m) from the END markers of ``breakaway`` segments."""
    return [
        (e.segment, e.target)
        for e in experiment_events(bag_or_path, joint, events_topic)
        if e.event == END and "breakaway" in e.program and math.isfinite(e.target)
    ]
