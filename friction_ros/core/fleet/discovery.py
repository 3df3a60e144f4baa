"""Find the runs of a fleet under folders and say whose they are: robot, joint, time.

A run is a ``.csv`` log, a rosbag2 bag directory (one holding ``metadata.yaml`` or ``.mcap``
files) or a lone ``.mcap`` file. Its identity comes from, first hit per field wins:

1. its sidecar ``<run>.yaml`` (``log.csv`` -> ``log.yaml``, bag ``day1/`` -> ``day1.yaml``):
   :data:`SIDECAR_KEYS`;
2. a bag's metadata: the ``friction_ros`` MCAP metadata record or ``metadata.yaml``
   ``custom_data`` (``robot``, ``joint``, ``run_time``), else the time of its first message;
3. the user's path pattern (:class:`PathPattern`), e.g. ``{robot}/{date:%Y-%m-%d}/{joint}.csv``,
   matched against the path below the root folder.

A bag without a joint gives one task per joint on its JointState topic; a CSV log holds one
joint. The identity of a run's data is the SHA-256 of its bytes (:func:`source_sha256`). Inputs
are only read. Pure: no rclpy.
"""

from __future__ import annotations

import datetime as dt
import hashlib
import re
from dataclasses import dataclass, field, replace
from pathlib import Path

from friction_ros.core.validation import ParameterError

#: keys a sidecar ``<run>.yaml`` may hold
SIDECAR_KEYS = (
    "robot",
    "joint",
    "time",
    "joint_type",
    "temperature_column",
    "temperature_topic",
    "columns",
    "time_scale",
    "topic",
)
#: fields of a path pattern; ``date`` and ``time`` take a strptime format: ``{date:%Y-%m-%d}``
PATTERN_FIELDS = ("robot", "joint", "date", "time")
_STRPTIME_RE = {"Y": r"\d{4}", "m": r"\d{2}", "d": r"\d{2}", "H": r"\d{2}", "M": r"\d{2}", "S": r"\d{2}"}
_FIELD = re.compile(r"\{([^{}]*)\}")


@dataclass(frozen=True)
class RunTask:
    """One (run, joint) to fit: plain data, sent to a worker. ``problem``: why it cannot be fitted
    ('' when it can); ``joint`` None: every joint of the bag (expanded by :func:`expand_joints`)."""

    path: str
    robot: str = ""
    joint: str | None = None
    run_time: dt.datetime | None = None
    source_sha256: str = ""
    joint_type: str = "auto"
    topic: str = "/joint_states"
    temperature_column: str | None = None
    temperature_topic: str | None = None
    columns: dict | None = field(default=None, hash=False)
    time_scale: float = 1.0
    problem: str = ""

    @property
    def key(self) -> tuple[str, str]:
        return (self.source_sha256, self.joint or "")


