"""Input plausibility gate for joint samples: stamps, jumps and magnitudes (pure, no rclpy).

Every node that consumes ``joint_states`` (controller, estimator) or ``joint_commands`` (plant) runs
its input through this module, so one bad message is rejected with a reason, counted and logged
(rate-limited) while the node keeps working on the good ones.

Joint states (:class:`JointInputGate`), in order:

``wrong_joint``   the joint is not in ``name`` (or an unnamed message has != 1 position)
``wrong_length``  ``position`` (and ``velocity``/``effort`` when given or needed) does not have one
                  value per name
``not_finite``    NaN/inf position, velocity or effort
``out_of_range``  ``|position| > max_position``, ``|velocity| > max_velocity``, ``|effort| > max_effort``
``old_stamp``     stamp older than the last accepted one (an equal stamp is a *duplicate*: a lockstep
                  re-send, not a rejection)
``future_stamp``  stamp more than ``max_stamp_lead`` ahead of the expected one, ``S + (now - A)``
                  (S, A: stamp and node-clock arrival of the last accepted sample; before the first
                  one: the node clock ``now``, when it is known)
``jump``          ``|position - last accepted| > max_velocity * max(stamp difference, period)``

A stamp of 0 means *unstamped*: the node's receive time is used instead (counted as ``unstamped``).
Rejected samples never reach the caller's state. ``resync_samples`` consecutive rejected samples
that are consistent with each other (increasing stamps, no jump between them) re-synchronise the
gate: the last of them is accepted as the new reference (a genuine clock jump, re-homing or a bag
loop is adopted instead of freezing the node forever). Per sample the cost is a few comparisons.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

from friction_ros.core.validation import ParameterError, check_int, check_real

#: Plausibility bound of a joint torque [N*m]: a command or effort above it is not a torque but a
#: bug. The plant simulator rejects commands above it; the controller's default torque clamp.
PLAUSIBLE_EFFORT = 1.0e6

#: Defaults of the gate (node parameters ``input_gate.<key>``).
GATE_DEFAULTS: dict[str, Any] = {
    "max_position": 1.0e9,
    "max_velocity": 1.0e3,
    "max_effort": PLAUSIBLE_EFFORT,
    "max_stamp_lead": 0.5,
    "resync_samples": 10,
    "log_period": 1.0,
}
GATE_DOCS = {
    "max_position": ("|position| above this is not a joint position", "rad"),
    "max_velocity": (
        "|velocity| above this is implausible; also bounds the position jump per stamp step",
        "rad/s",
    ),
    "max_effort": ("|effort| above this is not a joint torque", "N*m"),
    "max_stamp_lead": ("a stamp further ahead of the expected one than this is rejected", "s"),
    "resync_samples": ("consistent rejected samples in a row that re-synchronise stamps/position", ""),
    "log_period": ("at most one log line per rejection reason per this period", "s"),
}

REASONS = ("wrong_joint", "wrong_length", "not_finite", "out_of_range", "old_stamp", "future_stamp", "jump")
#: rejections that a consistent run of samples can turn into a re-synchronisation
_RESYNCABLE = frozenset(("old_stamp", "future_stamp", "jump"))

ACCEPTED, DUPLICATE, RESYNC, REJECTED = 0, 1, 2, 3


class RejectionLog:
    """Counts rejections per reason and rate-limits their log lines.

    :meth:`reject` returns the line to log, or None when a line for the same reason was returned
    less than ``period`` seconds ago; the next line says how many were not logged meanwhile.
    :meth:`recovered` returns one line when samples are accepted again after logged rejections.
    """

    def __init__(self, what: str, period: float = 1.0, reasons: tuple[str, ...] = REASONS):
        self.what = what
        self.period = period
        self.counts: dict[str, int] = dict.fromkeys(reasons, 0)
        self.total = 0
        self.last_reason = ""
        self._last_log: dict[str, float] = {}
        self._suppressed: dict[str, int] = {}
        self._streak = 0
        self._streak_logged = False

    def reject(self, reason: str, detail: str, now: float) -> str | None:
        self.counts[reason] = self.counts.get(reason, 0) + 1
        self.total += 1
        self.last_reason = reason
        self._streak += 1
        last = self._last_log.get(reason)
        if last is not None and now - last < self.period:
            self._suppressed[reason] = self._suppressed.get(reason, 0) + 1
            return None
        self._last_log[reason] = now
        n = self._suppressed.pop(reason, 0)
        self._streak_logged = True
        more = f" ({n} more {reason} rejections since the last line)" if n else ""
        return f"rejected {self.what} [{reason}]: {detail}{more}"

    def recovered(self) -> str | None:
        """Call on an accepted sample; returns a line once after a logged run of rejections."""
        if not self._streak:
            return None
        n, logged = self._streak, self._streak_logged
        self._streak, self._streak_logged = 0, False
        return f"{self.what}: accepted again after {n} rejected" if logged else None

    def values(self, prefix: str = "rejected.") -> dict[str, int]:
        """Counts for diagnostics: ``{prefix + reason: n}``."""
        return {prefix + k: v for k, v in self.counts.items()}


def _sel(seq, i: int, n: int):
    """(value or None, ok): value ``i`` of a per-joint sequence that must be empty or of length n."""
    m = len(seq)
    if m == 0:
        return None, True
    return (float(seq[i]), True) if m == n else (None, False)


def _name_index(names, joint: str) -> tuple[int | None, str]:
    """Index of ``joint`` in a message's ``name`` list, or (None, why)."""
    names = list(names)
    if joint in names:
        return names.index(joint), ""
    return None, f"joint {joint!r} is not in name {names} (check joint_name)"


