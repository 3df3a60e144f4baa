"""One joint of a CSV log (time, position/velocity, effort or motor current) as a prepared record.

:func:`load_csv` reads a delimited text file with one header line (``,``, ``;`` or tab separated;
``#`` comment lines and blank lines are skipped) and builds :class:`JointData` with
:func:`~friction_ros.core.identification.data.records.prepare` (sorting, duplicate stamps, non-uniform
sampling and current -> torque are handled there).

Columns have roles: ``time`` [s x ``time_scale``], ``position`` [rad], ``velocity`` [rad/s],
``effort`` [N*m] and ``current`` [A] (joint torque = current x ``torque_constant`` x ``gear_ratio``).
``columns`` maps roles to column names; the roles it leaves out are found by header, case-insensitive,
with a unit annotation (``time [s]``, ``torque (Nm)``, ``position_rad``, ``force_N``) ignored
(a prismatic joint's log is in m, m/s and N: :func:`~friction_ros.core.joint_type.detect_joint_type`
tells from the headers):

=========  ==================================
time       time, t, timestamp, stamp
position   position, pos, q
velocity   velocity, vel, qd, dq
effort     effort, torque, tau, force
current    current, iq
load       load, load_torque, transmitted
=========  ==================================

``load`` [N*m]: the torque the gear transmits to the link, where the user knows it (a load cell, an
arm's inverse dynamics); the load-dependent friction then uses it instead of the fit's estimate
(:mod:`~friction_ros.core.identification.fit.load_terms`).

Several joints in one file: ``position_<joint>``, ``<joint>_position`` or ``<joint>/position`` (any
alias); ``joint`` chooses one, columns without a joint (a shared ``time``) serve every joint.
Bad input raises :class:`~friction_ros.core.identification.data.records.ExcitationError` with one line
naming the file, the problem and what is allowed.
"""

from __future__ import annotations

import csv
import re
from pathlib import Path

import numpy as np

from friction_ros.core.identification.data.records import ExcitationError, JointData, prepare
from friction_ros.core.validation import ParameterError, check_real

#: column roles and the headers recognised for each (lower case)
ROLES: dict[str, tuple[str, ...]] = {
    "time": ("time", "t", "timestamp", "stamp"),
    "position": ("position", "pos", "q"),
    "velocity": ("velocity", "vel", "qd", "dq"),
    "effort": ("effort", "torque", "tau", "force"),
    "current": ("current", "iq"),
    # the torque the gear transmits to the link (a load cell, an arm's inverse dynamics ...) [N*m],
    # used by the load-dependent friction instead of the fit's own estimate
    "load": ("load", "load_torque", "transmitted"),
}
#: SI unit suffixes dropped from a header before matching (``position_rad``, ``torque_Nm``)
_UNIT_SUFFIXES = (
    *("rad_s", "rad/s", "rads", "rad", "m_s", "m/s", "s", "sec", "nm", "n_m", "n*m", "a", "amp", "amps"),
    *("m", "n"),  # a prismatic joint's position and force (position_m, force_N)
)
#: time units that need ``time_scale`` (``time_ms``, ``stamp [ns]``): their factor to seconds
TIME_UNITS = {"ns": 1e-9, "us": 1e-6, "ms": 1e-3}
#: qualifiers of a set-point column (``position_desired``, ``tau_cmd``): ignored, never a joint name
_REFERENCE = ("des", "desired", "ref", "reference", "cmd", "command", "target", "setpoint", "sp", "goal")
#: qualifiers of the measured signal (``position_measured``): the role itself, not a joint name
_MEASURED = ("meas", "measured", "msr", "act", "actual", "real")
_BRACKET_UNIT = re.compile(r"\s*[\[(][^\])]*[\])]\s*$")
_SEPARATORS = ("_", "/", ".", ":")
_DELIMITERS = (",", ";", "\t")


def _allowed_roles() -> str:
    return "; ".join(f"{r}: {', '.join(a)}" for r, a in ROLES.items())


def _base(header: str) -> str:
    """Header without quotes, surrounding space and a bracketed unit, lower case."""
    h = _BRACKET_UNIT.sub("", header.strip().strip("\"'").strip())
    return h.strip()