class PathPattern:
    """``{robot}/{date:%Y-%m-%d}/{joint}.csv``: fields :data:`PATTERN_FIELDS` between literal text;
    ``*`` matches any text inside one folder name. A bad pattern raises ParameterError (one line)."""

    def __init__(self, text: str):
        self.text = text
        parts, pos, self.formats = [], 0, {}
        for m in _FIELD.finditer(text):
            parts.append(self._literal(text[pos : m.start()]))
            name, _, fmt = m.group(1).partition(":")
            if name not in PATTERN_FIELDS:
                raise ParameterError(
                    f"--pattern {text!r}: unknown field {{{name}}}: fields are "
                    + ", ".join("{" + f + "}" for f in PATTERN_FIELDS)
                    + " ({date:%Y-%m-%d}, {time:%H%M%S})"
                )
            if name in self.formats:
                raise ParameterError(f"--pattern {text!r}: field {{{name}}} appears twice")
            if name in ("date", "time"):
                fmt = fmt or ("%Y-%m-%d" if name == "date" else "%H:%M:%S")
                parts.append(f"(?P<{name}>{self._strptime_regex(fmt)})")
            elif fmt:
                raise ParameterError(
                    f"--pattern {text!r}: {{{name}}} takes no format (only date and time do)"
                )
            else:
                parts.append(f"(?P<{name}>[^/]+?)")
            self.formats[name] = fmt
            pos = m.end()
        parts.append(self._literal(text[pos:]))
        if not self.formats:
            raise ParameterError(
                f"--pattern {text!r} has no field: write e.g. '{{robot}}/{{date:%Y-%m-%d}}/{{joint}}.csv'"
            )
        self.regex = re.compile("".join(parts) + "$")

    def _literal(self, s: str) -> str:
        if "{" in s or "}" in s:
            raise ParameterError(f"--pattern {self.text!r}: unbalanced brace in {s!r}")
        return ".*".join(re.escape(p) for p in s.split("*")).replace(".*", "[^/]*")

    def _strptime_regex(self, fmt: str) -> str:
        out, i = [], 0
        while i < len(fmt):
            if fmt[i] == "%":
                code = fmt[i + 1 : i + 2]
                if code not in _STRPTIME_RE:
                    raise ParameterError(
                        f"--pattern {self.text!r}: format %{code} is not supported: use %Y %m %d %H %M %S"
                    )
                out.append(_STRPTIME_RE[code])
                i += 2
            else:
                out.append(re.escape(fmt[i]))
                i += 1
        return "".join(out)

    def match(self, relative: str) -> dict | None:
        """{robot, joint, run_time} found in ``relative`` (posix path below the root), None when it
        does not match."""
        m = self.regex.search(relative)
        if m is None:
            return None
        g = m.groupdict()
        out = {k: g[k] for k in ("robot", "joint") if g.get(k)}
        if g.get("date") or g.get("time"):
            day = dt.datetime.strptime(g["date"], self.formats["date"]) if g.get("date") else None
            tod = dt.datetime.strptime(g["time"], self.formats["time"]).time() if g.get("time") else dt.time()
            base = day.date() if day else dt.date(1970, 1, 1)
            out["run_time"] = dt.datetime.combine(base, tod, tzinfo=dt.UTC)
        return out


# ------------------------------------------------------------------------------------ finding runs
def is_bag_dir(path: Path) -> bool:
    return path.is_dir() and ((path / "metadata.yaml").is_file() or any(path.glob("*.mcap")))


def find_run_paths(root) -> list[Path]:
    """Every run under ``root`` (or ``root`` itself when it is a run), sorted."""
    root = Path(root)
    if root.is_file() or is_bag_dir(root):
        return [root]
    out: list[Path] = []
    for p in sorted(root.iterdir()):
        if p.name.startswith("."):
            continue
        if p.is_dir():
            out += find_run_paths(p)
        elif p.suffix.lower() in (".csv", ".mcap"):
            out.append(p)
    return out


def source_sha256(path) -> str:
    """SHA-256 of a log file, or of a bag directory's files (name and bytes, in name order)."""
    path = Path(path)
    h = hashlib.sha256()
    files = [path] if path.is_file() else sorted(p for p in path.rglob("*") if p.is_file())
    for f in files:
        if path.is_dir():
            h.update(f.relative_to(path).as_posix().encode() + b"\0")
        with f.open("rb") as fh:
            for block in iter(lambda: fh.read(1 << 20), b""):
                h.update(block)
    return h.hexdigest()


def sidecar_path(run: Path) -> Path:
    return run.with_suffix(".yaml") if run.is_file() else run.parent / (run.name + ".yaml")


def _as_utc(value, where: str) -> dt.datetime:
    if isinstance(value, dt.datetime):
        t = value
    elif isinstance(value, dt.date):
        t = dt.datetime.combine(value, dt.time())
    else:
        try:
            t = dt.datetime.fromisoformat(str(value).strip().replace("Z", "+00:00"))
        except ValueError:
            raise ParameterError(
                f"{where}: time {value!r} is not ISO 8601 (e.g. 2026-03-01T08:00:00Z)"
            ) from None
    return t.replace(tzinfo=dt.UTC) if t.tzinfo is None else t.astimezone(dt.UTC)