def select_sample(msg, joint: str) -> tuple[tuple[float, float | None, float | None] | None, str, str]:
    """(position, velocity|None, effort|None) of ``joint`` in a JointState-like ``msg``.

    Returns ``(values, "", "")`` or ``(None, reason, detail)`` (``wrong_joint``/``wrong_length``).
    An unnamed message with exactly one position counts as the joint.
    """
    n = len(msg.name)
    if n:
        i, detail = _name_index(msg.name, joint)
        if i is None:
            return None, "wrong_joint", detail
    elif len(msg.position) == 1:
        i, n = 0, 1
    else:
        return (
            None,
            "wrong_joint",
            f"unnamed message with {len(msg.position)} positions: cannot tell the joint",
        )
    if len(msg.position) != n:
        return None, "wrong_length", f"position has {len(msg.position)} values for {n} names"
    vel, ok_v = _sel(msg.velocity, i, n)
    eff, ok_e = _sel(msg.effort, i, n)
    if not (ok_v and ok_e):
        field, seq = ("velocity", msg.velocity) if not ok_v else ("effort", msg.effort)
        return None, "wrong_length", f"{field} has {len(seq)} values for {n} names (must be 0 or {n})"
    return (float(msg.position[i]), vel, eff), "", ""


def select_command(msg, joint: str, max_effort: float) -> tuple[float | None, str, str]:
    """Effort of ``joint`` in a JointState command: ``(effort, "", "")`` or ``(None, reason, detail)``.

    An unnamed command with exactly one effort counts as the joint. Reasons: ``wrong_joint``,
    ``wrong_length``, ``not_finite``, ``out_of_range`` (``|effort| > max_effort``).
    """
    n = len(msg.name)
    if n:
        i, detail = _name_index(msg.name, joint)
        if i is None:
            return None, "wrong_joint", detail
        if len(msg.effort) != n:
            return None, "wrong_length", f"effort has {len(msg.effort)} values for {n} names"
    elif len(msg.effort) == 1:
        i = 0
    else:
        return None, "wrong_length", f"unnamed command with {len(msg.effort)} efforts: must have exactly 1"
    e = float(msg.effort[i])
    if not math.isfinite(e):
        return None, "not_finite", f"effort = {e} for {joint}: must be a finite torque [N*m]"
    if abs(e) > max_effort:
        return (
            None,
            "out_of_range",
            f"effort = {e:g} for {joint}: must satisfy |effort| <= max_effort = {max_effort:g} [N*m]",
        )
    return e, "", ""


