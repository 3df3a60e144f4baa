"""QoS profiles as rosbag2 stores them (``offered_qos_profiles``), without rclpy.

A profile is a plain dict in the metadata version 9 string dialect::

    {"history": "keep_last", "depth": 10, "reliability": "reliable", "durability": "volatile",
     "deadline": {"sec": 0, "nsec": 0}, "lifespan": {...}, "liveliness": "automatic",
     "liveliness_lease_duration": {...}, "avoid_ros_namespace_conventions": False}

:func:`dump_qos` gives the YAML string written into MCAP channel metadata; :func:`parse_qos` reads both
the v9 strings and the older integer enums (v8 and earlier).
"""

from __future__ import annotations

import yaml

from friction_ros.core.yaml_files import parse_yaml

from .errors import BagError

# rmw enum values (rmw/types.h) <-> v9 names
_ENUMS = {
    "history": ["system_default", "keep_last", "keep_all", "unknown"],
    "reliability": ["system_default", "reliable", "best_effort", "unknown", "best_available"],
    "durability": ["system_default", "transient_local", "volatile", "unknown", "best_available"],
    "liveliness": ["system_default", "automatic", "", "manual_by_topic", "unknown", "best_available"],
}
_TIMES = ("deadline", "lifespan", "liveliness_lease_duration")


def make_qos(
    reliability: str = "reliable",
    durability: str = "volatile",
    history: str = "keep_last",
    depth: int = 10,
) -> dict:
    """A v9 profile dict; deadline/lifespan/lease 0 (= default/infinite)."""
    return {
        "history": history,
        "depth": int(depth),
        "reliability": reliability,
        "durability": durability,
        "deadline": {"sec": 0, "nsec": 0},
        "lifespan": {"sec": 0, "nsec": 0},
        "liveliness": "automatic",
        "liveliness_lease_duration": {"sec": 0, "nsec": 0},
        "avoid_ros_namespace_conventions": False,
    }


def normalize_qos(profile: dict) -> dict:
    """Return a v9 dict from a v8 (integer enums) or v9 profile dict."""
    out = make_qos()
    for key, names in _ENUMS.items():
        v = profile.get(key, out[key])
        if isinstance(v, int) and not isinstance(v, bool):
            v = names[v] if 0 <= v < len(names) and names[v] else "unknown"
        out[key] = str(v).lower()
    out["depth"] = int(profile.get("depth", 0) or 0)
    for key in _TIMES:
        t = profile.get(key) or {}
        out[key] = {"sec": int(t.get("sec", 0)), "nsec": int(t.get("nsec", 0))}
    out["avoid_ros_namespace_conventions"] = bool(profile.get("avoid_ros_namespace_conventions", False))
    return out


def dump_qos(profiles: list[dict]) -> str:
    """YAML text of a list of profiles (v9 dialect), as in MCAP channel metadata."""
    return yaml.safe_dump([normalize_qos(p) for p in profiles], sort_keys=False).strip() if profiles else ""


def parse_qos(text: str | list | None) -> list[dict]:
    """Parse ``offered_qos_profiles`` (YAML string or list, any dialect) into v9 dicts."""
    if not text:
        return []
    try:
        items = parse_yaml(text, "offered_qos_profiles") if isinstance(text, str) else text
    except ValueError as exc:
        raise BagError(str(exc)) from None
    if not isinstance(items, list) or not all(isinstance(i, dict) for i in items):
        raise BagError(f"offered_qos_profiles must be a list of mappings, got {type(items).__name__}")
    return [normalize_qos(i) for i in items]