def _time_unit(header: str) -> str | None:
    """``ns``/``us``/``ms`` when a header carries that unit (``time_ms``, ``stamp [ns]``, ``t (us)``)."""
    low = header.strip().strip("\"'").lower()
    for u in TIME_UNITS:
        if re.search(rf"(^|[\s_\[(]){u}[\])]?$", low):
            return u
    return None


def _strip_unit(low: str) -> str:
    for u in (*_UNIT_SUFFIXES, *TIME_UNITS):
        for sep in ("_", " "):
            if low.endswith(sep + u) and len(low) > len(u) + 1:
                return low[: -len(u) - 1]
    return low


def _match(header: str) -> tuple[str, str | None] | None:
    """(role, joint or None) of a header, or None when it names no role."""
    h = _base(header)
    low = h.lower()
    for cand in dict.fromkeys((low, _strip_unit(low))):
        for role, aliases in ROLES.items():
            if cand in aliases:
                return role, None
    for role, aliases in ROLES.items():
        for a in sorted(aliases, key=len, reverse=True):
            for sep in _SEPARATORS:
                rest = None
                if low.startswith(a + sep) and len(low) > len(a) + 1:
                    rest = h[len(a) + 1 :]
                elif low.endswith(sep + a) and len(low) > len(a) + 1:
                    rest = h[: -len(a) - 1]
                if rest is None:
                    continue
                if rest.lower() in _REFERENCE:
                    return None
                return role, None if rest.lower() in _MEASURED else rest
    return None


def _read_table(path: Path) -> tuple[list[str], list[list[str]], int, list[str]]:
    """(headers, rows of cells, line number of the first row, notes) of a delimited text file."""
    try:
        text = path.read_text(encoding="utf-8-sig", errors="replace")
    except OSError as exc:
        raise ExcitationError(f"csv {path}: cannot read it ({exc.strerror})") from None
    lines = text.splitlines()
    numbered = [(i + 1, ln) for i, ln in enumerate(lines) if ln.strip() and not ln.lstrip().startswith("#")]
    if not numbered:
        raise ExcitationError(
            f"csv {path}: file is empty: need a header line and at least 3 rows (roles {_allowed_roles()})"
        )
    head_no, head = numbered[0]
    delim = max(_DELIMITERS, key=head.count)
    if head.count(delim) == 0:
        delim = None  # one column, or whitespace separated
    headers = [c.strip() for c in (next(csv.reader([head], delimiter=delim)) if delim else head.split())]
    if all(_is_number(c) for c in headers):
        raise ExcitationError(
            f"csv {path}: line {head_no} is numbers, not column names: add a header line naming the columns "
            f"(roles {_allowed_roles()})"
        )
    body = [ln for _, ln in numbered[1:]]
    rows = list(csv.reader(body, delimiter=delim)) if delim else [ln.split() for ln in body]
    notes: list[str] = []
    if rows and len(rows[-1]) < len(headers) and all(len(r) == len(headers) for r in rows[:-1]):
        notes.append(
            f"{path}: the last line has {len(rows[-1])} of {len(headers)} values (cut off): left out"
        )
        rows = rows[:-1]
    for k, r in enumerate(rows):
        if len(r) != len(headers):
            raise ExcitationError(
                f"csv {path}: line {numbered[k + 1][0]} has {len(r)} values, the header {len(headers)}: "
                "every row must have one value per column"
            )
    return headers, rows, numbered[1][0] if len(numbered) > 1 else head_no + 1, notes


def _header(path: Path) -> tuple[int, str | None, list[str]] | None:
    """(line number, delimiter, column names) of the header line, read without the rest of the file."""
    try:
        with open(path, encoding="utf-8-sig", errors="replace") as f:
            for no, ln in enumerate(f, 1):
                if ln.strip() and not ln.lstrip().startswith("#"):
                    head = ln.rstrip("\r\n")
                    delim = max(_DELIMITERS, key=head.count)
                    delim = delim if head.count(delim) else None
                    cells = next(csv.reader([head], delimiter=delim)) if delim else head.split()
                    return no, delim, [c.strip() for c in cells]
    except OSError:
        return None
    return None