class JointInputGate:
    """Plausibility gate of one joint's states; see the module docstring.

    ``admit(msg, now_ns)`` returns ACCEPTED, RESYNC (accepted after a re-synchronisation),
    DUPLICATE (same stamp as the last accepted) or REJECTED (``log_line`` then holds the line to log
    or None when rate-limited). After ACCEPTED/RESYNC: ``position``, ``velocity``, ``effort``,
    ``stamp_ns`` (the effective stamp: receive time for unstamped samples). ``now_ns`` is the node
    clock in ns (0: unknown). ``need_velocity``/``need_effort``: reject samples without them.
    """

    def __init__(
        self,
        joint: str,
        config: dict[str, Any] | None = None,
        *,
        period: float = 1e-3,
        need_velocity: bool = False,
        need_effort: bool = False,
        what: str = "",
    ):
        c = dict(GATE_DEFAULTS)
        for k, v in (config or {}).items():
            if k not in GATE_DEFAULTS:
                raise ParameterError(
                    f"input_gate.{k} is not a parameter: must be one of {', '.join(GATE_DEFAULTS)}"
                )
            c[k] = v
        self.max_position = check_real(
            "input_gate.max_position", c["max_position"], 0.0, lo_open=True, unit="rad"
        )
        self.max_velocity = check_real(
            "input_gate.max_velocity", c["max_velocity"], 0.0, lo_open=True, unit="rad/s"
        )
        self.max_effort = check_real("input_gate.max_effort", c["max_effort"], 0.0, lo_open=True, unit="N*m")
        self.max_stamp_lead = check_real(
            "input_gate.max_stamp_lead", c["max_stamp_lead"], 0.0, lo_open=True, unit="s"
        )
        self.resync_samples = check_int("input_gate.resync_samples", c["resync_samples"], 1, 1_000_000)
        log_period = check_real("input_gate.log_period", c["log_period"], 0.0, unit="s")
        self.period = check_real("input_gate.period", period, 0.0, lo_open=True, unit="s")
        self.joint = joint
        self.need_velocity = need_velocity
        self.need_effort = need_effort
        self.log = RejectionLog(what or f"joint state of {joint}", log_period)
        self._lead_ns = int(self.max_stamp_lead * 1e9)
        self._one = (joint,)
        self._names: tuple | None = None  # names of the last multi-joint message and this joint's index
        self._index = 0
        self.counts = {"accepted": 0, "duplicates": 0, "unstamped": 0, "resyncs": 0}
        self.reset()

    def reset(self) -> None:
        """Forget the reference sample (the next plausible sample is accepted as the first)."""
        self.stamp_ns = 0
        self._last_stamp: int | None = None
        self._last_now = 0
        self._last_pos = 0.0
        self._cand: tuple[int, int, float] | None = None  # stamp, now, position of the last rejected
        self._cand_n = 0
        self.resync_reason = ""
        self.log_line: str | None = None
        self.position = 0.0
        self.velocity: float | None = None
        self.effort: float | None = None

    # -- the per-sample path ------------------------------------------------------------------------
    def admit(self, msg, now_ns: int, now_wall: float | None = None) -> int:
        """Gate one JointState-like ``msg`` (``name``, ``position``, ``velocity``, ``effort``, ``stamp_ns``)."""
        if msg.name == self._one and len(msg.position) == 1:  # the usual single-joint message
            v, e = msg.velocity, msg.effort
            if len(v) > 1 or len(e) > 1:
                return self._reject(
                    "wrong_length",
                    f"velocity/effort have {len(v)}/{len(e)} values for 1 name",
                    now_ns,
                    now_wall,
                )
            pos = msg.position[0]
            vel = v[0] if v else None
            eff = e[0] if e else None
        else:
            names, n = msg.name, len(msg.name)
            v, e = msg.velocity, msg.effort
            if names is self._names and len(msg.position) == n and len(v) in (0, n) and len(e) in (0, n):
                i = self._index  # the same names object as last time (the decoder's layout): same index
                pos = float(msg.position[i])
                vel = v[i] if v else None
                eff = e[i] if e else None
            else:
                sel, reason, detail = select_sample(msg, self.joint)
                if sel is None:
                    return self._reject(reason, detail, now_ns, now_wall)
                pos, vel, eff = sel
                if n and isinstance(names, tuple):
                    self._names, self._index = names, names.index(self.joint)
        if (vel is None and self.need_velocity) or (eff is None and self.need_effort):
            field = "velocity" if vel is None and self.need_velocity else "effort"
            return self._reject("wrong_length", f"no {field} value (this node needs it)", now_ns, now_wall)
        return self.check(msg.stamp_ns, now_ns, pos, vel, eff, now_wall)

    def check(
        self, stamp_ns: int, now_ns: int, pos: float, vel: float | None, eff: float | None, now_wall=None
    ) -> int:
        """Gate already-selected values (see :meth:`admit`)."""
        # magnitudes (never re-synchronised: such a value is never a joint state)
        if not (
            abs(pos) <= self.max_position
            and (vel is None or abs(vel) <= self.max_velocity)
            and (eff is None or abs(eff) <= self.max_effort)
        ):
            if not (
                math.isfinite(pos)
                and (vel is None or math.isfinite(vel))
                and (eff is None or math.isfinite(eff))
            ):
                return self._reject(
                    "not_finite",
                    f"position {pos}, velocity {vel}, effort {eff}: must be finite",
                    now_ns,
                    now_wall,
                )
            return self._reject(
                "out_of_range",
                f"position {pos:g} rad, velocity {_g(vel)} rad/s, effort {_g(eff)} N*m: must satisfy "
                f"|position| <= {self.max_position:g}, |velocity| <= {self.max_velocity:g}, "
                f"|effort| <= {self.max_effort:g} (input_gate.max_*)",
                now_ns,
                now_wall,
            )
        if stamp_ns == 0 and now_ns:  # (clock 0 too: lockstep's first state at simulated time 0)
            self.counts["unstamped"] += 1
            stamp_ns = now_ns
        last = self._last_stamp
        if last is not None:
            if stamp_ns == last:
                self.counts["duplicates"] += 1
                return DUPLICATE
            if stamp_ns < last:
                return self._chain(
                    "old_stamp",
                    f"stamp {stamp_ns * 1e-9:.9f} s is {(last - stamp_ns) * 1e-9:.6g} s older than the last "
                    f"accepted {last * 1e-9:.9f} s",
                    stamp_ns,
                    now_ns,
                    (pos, vel, eff),
                    now_wall,
                )
            expected = last + max(now_ns - self._last_now, 0)
            if stamp_ns - expected > self._lead_ns:
                return self._chain(
                    "future_stamp",
                    f"stamp {stamp_ns * 1e-9:.9f} s is {(stamp_ns - expected) * 1e-9:.6g} s ahead of the "
                    f"expected {expected * 1e-9:.9f} s (allowed: input_gate.max_stamp_lead = {self.max_stamp_lead:g} s)",
                    stamp_ns,
                    now_ns,
                    (pos, vel, eff),
                    now_wall,
                )
            step = max((stamp_ns - last) * 1e-9, self.period)
            limit = self.max_velocity * step
            if abs(pos - self._last_pos) > limit:
                return self._chain(
                    "jump",
                    f"position {pos:g} rad jumps {pos - self._last_pos:.6g} rad from the last accepted "
                    f"{self._last_pos:g} rad in {step:.6g} s (allowed {limit:.6g} rad = "
                    f"input_gate.max_velocity {self.max_velocity:g} rad/s x {step:.6g} s)",
                    stamp_ns,
                    now_ns,
                    (pos, vel, eff),
                    now_wall,
                )
        elif now_ns > 0 and stamp_ns - now_ns > self._lead_ns:
            return self._chain(
                "future_stamp",
                f"stamp {stamp_ns * 1e-9:.9f} s is {(stamp_ns - now_ns) * 1e-9:.6g} s ahead of the node clock "
                f"(allowed: input_gate.max_stamp_lead = {self.max_stamp_lead:g} s)",
                stamp_ns,
                now_ns,
                (pos, vel, eff),
                now_wall,
            )
        return self._accept(stamp_ns, now_ns, pos, vel, eff, ACCEPTED)

    # -- internals ----------------------------------------------------------------------------------
    def _accept(self, stamp_ns, now_ns, pos, vel, eff, status) -> int:
        self._last_stamp = self.stamp_ns = stamp_ns
        self._last_now = now_ns
        self._last_pos = self.position = pos
        self.velocity, self.effort = vel, eff
        self._cand, self._cand_n = None, 0
        self.counts["accepted"] += 1
        self.log_line = self.log.recovered() if self.log._streak else None
        return status

    def _reject(self, reason: str, detail: str, now_ns: int, now_wall) -> int:
        self._cand, self._cand_n = None, 0  # never adopted: breaks a re-synchronisation run
        self.log_line = self.log.reject(reason, detail, _wall(now_wall, now_ns))
        return REJECTED

    def _chain(self, reason: str, detail: str, stamp_ns: int, now_ns: int, values: tuple, now_wall) -> int:
        """A rejection that a consistent run of samples may turn into a re-synchronisation."""
        pos = values[0]
        c = self._cand
        consistent = False
        if c is not None:
            c_stamp, c_now, c_pos = c
            if stamp_ns > c_stamp and stamp_ns - (c_stamp + max(now_ns - c_now, 0)) <= self._lead_ns:
                step = max((stamp_ns - c_stamp) * 1e-9, self.period)
                consistent = abs(pos - c_pos) <= self.max_velocity * step
        self._cand_n = self._cand_n + 1 if consistent else 1
        self._cand = (stamp_ns, now_ns, pos)
        if self._cand_n >= self.resync_samples:
            self.counts["resyncs"] += 1
            self.resync_reason = reason
            status = self._accept(stamp_ns, now_ns, pos, values[1], values[2], RESYNC)
            self.log_line = (
                f"{self.log.what}: re-synchronised on {self.resync_samples} consistent samples after "
                f"{reason} rejections (new reference: stamp {stamp_ns * 1e-9:.9f} s, position {pos:g} rad)"
            )
            return status
        self.log_line = self.log.reject(reason, detail, _wall(now_wall, now_ns))
        return REJECTED


