"""A chunk's message indexes checked against the chunk before they are trusted.

The message index records that follow a chunk say where each message lies in it; they carry no CRC.
:func:`index_matches` accepts them only when every entry points to a message record of its channel
with the entry's log time, no two records overlap, and the bytes between the indexed messages hold
no other message record (the index is complete). Otherwise the chunk, whose CRC was checked, is read
by a linear scan of its records.
"""

from __future__ import annotations

import numpy as np

from .mcap_records import MESSAGE, OPHDR


def _u64(win: np.ndarray, pos: np.ndarray) -> np.ndarray:
    return np.ascontiguousarray(win[pos]).view("<u8")[:, 0].astype(np.int64)


def index_matches(buf: bytes, index: dict[int, np.ndarray]) -> bool:
    """The message indexes (channel id -> entries (log time, offset)) describe the chunk ``buf`` exactly."""
    if -1 in index:  # a message index record that did not parse
        return False
    n = len(buf)
    arr = np.frombuffer(buf, np.uint8)
    win = np.lib.stride_tricks.sliding_window_view(arr, 8) if n >= 8 else None
    offs_all, ends_all = [], []
    for ch, e in index.items():
        if not len(e):
            continue
        offs = e[:, 1]
        if win is None or offs.min() < 0 or offs.max() + 31 > n:
            return False
        if np.any(arr[offs] != MESSAGE) or np.any(
            (arr[offs + 9] | (arr[offs + 10].astype(np.int64) << 8)) != ch
        ):
            return False
        ln = _u64(win, offs + 1)
        if np.any(ln < 22) or np.any(ln > n) or np.any(_u64(win, offs + 15) != e[:, 0]):
            return False
        offs_all.append(offs)
        ends_all.append(offs + 9 + ln)
    if not offs_all:
        return _no_message_between(buf, 0, n)
    offs, ends = np.concatenate(offs_all), np.concatenate(ends_all)
    if len(offs_all) > 1 or np.any(offs[1:] < offs[:-1]):  # one channel in write order needs no sort
        order = np.argsort(offs, kind="stable")
        offs, ends = offs[order], ends[order]
    nxt = np.append(offs[1:], n)
    if np.any(ends > nxt):  # overlapping or repeated entries
        return False
    gaps = [(0, int(offs[0]))] + [(int(a), int(b)) for a, b in zip(ends[ends < nxt], nxt[ends < nxt])]
    return all(_no_message_between(buf, a, b) for a, b in gaps if a < b)


def _no_message_between(buf: bytes, pos: int, end: int) -> bool:
    """The bytes from ``pos`` to ``end`` are whole records, none of them a message."""
    while pos < end:
        if pos + 9 > end:
            return False
        op, ln = OPHDR.unpack_from(buf, pos)
        if op == MESSAGE or pos + 9 + ln > end:
            return False
        pos += 9 + ln
    return True