def _fast_columns(path: Path, head: tuple[int, str | None, list[str]], roles: dict[str, int]):
    """{role: values} parsed by numpy straight from the file (one array per column, no per-row
    objects), or None when a row is unusual (empty or non-numeric cells, a short row): the careful
    reader then says what is wrong."""
    no, delim, headers = head
    cols = sorted(set(roles.values()) | {len(headers) - 1})
    try:
        with open(path, encoding="utf-8-sig") as f:
            arr = np.loadtxt(
                f, delimiter=delim, comments="#", skiprows=no, usecols=cols, ndmin=2, quotechar='"'
            )
    except (ValueError, OSError, UnicodeDecodeError):
        return None
    if arr.shape[0] < 3:
        return None
    return {r: arr[:, cols.index(j)].copy() for r, j in roles.items()}


def _is_number(cell: str) -> bool:
    try:
        float(cell)
    except ValueError:
        return False
    return True


def _column(path: Path, headers: list[str], rows: list[list[str]], j: int, first_line: int) -> np.ndarray:
    cells = [r[j].strip() for r in rows]
    try:
        return np.array([c if c else "nan" for c in cells]).astype(float)
    except ValueError:
        k = next(i for i, c in enumerate(cells) if c and not _is_number(c))
        raise ExcitationError(
            f"csv {path}: column {headers[j]!r}, data row {k + 1} (line ~{first_line + k}): {cells[k]!r} is not "
            "a number: values must be decimal numbers (empty or nan for a missing value)"
        ) from None


def _resolve(
    path: Path, headers: list[str], columns: dict | None, joint: str | None
) -> tuple[dict[str, int], str]:
    """{role: column index} for ``joint`` and the joint's name ("" for a single-joint file)."""
    chosen: dict[str, int] = {}
    if columns:
        for role, name in columns.items():
            if role not in ROLES:
                raise ExcitationError(
                    f"csv {path}: unknown column role {role!r}: roles are {', '.join(ROLES)}"
                )
            hits = [i for i, h in enumerate(headers) if h == name] or [
                i for i, h in enumerate(headers) if _base(h).lower() == str(name).strip().lower()
            ]
            if not hits:
                raise ExcitationError(
                    f"csv {path}: no column {name!r} for {role}: columns are {', '.join(headers)}"
                )
            chosen[role] = hits[0]
    taken = set(chosen.values())
    found: dict[str, dict[str | None, list[int]]] = {r: {} for r in ROLES}
    for i, h in enumerate(headers):
        m = _match(h)
        if m is not None and i not in taken:
            found[m[0]].setdefault(m[1], []).append(i)
    joints = list(dict.fromkeys(j for r in ROLES if r not in chosen for j in found[r] if j is not None))
    name = ""
    if joints:
        if joint is None:
            if len(joints) > 1:
                raise ExcitationError(
                    f"csv {path} has columns of joints {', '.join(joints)}: choose one with --joint (joint=)"
                )
            joint = joints[0]
        elif joint not in joints:
            raise ExcitationError(
                f"csv {path}: no columns of joint {joint!r}: joints are {', '.join(joints)}"
            )
        name = joint
    elif joint is not None:
        name = joint  # one joint in the file: its columns carry no name
    for role in ROLES:
        if role in chosen:
            continue
        idx = found[role].get(name) if name in found[role] else None
        if idx is None:
            idx = found[role].get(None)
        if not idx:
            continue
        if len(idx) > 1:
            raise ExcitationError(
                f"csv {path}: columns {', '.join(repr(headers[i]) for i in idx)} all look like {role}: "
                f"choose one with --columns {role}=<name>"
            )
        chosen[role] = idx[0]
    return chosen, name


