"""Content digest of a bag: what was recorded, independent of when it was received.

Two recordings of the same deterministic (lockstep) run differ in their log times (wall clock at
the recorder), in how often a waiting plant re-sent its pending state, and in the CDR padding
bytes (uninitialised by the serialiser), but not in the messages' values. :func:`content_digest`
decodes every message and hashes, per topic in name order, the field values in recording order
with exact repeats of an already seen message removed (a re-send has the same stamp and data).
Equal digests mean the same message values on the same topics.
"""

from __future__ import annotations

import hashlib
import os
from collections.abc import Iterable

import numpy as np

from .reader import read_bag


def _row_keys(fields: dict[str, np.ndarray], n: int) -> list[bytes]:
    cols = []
    for name in sorted(fields):
        col = fields[name]
        if col.dtype == object:
            cols.append([repr(x).encode() for x in col])
        else:
            arr = np.ascontiguousarray(col).reshape(n, -1)
            cols.append([name.encode() + arr[i].tobytes() for i in range(n)])
    return [hashlib.sha256(b"\0".join(parts)).digest() for parts in zip(*cols)] if cols else []


def content_digest(
    path: str | os.PathLike, topics: Iterable[str] | None = None
) -> tuple[str, dict[str, int]]:
    """SHA-256 hex digest of the bag's distinct messages and the count of distinct messages per topic."""
    bag = read_bag(path, list(topics) if topics is not None else None)
    h = hashlib.sha256()
    counts: dict[str, int] = {}
    for topic in sorted(bag.topics):
        td = bag[topic]
        seen: set[bytes] = set()
        h.update(topic.encode() + b"\0")
        for key in _row_keys(td.fields, len(td)):
            if key not in seen:
                seen.add(key)
                h.update(key)
        counts[topic] = len(seen)
    return h.hexdigest(), counts
