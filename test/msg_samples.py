"""Deterministic sample values for every field of a ROS message class (used by round-trip tests)."""

from __future__ import annotations

import math

_SCALARS = {
    "boolean": lambda i: i % 2 == 1,
    "octet": lambda i: bytes([i % 256]),
    "uint8": lambda i: (37 * i + 11) % 256,
    "int8": lambda i: (37 * i + 11) % 128 - 64,
    "uint16": lambda i: (4099 * i + 7) % 65536,
    "int16": lambda i: (4099 * i + 7) % 32768 - 16384,
    "uint32": lambda i: (2654435761 * i + 3) % 2**32,
    "int32": lambda i: (2654435761 * i + 3) % 2**31 - 2**30,
    "uint64": lambda i: (11400714819323198485 * i + 5) % 2**64,
    "int64": lambda i: (11400714819323198485 * i + 5) % 2**63 - 2**62,
    "float": lambda i: float(i) * 0.5 - 3.25,
    "double": lambda i: math.pi * (i + 1) * (-1) ** i,
    "string": lambda i: f"value-{i}-\u00b5",
}


def fill(msg, seed: int = 1):
    """Set every field of ``msg`` (recursively) to a value derived from ``seed`` and the field index."""
    for k, (name, ftype) in enumerate(msg.get_fields_and_field_types().items()):
        i = seed * 31 + k
        if ftype.startswith("sequence<") or ftype.endswith("]"):
            base = ftype[len("sequence<") : -1] if ftype.startswith("sequence<") else ftype.split("[")[0]
            base = base.split(",")[0]
            if base in _SCALARS:
                setattr(msg, name, [_SCALARS[base](i + j) for j in range(3)])
            continue
        if ftype in _SCALARS:
            setattr(msg, name, _SCALARS[ftype](i))
        else:
            fill(getattr(msg, name), i)
    return msg


def diff(a, b, path: str = "") -> list[str]:
    """Return the list of field paths where ``a`` and ``b`` differ (empty when equal)."""
    out = []
    for name in a.get_fields_and_field_types():
        va, vb = getattr(a, name), getattr(b, name)
        if hasattr(va, "get_fields_and_field_types"):
            out += diff(va, vb, f"{path}{name}.")
        elif list(va) != list(vb) if hasattr(va, "__len__") and not isinstance(va, str) else va != vb:
            out.append(f"{path}{name}: {va!r} != {vb!r}")
    return out
