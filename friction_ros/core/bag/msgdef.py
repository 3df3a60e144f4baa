"""ROS 2 ``.msg`` definitions: parsing, resolving installed definitions, rosbag2 schema text.

A message type is named ``pkg/msg/Type``. :func:`schema_text` returns the text rosbag2 and Foxglove
expect as MCAP schema data (encoding ``ros2msg``): the ``.msg`` text of the type followed by every
dependency (recursively, each once), each preceded by a line of 80 ``=`` and ``MSG: pkg/Type``.
Installed definitions are found under ``<prefix>/share/<pkg>/msg/<Type>.msg`` for every prefix in
``AMENT_PREFIX_PATH``, then ``sys.prefix``, then the prefix the Python package ``<pkg>`` is installed in.
"""

from __future__ import annotations

import functools
import importlib.util
import json
import os
import re
import sys
from dataclasses import dataclass, field
from pathlib import Path

from .errors import SchemaError

# primitive type -> numpy dtype char (without byte order), size in bytes
PRIMITIVES: dict[str, tuple[str, int]] = {
    "bool": ("?", 1),
    "byte": ("u1", 1),
    "char": ("u1", 1),
    "int8": ("i1", 1),
    "uint8": ("u1", 1),
    "int16": ("i2", 2),
    "uint16": ("u2", 2),
    "int32": ("i4", 4),
    "uint32": ("u4", 4),
    "int64": ("i8", 8),
    "uint64": ("u8", 8),
    "float32": ("f4", 4),
    "float64": ("f8", 8),
}
STRINGS = ("string", "wstring")
SEPARATOR = "=" * 80

_FIELD_RE = re.compile(r"^([A-Za-z0-9_/]+)(?:<=(\d+))?(?:\[(<=)?(\d*)\])?$")


@dataclass(frozen=True)
class Field:
    """One field: ``type`` is a primitive name, ``string``/``wstring`` or a ``pkg/msg/Type``."""

    name: str
    type: str
    array: str | None = None  # None, "fixed" or "seq"
    length: int | None = None  # fixed length, or upper bound of a bounded sequence

    @property
    def is_complex(self) -> bool:
        return self.type not in PRIMITIVES and self.type not in STRINGS


@dataclass
class MsgDef:
    """A parsed message definition."""

    name: str
    fields: list[Field]
    constants: dict[str, str] = field(default_factory=dict)
    text: str = ""


def split_type(name: str) -> tuple[str, str]:
    """``pkg/msg/Type`` or ``pkg/Type`` -> (pkg, Type); raise SchemaError otherwise."""
    parts = name.strip().split("/")
    if len(parts) == 3 and parts[1] == "msg":
        return parts[0], parts[2]
    if len(parts) == 2:
        return parts[0], parts[1]
    raise SchemaError(f"message type {name!r} is not of the form pkg/msg/Type")


def normalize_type(name: str, package: str = "") -> str:
    """Full ``pkg/msg/Type`` name of a field type written in a .msg file of ``package``."""
    if "/" in name:
        pkg, typ = split_type(name)
        return f"{pkg}/msg/{typ}"
    if name == "Header" and package != "std_msgs":
        return "std_msgs/msg/Header"
    if not package:
        raise SchemaError(f"message type {name!r} has no package")
    return f"{package}/msg/{name}"


def parse_msg(text: str, name: str) -> MsgDef:
    """Parse the text of one ``.msg`` file defining ``name`` (``pkg/msg/Type``)."""
    pkg, _ = split_type(name)
    full = f"{pkg}/msg/{split_type(name)[1]}"
    fields: list[Field] = []
    constants: dict[str, str] = {}
    for lineno, raw in enumerate(text.splitlines(), 1):
        line = raw.strip()
        if not line or line.startswith("#"):
            continue
        head = line.split(None, 1)
        if len(head) != 2:
            raise SchemaError(f"{full}: line {lineno} {raw.strip()!r} is not 'type name'")
        typ, rest = head
        const = re.match(r"^(\w+)\s*=(.*)$", rest)
        if const:
            cname, value = const.groups()
            if typ not in STRINGS:
                value = value.split("#", 1)[0]
            constants[cname] = value.strip()
            continue
        fname = rest.split("#", 1)[0].split()[0]
        m = _FIELD_RE.match(typ)
        if not m:
            raise SchemaError(f"{full}: line {lineno}: cannot parse field type {typ!r}")
        base, _strbound, bounded, size = m.groups()
        if base in PRIMITIVES or base in STRINGS:
            ftype = base
        else:
            ftype = normalize_type(base, pkg)
        if "[" not in typ:
            array, length = None, None
        elif size and not bounded:
            array, length = "fixed", int(size)
        else:
            array, length = "seq", int(size) if size else None
        fields.append(Field(fname, ftype, array, length))
    return MsgDef(full, fields, constants, text)


