"""Experiment event markers: the fields of ``friction_msgs/ExperimentEvent``.

An excitation program emits them (:mod:`friction_ros.core.experiment.excitation`); identification
reads them back from a bag to find its segments (plateaus, breakaway ramps). On an arm each event
names its joint in ``header.frame_id`` (:func:`event_joint_matches`).
"""

from __future__ import annotations

import math
import re
from typing import NamedTuple

START, END, ABORT = 0, 1, 2
EVENT_NAMES = {START: "START", END: "END", ABORT: "ABORT"}


class Event(NamedTuple):
    """A segment marker: ``event`` is START/END/ABORT, ``time`` in program (or record) seconds."""

    time: float
    program: str
    segment: str
    index: int
    event: int
    target: float = math.nan
    note: str = ""


def completed_segments(events: list[Event], key: str) -> list[tuple[Event, Event]]:
    """(START, END) pairs of the segments whose program or label contains ``key`` (aborted ones left out)."""
    out = []
    open_: dict[tuple[str, int], Event] = {}
    for e in events:
        if key not in e.program.lower() and key not in e.segment.lower():
            continue
        k = (e.program, e.index)
        if e.event == START:
            open_[k] = e
        elif e.event == END and k in open_:
            out.append((open_.pop(k), e))
        elif e.event == ABORT:
            open_.pop(k, None)
    return out


def event_joint_matches(frame_id: str, joint: str | None) -> bool:
    """Whether an event recorded with ``header.frame_id`` belongs to ``joint``.

    An experiment on several joints (``identification_experiment`` with ``joints``) stamps each
    event with the joint it is about in ``header.frame_id``; a single-joint experiment (and every
    bag recorded before) leaves it empty, and such an event belongs to any joint."""
    return not frame_id or joint is None or frame_id == joint


_SETTLE_NOTE = re.compile(r"settle=([0-9.eE+-]+)")
_LAG_NOTE = re.compile(r"\blag=([0-9.eE+-]+)")


def start_lag(event: Event) -> float:
    """The detection lag a breakaway ramp's START marker states (``lag=<N*m>``), else NaN."""
    m = _LAG_NOTE.search(event.note or "")
    return float(m.group(1)) if m else math.nan


def start_settle(event: Event, default: float) -> float:
    """The transient a plateau's START marker says to discard (``settle=<s>`` in its note) [s]."""
    m = _SETTLE_NOTE.search(event.note or "")
    return float(m.group(1)) if m else default
