"""Which drive gets which effort of a ``joint_commands`` message (several drives on one bus)."""

from __future__ import annotations

from collections.abc import Sequence


def route_efforts(names: Sequence[str], efforts: Sequence, joints: Sequence[str]) -> tuple[list, str, str]:
    """``([(drive index, effort), ...], "", "")``, or ``([], kind, why)`` for a message to ignore.

    Efforts go by joint name (a message may carry any subset of ``joints``; a drive left out gets no
    command, so its watchdog zeroes it), or by position when the message has no names and exactly
    one effort per drive. Ignored: names and efforts of different lengths, or no names and not one
    effort per drive (kind ``length``); a message for none of ``joints`` (kind ``foreign``).
    """
    if names:
        if len(efforts) != len(names):
            return (
                [],
                "length",
                f"ignored joint_commands with {len(names)} names but {len(efforts)} efforts: "
                "must carry one effort per name",
            )
        names = list(names)
        routed = [(k, efforts[names.index(j)]) for k, j in enumerate(joints) if j in names]
        if not routed:
            return (
                [],
                "foreign",
                f"ignored joint_commands for {names}: this node drives {list(joints)} "
                "(set joint_name / joints to match the controller)",
            )
        return routed, "", ""
    n = len(joints)
    if len(efforts) == n:
        return list(enumerate(efforts)), "", ""
    return (
        [],
        "length",
        f"ignored joint_commands without names and {len(efforts)} efforts: "
        f"must name its joints or carry exactly {n} effort{'s' if n > 1 else ''} (joints {list(joints)})",
    )