def load_csv(
    path,
    joint: str | None = None,
    columns: dict | None = None,
    *,
    torque_constant: float | None = None,
    gear_ratio: float = 1.0,
    time_scale: float = 1.0,
    velocity_window: float = 0.021,
    acceleration_window: float = 0.041,
    torque_delay: float = 0.0,
) -> JointData:
    """Read one joint of a CSV log into :class:`JointData` (module docstring: columns and roles).

    ``time_scale`` [s per time unit] scales the time column (1e-9 for ns, 1e-3 for ms). The torque
    is the ``effort`` column, or the ``current`` column x ``torque_constant`` [N*m/A] x
    ``gear_ratio`` when a torque constant is given (or there is no effort column).
    """
    path = Path(path)
    if not path.is_file():
        what = "is a directory, not a CSV file" if path.is_dir() else "no such file"
        raise ExcitationError(f"csv {path}: {what}")
    try:
        scale = check_real("time_scale", time_scale, 0.0, lo_open=True, unit="s per time unit")
    except ParameterError as exc:
        raise ExcitationError(f"csv {path}: {exc}") from None
    head = _header(path)
    fast = None
    if head is not None and not all(_is_number(c) for c in head[2]):
        headers = head[2]
        roles, name = _resolve(path, headers, columns, joint)
        if "time" in roles and ("position" in roles or "velocity" in roles):
            fast = _fast_columns(path, head, roles)
    if fast is None:
        headers, rows, first_line, notes = _read_table(path)
        roles, name = _resolve(path, headers, columns, joint)
    else:
        rows, notes = fast, []
    hint = "name it with --columns role=<column> (columns= in Python)"
    if "time" not in roles:
        raise ExcitationError(
            f"csv {path}: no time column among {', '.join(headers)}: {hint}; recognised: {', '.join(ROLES['time'])}"
        )
    if "position" not in roles and "velocity" not in roles:
        raise ExcitationError(
            f"csv {path}: no position or velocity column among {', '.join(headers)}: {hint}; recognised: "
            f"{', '.join(ROLES['position'] + ROLES['velocity'])}"
        )
    unit = _time_unit(headers[roles["time"]])
    if unit and not abs(scale / TIME_UNITS[unit] - 1.0) < 1e-9:
        raise ExcitationError(
            f"csv {path}: time column {headers[roles['time']]!r} looks like {unit} but time_scale is {scale:g} s: "
            f"pass --time-scale {TIME_UNITS[unit]:g} (time_scale=)"
        )
    use_current = "current" in roles and (torque_constant is not None or "effort" not in roles)
    if not use_current and "effort" not in roles:
        raise ExcitationError(
            f"csv {path}: no effort column among {', '.join(headers)}: {hint}; recognised: "
            f"{', '.join(ROLES['effort'])}, or a current column ({', '.join(ROLES['current'])}) with "
            "torque_constant and gear_ratio"
        )
    if use_current and torque_constant is None:
        raise ExcitationError(
            f"csv {path}: the torque comes from current column {headers[roles['current']]!r}: "
            "pass --torque-constant [N*m/A] (and --gear-ratio)"
        )
    if fast is None and len(rows) < 3:
        raise ExcitationError(f"csv {path}: {len(rows)} data rows: need at least 3")
    col = (
        fast
        if fast is not None
        else {r: _column(path, headers, rows, j, first_line) for r, j in roles.items()}
    )
    t = col["time"] * scale
    if not np.all(np.isfinite(t)):
        k = int(np.flatnonzero(~np.isfinite(t))[0])
        raise ExcitationError(
            f"csv {path}: time in data row {k + 1} is missing or not finite: every row needs a time"
        )
    try:
        data = prepare(
            t,
            col.get("position"),
            col.get("velocity"),
            None if use_current else col["effort"],
            current=col["current"] if use_current else None,
            torque_constant=torque_constant,
            gear_ratio=gear_ratio,
            velocity_window=velocity_window,
            acceleration_window=acceleration_window,
            torque_delay=torque_delay,
            source=str(path),
        )
    except ParameterError as exc:
        raise ExcitationError(f"csv {path}: {exc}") from None
    if col.get("load") is not None:
        ok = np.isfinite(col["load"]) & np.isfinite(t)
        order = np.argsort(t[ok], kind="stable")
        data.transmitted = np.interp(data.t + data.t0, t[ok][order], col["load"][ok][order])
        data.meta["transmitted_source"] = f"column {headers[roles['load']]!r}"
    data.meta["warnings"] = notes + data.meta.get("warnings", [])
    data.meta["joint"] = name
    data.meta["columns"] = {r: headers[j] for r, j in roles.items()}
    return data
