"""Damage found while reading an MCAP file and the messages it cost.

A file is *damaged* when a part of it fails a check: a chunk whose CRC does not match or that
cannot be decompressed or parsed, a record whose length runs past its section, a summary, footer or
message index that is corrupt. Reading goes on past every such part. Each :class:`Problem` says
where and what; :func:`channel_loss` counts the messages that could not be read, per channel,
from the summary statistics when the summary is intact, else from the message indexes of the
damaged chunks, else the number is unknown (``None``). :func:`describe_loss` says it in one phrase.
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass
class Problem:
    """One damaged part of a file."""

    offset: int | None  # byte in the file where the damaged part starts
    text: str  # what is wrong and what reading did about it
    loses: bool  # messages may have been lost with it
    counts: dict[int, int] | None = None  # channel id -> messages it held (message indexes); None = unknown
    end: int | None = None  # byte where a run of unknown records ends (to merge the next one into it)
    span: tuple[int, int] | None = None  # log times of the first and last message it held [ns]

    def add_index(self, channel: int, n: int) -> None:
        """A message index record that followed the damaged part: it held ``n`` messages of ``channel``."""
        self.counts = self.counts or {}
        self.counts[channel] = self.counts.get(channel, 0) + n


def channel_loss(
    problems: list[Problem], expected: dict[int, int] | None, found: dict[int, int]
) -> dict[int | None, int | None]:
    """Messages lost per channel id (key None: channels unknown; value None: number unknown).

    ``expected``: messages per channel of the summary statistics (None when the summary is not
    usable); ``found``: messages per channel that were read.
    """
    if expected is not None:
        return {c: e - found.get(c, 0) for c, e in expected.items() if e > found.get(c, 0)}
    out: dict[int | None, int | None] = {}
    for p in problems:
        if not p.loses:
            continue
        if p.counts is None:
            out[None] = None
            continue
        for c, k in p.counts.items():
            out[c] = None if (c in out and out[c] is None) else out.get(c, 0) + k
    return out


def merge_loss(a: dict[str, int | None], b: dict[str, int | None]) -> dict[str, int | None]:
    """Per-topic losses of two files added (unknown stays unknown)."""
    out = dict(a)
    for t, k in b.items():
        out[t] = None if (k is None or (t in out and out[t] is None)) else out.get(t, 0) + k
    return out


def lost_total(lost: dict[str, int | None]) -> int | None:
    """All messages lost, None when any number is unknown."""
    return None if any(v is None for v in lost.values()) else sum(lost.values())


def describe_loss(lost: dict[str, int | None]) -> str:
    """``"37 messages lost (/joint_states 37)"``, or with unknown numbers ``"an unknown number of ..."``."""
    if not lost:
        return "no messages lost"
    total = lost_total(lost)
    parts = [t if k is None else f"{t} {k}" for t, k in sorted(lost.items())]
    head = (
        "an unknown number of messages lost" if total is None else f"{total} message{'s' * (total != 1)} lost"
    )
    return f"{head} ({', '.join(parts)})"