def parse_schema(text: str, name: str) -> dict[str, MsgDef]:
    """Parse a concatenated rosbag2 ``ros2msg`` schema into {type name: MsgDef} (root included)."""
    defs: dict[str, MsgDef] = {}
    blocks = re.split(r"(?m)^=+\s*$", text)
    root = normalize_type(name)
    defs[root] = parse_msg(blocks[0], root)
    for block in blocks[1:]:
        block = block.lstrip("\n")
        if not block.strip():
            continue
        first, _, body = block.partition("\n")
        if not first.startswith("MSG:"):
            raise SchemaError(
                f"schema of {root}: dependency block starts with {first!r}, expected 'MSG: pkg/Type'"
            )
        dep = normalize_type(first[4:].strip())
        defs[dep] = parse_msg(body, dep)
    return defs


def _prefixes(package: str) -> list[Path]:
    out: list[Path] = []
    for p in os.environ.get("AMENT_PREFIX_PATH", "").split(os.pathsep):
        if p:
            out.append(Path(p))
    out.append(Path(sys.prefix))
    try:  # the prefix a Python message package is installed in: <prefix>/lib/pythonX.Y/site-packages/pkg
        spec = importlib.util.find_spec(package)
        if spec and spec.origin:
            out.append(Path(spec.origin).resolve().parents[4])
    except (ImportError, ValueError, IndexError):
        pass
    return out


@functools.cache
def find_msg_file(name: str) -> Path:
    """Path of the installed ``.msg`` file of ``pkg/msg/Type``; SchemaError if none is installed."""
    pkg, typ = split_type(name)
    tried = []
    for prefix in _prefixes(pkg):
        path = prefix / "share" / pkg / "msg" / f"{typ}.msg"
        if path.is_file():
            return path
        tried.append(str(path.parent))
    raise SchemaError(
        f"message definition of {pkg}/msg/{typ} not found: no {typ}.msg in "
        f"{', '.join(dict.fromkeys(tried))} (is the package installed / AMENT_PREFIX_PATH set?)"
    )


def load_installed(name: str) -> dict[str, MsgDef]:
    """{type: MsgDef} for ``name`` and all its dependencies, from installed .msg files."""
    defs: dict[str, MsgDef] = {}
    order: list[str] = []

    def visit(t: str) -> None:
        if t in defs:
            return
        md = parse_msg(find_msg_file(t).read_text(), t)
        defs[t] = md
        order.append(t)
        for f in md.fields:
            if f.is_complex:
                visit(f.type)

    visit(normalize_type(name))
    return {t: defs[t] for t in order}


@functools.cache
def schema_text(name: str) -> str:
    """rosbag2/Foxglove ``ros2msg`` schema data of ``name``: .msg text + every dependency once."""
    defs = load_installed(name)
    root = normalize_type(name)
    out = defs[root].text
    for t, md in defs.items():
        if t != root:
            pkg, typ = split_type(t)
            out += f"\n{SEPARATOR}\nMSG: {pkg}/{typ}\n{md.text}"
    return out


@functools.cache
def type_hash(name: str) -> str:
    """RIHS01 type hash of ``name`` from the installed ``<Type>.json`` (ROS 2 Jazzy), or "" if absent."""
    try:
        path = find_msg_file(name).with_suffix(".json")
        data = json.loads(path.read_text())
    except (SchemaError, OSError, ValueError):
        return ""
    full = normalize_type(name)
    for entry in data.get("type_hashes", []):
        if entry.get("type_name") == full:
            return str(entry.get("hash_string", ""))
    return ""