def read_sidecar(run: Path) -> dict:
    """The sidecar of ``run`` as task fields ({} when there is none); ParameterError on a bad one."""
    side = sidecar_path(run)
    if not side.is_file():
        return {}
    import yaml

    try:
        doc = yaml.safe_load(side.read_text()) or {}
    except (OSError, yaml.YAMLError) as exc:
        raise ParameterError(f"sidecar {side}: cannot read it ({str(exc).splitlines()[0]})") from None
    if not isinstance(doc, dict):
        raise ParameterError(f"sidecar {side}: must be a mapping of {', '.join(SIDECAR_KEYS)}")
    unknown = sorted(set(doc) - set(SIDECAR_KEYS))
    if unknown:
        raise ParameterError(
            f"sidecar {side}: unknown key(s) {', '.join(unknown)}: allowed {', '.join(SIDECAR_KEYS)}"
        )
    out = {k: doc[k] for k in SIDECAR_KEYS if k in doc and k != "time"}
    for k in ("robot", "joint"):
        if k in out:
            out[k] = str(out[k])
    if "time" in doc:
        out["run_time"] = _as_utc(doc["time"], f"sidecar {side}")
    return out


def bag_identity(run: Path) -> dict:
    """robot, joint, run_time a bag states (MCAP ``friction_ros`` record, metadata.yaml custom_data),
    run_time else the time of its first message."""
    from friction_ros.core.bag.reader import bag_info
    from friction_ros.core.joint_type import _bag_custom_data

    info = bag_info(run)
    found: dict = {}
    records = [_bag_custom_data(run) if run.is_dir() else {}, *(info.metadata or {}).values()]
    for rec in records:
        for key in ("robot", "joint", "run_time"):
            if key not in found and rec.get(key) not in (None, ""):
                found[key] = rec[key]
    if "run_time" in found:
        found["run_time"] = _as_utc(found["run_time"], f"bag {run}")
    elif info.span is not None:
        found["run_time"] = dt.datetime.fromtimestamp(info.span[0] * 1e-9, dt.UTC)
    return {k: str(v) if k != "run_time" else v for k, v in found.items()}


def describe_run(run: Path, root: Path, pattern: PathPattern | None = None, **defaults) -> RunTask | None:
    """The task of ``run`` (identity merged from sidecar, bag metadata, pattern; ``defaults``:
    RunTask fields given on the command line). None when a ``pattern`` is given, the path does
    not match it and nothing else names the run."""
    task = RunTask(path=str(run), **defaults)
    try:
        ident = read_sidecar(run)
        if run.suffix.lower() != ".csv":
            ident = {**bag_identity(run), **ident}
        rel = run.relative_to(root).as_posix() if run != root else run.name
        matched = pattern.match(rel) if pattern is not None else None
        if pattern is not None and matched is None and not {"robot", "run_time"} <= set(ident):
            return None
        ident = {**(matched or {}), **ident}
        task = replace(task, **ident)
        missing = [k for k in ("robot", "run_time") if not getattr(task, k)]
        if run.suffix.lower() == ".csv" and not task.joint:
            missing.append("joint")
        if missing:
            raise ParameterError(
                f"{run}: no {', '.join(missing)}: give a sidecar {sidecar_path(run).name} or --pattern"
            )
        return replace(task, source_sha256=source_sha256(run))
    except (ParameterError, OSError, ValueError) as exc:
        sha = source_sha256(run) if run.exists() else ""
        return replace(task, source_sha256=sha, problem=str(exc).splitlines()[0])


def expand_joints(task: RunTask) -> list[RunTask]:
    """A bag task without a joint: one task per joint on its topic (sorted)."""
    if task.joint or task.problem:
        return [task]
    from friction_ros.core.identification.data.joint_selection import bag_joint_names

    try:
        names = bag_joint_names([task.path], task.topic)
    except (ParameterError, ValueError, OSError) as exc:
        return [replace(task, problem=str(exc).splitlines()[0])]
    return [replace(task, joint=j) for j in sorted(names)]


def discover(roots, pattern: str | None = None, **defaults) -> tuple[list[RunTask], list[str]]:
    """(tasks sorted by key, notes on skipped files) for every run under ``roots``."""
    pat = PathPattern(pattern) if pattern else None
    tasks, notes = [], []
    for root in map(Path, roots):
        if not root.exists():
            raise ParameterError(f"{root}: no such file or folder")
        for run in find_run_paths(root):
            t = describe_run(run, root, pat, **defaults)
            if t is None:
                notes.append(f"{run}: skipped: does not match --pattern {pattern!r}")
            else:
                tasks += expand_joints(t)
    tasks.sort(key=lambda t: (t.robot, t.joint or "", t.path))
    return tasks, notes
