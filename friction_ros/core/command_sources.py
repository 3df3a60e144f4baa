"""One command source per joint: which sources command each joint, told apart by the command's
``header.frame_id``.

The project's command publishers (compensating_controller, identification_experiment) put their
node's fully qualified name into ``header.frame_id`` of every ``joint_commands`` message, so a
plant or drive can tell who commands each joint without the middleware's message info. A joint
commanded by two sources within ``window`` seconds is in conflict: the follower applies zero
torque to it until one source has been alone for ``window`` (policy in README "Safety"). Several
controllers each commanding its own joints of one arm on one topic are no conflict. Sources
that leave ``frame_id`` empty count as one source ("").
"""

from __future__ import annotations

from dataclasses import dataclass, field


@dataclass
class JointSources:
    """The sources seen for one joint: name -> time last seen."""

    seen: dict[str, float] = field(default_factory=dict)
    conflict: bool = False


class CommandSources:
    """Per-joint source tracking; ``admit`` returns the joints in conflict among those commanded."""

    def __init__(self, joints, window: float = 0.5):
        self.joints = list(joints)
        self.window = float(window)
        self._by_joint = [JointSources() for _ in self.joints]
        self.started: list[tuple[str, list[str]]] = []  # (joint, sources) conflicts that began
        self.cleared: list[tuple[str, str]] = []  # (joint, remaining source) conflicts that ended

    def admit(self, source: str, indices, now: float) -> set[int]:
        """A command from ``source`` for the joints ``indices`` at time ``now`` [s]."""
        out = set()
        for i in indices:
            js = self._by_joint[i]
            js.seen[source] = now
            self._update(i, js, now)
            if js.conflict:
                out.add(i)
        return out

    def expire(self, now: float) -> None:
        """Forget sources not seen for ``window`` (clears conflicts when only one is left)."""
        for i, js in enumerate(self._by_joint):
            self._update(i, js, now)

    def in_conflict(self, i: int) -> bool:
        return self._by_joint[i].conflict

    def sources(self, i: int) -> list[str]:
        return sorted(self._by_joint[i].seen)

    def _update(self, i: int, js: JointSources, now: float) -> None:
        for name in [n for n, t in js.seen.items() if now - t > self.window]:
            del js.seen[name]
        conflict = len(js.seen) > 1
        if conflict and not js.conflict:
            self.started.append((self.joints[i], sorted(js.seen)))
        elif js.conflict and not conflict:
            self.cleared.append((self.joints[i], next(iter(js.seen), "")))
        js.conflict = conflict
