"""What friction-experiment prints after a run: segments, aborts, breakaways, the plateau map."""

from __future__ import annotations

from pathlib import Path


def summarize(bag: Path, joint: str, preset, events_topic: str, states_topic: str) -> str:
    """The text printed after a run: segments, aborts, breakaways, plateau map. ``preset``: the
    simulated joint's preset (name or Preset; None on a real joint) for the true friction column;
    a joint with a pendulum gravity load has none (its load changes along the plateaus)."""
    from friction_ros.core.identification.data.bag_loading import load_bag
    from friction_ros.core.identification.data.plateau_map import plateau_map

    data = load_bag(bag, topic=states_topic, joint=joint, events_topic=events_topic)
    ev = data.events
    starts = sum(e.event == 0 for e in ev)
    ends = sum(e.event == 1 for e in ev)
    aborts = [e for e in ev if e.event == 2]
    programs = list(dict.fromkeys(e.program for e in ev))
    lines = [
        f"joint {joint}: {data.n} joint states ({data.duration:.1f} s), {len(ev)} events: {starts} START, "
        f"{ends} END, {len(aborts)} ABORT; programs: {', '.join(programs) or '-'}"
    ]
    for e in aborts:
        lines.append(f"  ABORT {e.program}/{e.segment} at {e.time:.2f} s: {e.note}")
    brk = [e for e in ev if e.event == 1 and "breakaway" in e.program]
    if brk:
        lines.append(
            "breakaway torques [N*m]: " + ", ".join(f"{e.segment[-1]}{abs(e.target):.4f}" for e in brk)
        )
    if any("plateau" in e.program for e in ev) and not any(
        "plateau" in e.program and e.event == 1 for e in ev
    ):
        lines.append("plateau map: no plateau completed")
    elif any("plateau" in e.program for e in ev):
        truth = None
        if preset:
            import numpy as np

            from friction_ros.core.presets import load_preset

            truth_preset = load_preset(preset) if isinstance(preset, str) else preset
            p = truth_preset.params
            holding = p.gravity_force - p.load_torque  # the torque that holds a constant load
            if getattr(p, "gravity", 0.0):
                truth_preset = None  # a pendulum load: no constant holding torque

            def truth(v: float) -> float:
                # what a plateau measures on the simulated joint: joint-level friction + holding torque
                return float(truth_preset.joint_friction(np.array([v]))[0]) + holding

            if truth_preset is None:
                truth = None

        pm = plateau_map(bag, joint, topic=states_topic, events_topic=events_topic)
        lines.append(f"plateau map (first {pm.settle:g} s of each plateau discarded):")
        lines.append(pm.to_text(truth))
    return "\n".join(lines)