def _g(x) -> str:
    return "-" if x is None else f"{x:g}"


def _wall(now_wall, now_ns: int) -> float:
    return now_wall if now_wall is not None else now_ns * 1e-9


def select_joint_commands(
    msg, index: Mapping[str, int], limits: list[float]
) -> tuple[dict[int, float], list[tuple[int | None, str, str]], int]:
    """Efforts of a ``joint_commands`` message for several joints.

    Returns ``(efforts, rejections, unknown)``: ``{joint index: effort}`` (an implausible effort
    becomes 0.0 and is listed in ``rejections`` as ``(index, reason, detail)``), the rejections (a
    whole-message one has index None: ``wrong_joint`` when it names none of the joints,
    ``wrong_length`` for mismatched arrays or an unnamed message) and how many names are not joints
    of this node (ignored). A name given twice counts once (the first). Pure.
    """
    names = list(msg.name)
    n = len(names)
    if not n:
        return (
            {},
            [(None, "wrong_length", f"unnamed command with {len(msg.effort)} efforts: must name the joints")],
            0,
        )
    hits = [(k, index[nm]) for k, nm in enumerate(names) if nm in index]
    if not hits:
        return (
            {},
            [(None, "wrong_joint", f"none of the joints {list(index)} is in name {names} (check joints)")],
            n,
        )
    if len(msg.effort) != n:
        return {}, [(None, "wrong_length", f"effort has {len(msg.effort)} values for {n} names")], 0
    efforts: dict[int, float] = {}
    rejections: list[tuple[int | None, str, str]] = []
    for k, i in hits:
        if i in efforts:
            continue
        e = float(msg.effort[k])
        if not math.isfinite(e):
            rejections.append(
                (i, "not_finite", f"effort = {e} for {names[k]}: must be a finite torque [N*m]")
            )
            e = 0.0
        elif abs(e) > limits[i]:
            rejections.append(
                (
                    i,
                    "out_of_range",
                    f"effort = {e:g} for {names[k]}: must satisfy |effort| <= max_effort = {limits[i]:g} [N*m]",
                )
            )
            e = 0.0
        efforts[i] = e
    return efforts, rejections, n - len(hits)
