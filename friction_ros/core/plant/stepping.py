"""The plant_simulator's bookkeeping without ROS: N joint plants stepped one control period at a time.

Two ways to advance (the node's ``mode``):

* lockstep: the plants advance exactly one period ``dt`` once every joint has an answer stamped with
  the pending state's stamp ``t_ns``; answers may come in several messages (merged), a second answer
  for an already answered joint or a command with another stamp is a duplicate (ignored, counted);
* realtime: every tick applies each joint's newest command, or zero torque when it is older than
  ``command_timeout``; a tick whose previous state was not answered by every joint counts as missed.

Commands are admitted by :func:`~friction_ros.core.input_gate.select_command` (one joint) or
:func:`~friction_ros.core.input_gate.select_joint_commands` (several), with the plausibility bound
``min(max_effort, MAX_COMMAND / |k|)`` per joint (``k``: the plant's command scale, plant unit per
N*m): an implausible effort becomes zero torque, a message for no joint of ours is ignored. The
core returns log events ``(level, text)`` (levels of :mod:`friction_ros.core.joint_channel`).
"""

from __future__ import annotations

import threading

from friction_ros.core.input_gate import RejectionLog, select_command, select_joint_commands
from friction_ros.core.joint_channel import WARN
from friction_ros.core.plant.servo import MAX_COMMAND


class PlantStepper:
    """Pending state, answers per joint and command admission of N plants (module docstring).

    ``plants``: core plants (``step(command, dt)``, ``command_scale``, ``time``); ``joints``: their
    names in state order; ``dt`` [s]: the control period; ``initial_position`` [rad or m].
    """

    def __init__(self, joints, plants, dt: float, initial_position: float, log_period: float):
        self.joints = list(joints)
        self.plants = list(plants)
        self.scales = [pl.command_scale for pl in self.plants]
        n = self.n = len(self.joints)
        self.index = {j: i for i, j in enumerate(self.joints)}
        self.dt = dt
        self.dt_ns = int(round(dt * 1e9))
        self.lock = threading.Lock()  # realtime: commands arrive between ticks
        self.command = [0.0] * n
        self.command_wall = [float("-inf")] * n
        self.commands_rejected = 0  # implausible effort: zero torque applied instead
        self.rejected_by_joint = [0] * n
        self.commands_ignored = 0  # no joint of ours / malformed (logged) or a lockstep duplicate
        self.unknown_names = 0  # names in joint_commands that are not joints of this node (ignored)
        what = f"joint_commands for {self.joints[0]}" if n == 1 else "joint_commands"
        self.rejections = RejectionLog(what, log_period)
        self.steps = 0
        self.missed = 0
        for plant in self.plants:
            plant.reset(position=initial_position)
        self.t_ns = 0
        self.answered_ns = [-1] * n
        self.answers: list[float | None] = [None] * n  # lockstep: the pending state's commands
        self.n_answers = 0
        self.next_clock_ns = 0
        #: the state to publish: positions, velocities, efforts (joints order)
        self.pending = (*([initial_position] * n), *([0.0] * n), *([0.0] * n))

    # -- commands -------------------------------------------------------------------------------------
    def limit(self, scale: float, max_effort: float) -> float:
        """Plausibility bound [N*m]: ``max_effort`` and the plant's own command range (MAX_COMMAND)."""
        return min(max_effort, MAX_COMMAND / abs(scale)) if scale else max_effort

    def select(self, msg, max_effort: float, now: float) -> tuple[dict[int, float] | None, list]:
        """``({joint index: effort}, log events)`` of a command (rejected efforts: 0.0); efforts None
        when the whole message is ignored. ``now``: monotonic wall time [s] (log rate limit)."""
        events: list[tuple[int, str]] = []
        if self.n == 1:
            effort, reason, detail = select_command(
                msg, self.joints[0], self.limit(self.scales[0], max_effort)
            )
            if effort is not None:
                return {0: effort}, events
            rejections = [(None if reason in ("wrong_joint", "wrong_length") else 0, reason, detail)]
            efforts: dict[int, float] = {}
        else:
            efforts, rejections, unknown = select_joint_commands(
                msg, self.index, [self.limit(k, max_effort) for k in self.scales]
            )
            self.unknown_names += unknown
        for i, reason, detail in rejections:
            line = self.rejections.reject(reason, detail, now)
            if i is None:
                self.commands_ignored += 1  # not a command for our joints: ignored
                if line:
                    events.append((WARN, f"{line}; ignored"))
                return None, events
            self.commands_rejected += 1
            self.rejected_by_joint[i] += 1
            if line:
                events.append((WARN, f"{line}; applying zero torque instead"))
            efforts[i] = 0.0
        return efforts, events

    def answer(self, stamp_ns: int, efforts: dict[int, float]) -> bool:
        """Lockstep: take the answers to the pending state; True when every joint has answered and
        the plants advanced one period (the new pending state is to be published)."""
        if stamp_ns != self.t_ns:
            self.commands_ignored += 1  # duplicate or stale answer
            return False
        answers = self.answers
        new = 0
        for i, e in efforts.items():
            if answers[i] is None:
                answers[i] = e
                new += 1
        if not new:
            self.commands_ignored += 1  # every joint it names was answered already: duplicate
            return False
        self.n_answers += new
        if self.n_answers < self.n:
            return False  # wait for the other joints' commands
        self.advance(answers)
        self.answers = [None] * self.n
        self.n_answers = 0
        return True

    def hold(self, stamp_ns: int, efforts: dict[int, float], now: float) -> None:
        """Realtime: keep each named joint's newest command (``now``: monotonic wall time [s]);
        ``stamp_ns`` (0: unstamped) is the state it answers."""
        with self.lock:
            for i, e in efforts.items():
                self.command[i] = e
                self.command_wall[i] = now
                if stamp_ns:
                    self.answered_ns[i] = stamp_ns

    def fresh(self, now: float, timeout: float) -> list[bool]:
        """Realtime: per joint, whether its newest command is at most ``timeout`` s old."""
        with self.lock:
            return [now - w <= timeout for w in self.command_wall]

    # -- stepping -------------------------------------------------------------------------------------
    def advance(self, torques) -> None:
        """Step every plant one period with the joint torques [N*m] (times each command scale)."""
        dt = self.dt
        if self.n == 1:
            m = self.plants[0].step(torques[0] * self.scales[0], dt)
            self.pending = (m.position, m.velocity, m.effort)
        else:
            ms = [pl.step(t * k, dt) for pl, t, k in zip(self.plants, torques, self.scales, strict=True)]
            self.pending = (
                *(m.position for m in ms),
                *(m.velocity for m in ms),
                *(m.effort for m in ms),
            )
        self.steps += 1
        self.t_ns += self.dt_ns

    def tick(self, now: float, timeout: float, clock) -> None:
        """Realtime: advance with each joint's fresh command (zero when stale), then stamp the new
        state with ``clock()`` [ns]."""
        with self.lock:
            torques = [
                c if now - w <= timeout else 0.0 for c, w in zip(self.command, self.command_wall, strict=True)
            ]
            if self.steps and any(a != self.t_ns for a in self.answered_ns):
                self.missed += 1  # a command for the last published state did not arrive in time
        self.advance(torques)
        self.t_ns = clock()

    def clock_due(self, clock_period_ns: int) -> bool:
        """Lockstep ``/clock``: True when the pending state's time is one to publish (every
        ``clock_period_ns`` of simulated time, 0: every state); books the next one."""
        if self.t_ns < self.next_clock_ns:
            return False
        self.next_clock_ns = self.t_ns + clock_period_ns
        return True
