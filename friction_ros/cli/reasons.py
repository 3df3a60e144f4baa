"""Long reasons in console tables: a short marker in the cell, each distinct reason once under the table."""

from __future__ import annotations

import numbers
from collections.abc import Mapping


def footnotes(reasons: Mapping[str, str], strip: str = "") -> tuple[dict[str, str], list[str]]:
    """``label -> reason`` to (``label -> marker`` such as ``[1]``, lines ``[1] label, label: reason``).

    Labels with the same reason share one marker and one line; ``strip`` is a prefix left out of
    the line (``refused: `` when the cell already says refused). Empty reasons get no marker.
    """
    groups: dict[str, list[str]] = {}
    for label, reason in reasons.items():
        if reason:
            groups.setdefault(reason, []).append(label)
    markers: dict[str, str] = {}
    lines: list[str] = []
    for k, (reason, labels) in enumerate(groups.items(), start=1):
        for label in labels:
            markers[label] = f"[{k}]"
        lines.append(f"[{k}] {', '.join(labels)}: {reason.removeprefix(strip)}")
    return markers, lines


def grouped(reasons: Mapping[str, str]) -> list[tuple[str, str]]:
    """``(labels joined by ', ', reason)`` for each distinct reason, in first-seen order."""
    groups: dict[str, list[str]] = {}
    for label, reason in reasons.items():
        groups.setdefault(reason, []).append(label)
    return [(", ".join(labels), reason) for reason, labels in groups.items()]


def format_values(values: Mapping[str, object]) -> str:
    """``{'p': 200.0, 'd': 0.15}`` -> ``p 200, d 0.15`` (numbers in ``%g``, nested dicts in
    parentheses); for console lines where a Python dict repr would be noise."""
    parts = []
    for key, value in values.items():
        if isinstance(value, Mapping):
            parts.append(f"{key} ({format_values(value)})")
        elif isinstance(value, bool) or not isinstance(value, numbers.Real):
            parts.append(f"{key} {value}")
        else:
            parts.append(f"{key} {value:g}")
    return ", ".join(parts)
