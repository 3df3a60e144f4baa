"""Declarative configuration: one field spec and one schema type for every configurable object.

A :class:`Field` says everything about one setting: name, type, default (or required), allowed range
(open or closed bounds), allowed choices, unit, meaning, whether it can change at run time and
whether it is a list. A :class:`Schema` is an ordered set of fields and nested sections; it
validates a nested config dict once (:meth:`Schema.validate`), with one-line
:class:`~friction_ros.core.validation.ParameterError` messages that name the parameter, the value
and what is allowed.

The friction models list their coefficients as fields (``FrictionModel.COEFS``); the plant
(:data:`friction_ros.core.plant.params.PLANT_SCHEMA`), the controller
(:data:`friction_ros.core.control.controller.CONTROLLER_FIELDS`), the online estimator
(:data:`friction_ros.core.estimation.estimator.ESTIMATOR_SCHEMA`) and a CAN drive axis
(:data:`friction_ros.core.can.axis.AXIS_SCHEMA`) have schemas next to the code they configure. The
ROS adapter derives parameter declarations, descriptors and run-time validation from the same
schemas (``friction_ros.nodes.parameters.declare_config``) and ``scripts/parameter-tables.py``
writes ``docs/parameters.md`` from them.

A config travels as a nested dict (``{"pid": {"p": 200.0}}``); ROS parameters are its dotted
flat form (``pid.p``): :func:`flatten` and :func:`unflatten` convert between the two.

Typed configs (the model of ros2_controllers' generate_parameter_library: the YAML layout is the
struct): :meth:`Schema.typed` validates a nested config once and returns a frozen dataclass
generated from the schema (a :class:`TypedConfig`): its attributes are the fields, nested sections
are nested frozen objects, and every name in an error is the full ROS parameter name
(``prefix`` + dotted path, or what ``names`` maps it to), so no message is renamed afterwards.
"""

from __future__ import annotations

import dataclasses
import keyword
from collections.abc import Callable, Iterable, Iterator, Mapping, Sequence
from dataclasses import dataclass
from types import MappingProxyType
from typing import Any

import numpy as np

from friction_ros.core.validation import (
    ParameterError,
    check_bool,
    check_choice,
    check_int,
    check_keys,
    check_real,
    range_text,
)

_TYPE_NAMES = {bool: "bool", int: "int", float: "float", str: "str"}

#: schema-relative dotted name (``friction.fc``) -> the parameter name a message shows
Names = Callable[[str], str]


class prefixed:
    """The :data:`Names` of a plain prefix: ``rel`` -> ``prefix.rel`` (``rel`` alone without prefix;
    '' -> the prefix)."""

    __slots__ = ("prefix",)

    def __init__(self, prefix: str):
        self.prefix = prefix

    def __call__(self, rel: str) -> str:
        return f"{self.prefix}.{rel}" if self.prefix and rel else (self.prefix or rel)

    def __deepcopy__(self, memo: dict) -> prefixed:  # immutable
        return self


class within:
    """The :data:`Names` of a section ``section`` of ``names``: ``rel`` -> ``names('section.rel')``."""

    __slots__ = ("names", "section")

    def __init__(self, names: Names, section: str):
        self.names, self.section = names, section

    def __call__(self, rel: str) -> str:
        return self.names(f"{self.section}.{rel}" if rel else self.section)

    def __deepcopy__(self, memo: dict) -> within:  # immutable
        return self


def names_of(path: str | Names) -> Names:
    """A :data:`Names` from a section path (``friction``) or a :data:`Names` as it is."""
    return path if callable(path) else prefixed(path)


@dataclass(frozen=True)
class Field:
    """One setting: name, default (None: required), meaning, range, choices, unit, type, list-ness.

    ``kind`` (bool, int, float or str) is taken from the default when not given (float for a
    required field). ``lo``/``hi`` bound numbers (and every element of a number list), open when
    ``lo_open``/``hi_open``; ``ros_range`` False keeps them out of the ROS descriptor (the node's
    own check then names a refused run-time value in the schema's words). ``read_only`` settings are fixed once the owner is built (a node
    refuses to change them at run time). A list field (``is_list``) holds elements of ``kind``; a
    required list must not be empty. Numbers must be finite unless ``allow_inf``.
    """

    name: str
    default: Any = None
    doc: str = ""
    lo: float | None = None
    hi: float | None = None
    choices: tuple[str, ...] = ()
    read_only: bool = False
    unit: str = ""
    lo_open: bool = False
    hi_open: bool = False
    kind: type | None = None
    is_list: bool = False
    allow_inf: bool = False
    ros_range: bool = True

    def __post_init__(self) -> None:
        default = self.default
        if isinstance(default, (list, tuple)):
            object.__setattr__(self, "is_list", True)
            object.__setattr__(self, "default", list(default))
            if self.kind is None:
                kind = str if default and isinstance(default[0], str) else float
                object.__setattr__(self, "kind", kind)
        elif self.kind is None:
            object.__setattr__(self, "kind", float if default is None else type(default))
        if self.kind not in _TYPE_NAMES:
            raise TypeError(f"field {self.name}: unsupported type {self.kind!r}")

    @property
    def required(self) -> bool:
        return self.default is None

    @property
    def type_name(self) -> str:
        """``float``, ``int``, ``bool``, ``str``, or ``float[]`` / ``str[]`` for lists."""
        return _TYPE_NAMES[self.kind] + ("[]" if self.is_list else "")

    def range_text(self) -> str:
        """The allowed values in words (``>= 0``, ``in (0, 1]``, ``one of a, b``; '' if any)."""
        if self.choices:
            return "one of " + ", ".join(self.choices)
        if self.kind in (int, float) and (self.lo is not None or self.hi is not None):
            return range_text(self.lo, self.hi, self.lo_open, self.hi_open)
        return ""

    def check(self, value: Any, key: str | None = None) -> Any:
        """Return ``value`` validated and normalised (int -> float for float fields, tuple -> list).

        Raises ParameterError naming ``key`` (default: the field's name), the value and what is
        allowed.
        """
        key = self.name if key is None else key
        if value is None:
            raise ParameterError(f"{key} is missing: required {self._required_text()}", key)
        if self.is_list:
            if isinstance(value, (str, bytes)) or not isinstance(value, (Sequence, np.ndarray)):
                what = "numbers (flat float list)" if self.kind in (int, float) else "strings"
                raise ParameterError(f"{key} = {value!r} must be a list of {what}", key)
            items = [self._check_one(x, f"{key}[{i}]") for i, x in enumerate(list(value))]
            if not items and self.required:
                raise ParameterError(f"{key} is empty: must hold at least one element", key)
            return items
        return self._check_one(value, key)

    def _check_one(self, value: Any, key: str) -> Any:
        if self.kind is float:
            return check_real(
                key,
                value,
                self.lo,
                self.hi,
                lo_open=self.lo_open,
                hi_open=self.hi_open,
                unit=self.unit,
                allow_inf=self.allow_inf,
            )
        if self.kind is int:
            return check_int(key, value, self.lo, self.hi)
        if self.kind is bool:
            return check_bool(key, value)
        if not isinstance(value, str):
            raise ParameterError(f"{key} = {value!r} has type {type(value).__name__}: must be str", key)
        if self.choices:
            check_choice(key, value, self.choices)
        return value

    def _required_text(self) -> str:
        unit = f" [{self.unit}]" if self.unit else ""
        doc = f"{self.doc}, " if self.doc else ""
        return f"({doc}{self.range_text() or self.type_name}{unit})"


class Schema:
    """An ordered set of fields and nested sections (a section is a Schema under its name).

    ``open`` sections hold keys that the object built from them validates (a friction model's
    coefficients depend on the chosen model): :meth:`validate` passes their extra keys through
    unchanged, and a ROS node declares the keys given in its parameter files.
    """

    def __init__(
        self,
        name: str,
        items: Iterable[Field | Schema] = (),
        doc: str = "",
        open: bool = False,
        read_only: bool = False,
    ):
        self.name = name
        self.doc = doc
        self.open = open
        self.read_only = read_only  # of the keys an open section gets from a parameter file
        self.items: dict[str, Field | Schema] = {}
        for item in items:
            if item.name in self.items:
                raise ValueError(f"schema {name}: {item.name} defined twice")
            self.items[item.name] = item

    @classmethod
    def from_defaults(
        cls, name: str, defaults: Mapping[str, Any], doc: str, read_only: bool = False
    ) -> Schema:
        """An open section typed by a defaults dict (None values: given in a parameter file only);
        the core object built from it checks names, ranges and cross-field rules itself."""
        items: list[Field | Schema] = []
        for k, v in defaults.items():
            if isinstance(v, Mapping):
                items.append(cls.from_defaults(k, v, f"{doc}: {k}", read_only))
            elif v is not None:
                default = list(v) if isinstance(v, tuple) else v
                items.append(Field(k, default, f"{doc}: {k}", read_only=read_only, allow_inf=True))
        return cls(name, items, doc=doc, open=True, read_only=read_only)

    def __iter__(self) -> Iterator[Field | Schema]:
        return iter(self.items.values())

    def fields(self, prefix: str = "") -> Iterator[tuple[str, Field]]:
        """``(dotted name, field)`` of every field, sections expanded, in order."""
        for item in self.items.values():
            if isinstance(item, Schema):
                yield from item.fields(f"{prefix}{item.name}.")
            else:
                yield f"{prefix}{item.name}", item

    def sections(self, prefix: str = "") -> Iterator[tuple[str, Schema]]:
        """``(dotted name, schema)`` of every nested section, in order."""
        for item in self.items.values():
            if isinstance(item, Schema):
                yield f"{prefix}{item.name}", item
                yield from item.sections(f"{prefix}{item.name}.")

    def defaults(self) -> dict[str, Any]:
        """Nested dict of the defaults (required fields left out)."""
        out: dict[str, Any] = {}
        for item in self.items.values():
            if isinstance(item, Schema):
                out[item.name] = item.defaults()
            elif item.default is not None:
                out[item.name] = list(item.default) if item.is_list else item.default
        return out

    def check_given(self, config: Mapping[str, Any], prefix: str | None = None) -> None:
        """Only the checks that need the whole section: unknown keys and missing required fields
        (for owners that check each value themselves, e.g. a dataclass's ``__post_init__``)."""
        prefix = self.name if prefix is None else prefix
        if not self.open:
            check_keys(prefix, config, self.items)
        for name, item in self.items.items():
            if isinstance(item, Field) and item.required and config.get(name) is None:
                item.check(None, f"{prefix}.{name}" if prefix else name)

    def validate(
        self, config: Mapping[str, Any] | None, prefix: str | None = None, names: Names | None = None
    ) -> dict[str, Any]:
        """Validate a nested config: unknown keys, missing required values, types, ranges, choices.

        Returns a new nested dict with every field (defaults filled in, values normalised). Names in
        messages start with ``prefix`` (default: the schema's name; '' for none), or are
        ``names(<dotted key>)`` when given (a per-joint layout).
        """
        if names is None:
            names = prefixed(self.name if prefix is None else prefix)
        return self._validate(config, names, "")

    def _validate(self, config: Mapping[str, Any] | None, names: Names, rel: str) -> dict[str, Any]:
        config = dict(config or {})
        if not self.open:
            check_keys(names(rel) or self.name, config, self.items)
        out: dict[str, Any] = {k: v for k, v in config.items() if k not in self.items}
        for name, item in self.items.items():
            sub = f"{rel}.{name}" if rel else name
            if isinstance(item, Schema):
                out[name] = item._validate(config.get(name), names, sub)
            else:
                out[name] = item.check(config.get(name, item.default), names(sub))
        return out

    def typed(
        self, config: Mapping[str, Any] | None, prefix: str = "", names: Names | None = None
    ) -> TypedConfig:
        """Validate ``config`` once (as :meth:`validate`) and return it as a frozen typed object.

        ``config`` is nested or in dotted ROS names (``pid.p``). Messages name ``prefix.<dotted key>``
        (``gains.joint2.friction.fc = -1 is out of range``), or ``names(<dotted key>)`` when given (a
        per-joint layout); the object's :meth:`TypedConfig.path` gives the same names to the code that
        checks cross-field rules.
        """
        names = prefixed(prefix) if names is None else names
        if config and any("." in str(k) for k in config):
            config = unflatten(config)
        return self._typed(self._validate(config, names, ""), names, "")

    def _typed(self, valid: Mapping[str, Any], names: Names, rel: str) -> TypedConfig:
        values: dict[str, Any] = {}
        for name, item in self.items.items():
            sub = f"{rel}.{name}" if rel else name
            v = valid[name]
            values[_attr(name)] = item._typed(v, names, sub) if isinstance(item, Schema) else _frozen(v)
        extra = MappingProxyType({k: _frozen(v) for k, v in valid.items() if k not in self.items})
        return self.typed_class()(**values, _extra=extra, _names=names, _rel=rel)

    def typed_class(self) -> type[TypedConfig]:
        """The frozen dataclass of this section (generated once per schema)."""
        cls = self.__dict__.get("_typed_cls")
        if cls is None:
            bad = [n for n in self.items if not _attr(n).isidentifier()]
            if bad:
                raise TypeError(f"schema {self.name}: {bad} cannot be attribute names")
            spec = [(_attr(n), Any) for n in self.items]
            for n, t in (("_extra", Mapping), ("_names", Any), ("_rel", str)):
                spec.append((n, t, dataclasses.field(repr=False, compare=False)))
            title = "".join(p.capitalize() for p in (self.name or "config").split("_"))
            cls = dataclasses.make_dataclass(title + "Config", spec, bases=(TypedConfig,), frozen=True)
            self._typed_cls = cls
        return cls


def _attr(key: str) -> str:
    """The attribute of a key: the key, with '_' appended to a Python keyword (``lambda_``)."""
    return f"{key}_" if keyword.iskeyword(key) else key


class TypedConfig:
    """Base of the frozen config objects :meth:`Schema.typed` generates (attributes: the fields;
    a key that is a Python keyword gets a trailing '_', e.g. ``lambda_``).

    ``cfg["key"]`` and :meth:`as_dict` keep dict access for code not yet converted; an open
    section's extra keys are in :meth:`as_dict` (and ``cfg["key"]``) only.
    """

    _extra: Mapping[str, Any]
    _names: Names
    _rel: str

    @property
    def extras(self) -> Mapping[str, Any]:
        """The keys of an open section that are no fields (read-only; the owner checks them)."""
        return self._extra

    def path(self, key: str = "") -> str:
        """The parameter name of ``key`` (a dotted key below this section; '' for the section)."""
        rel = ".".join(p for p in (self._rel, key) if p)
        return self._names(rel)

    def as_dict(self) -> dict[str, Any]:
        """A nested dict of the values (sections as dicts, lists as lists, extra keys included)."""
        out = {k: _thawed(v) for k, v in self._extra.items()}
        for f in dataclasses.fields(self):
            if not f.name.startswith("_"):
                v = getattr(self, f.name)
                key = f.name[:-1] if f.name.endswith("_") and keyword.iskeyword(f.name[:-1]) else f.name
                out[key] = v.as_dict() if isinstance(v, TypedConfig) else _thawed(v)
        return out

    def __getitem__(self, key: str) -> Any:
        return self.as_dict()[key]

    def get(self, key: str, default: Any = None) -> Any:
        return self.as_dict().get(key, default)


def _frozen(value: Any) -> Any:
    if isinstance(value, Mapping):
        return MappingProxyType({k: _frozen(v) for k, v in value.items()})
    if isinstance(value, list):
        return tuple(_frozen(v) for v in value)
    return value


def _thawed(value: Any) -> Any:
    if isinstance(value, Mapping):
        return {k: _thawed(v) for k, v in value.items()}
    if isinstance(value, tuple):
        return [_thawed(v) for v in value]
    return value


def flatten(config: Mapping[str, Any], prefix: str = "", *, keep_none: bool = False) -> dict[str, Any]:
    """Nested config -> dotted names (``{'pid': {'p': 1}} -> {'pid.p': 1}``); None values are dropped
    (a ROS parameter cannot be None) unless ``keep_none``."""
    flat: dict[str, Any] = {}
    for key, value in config.items():
        name = f"{prefix}{key}"
        if isinstance(value, Mapping):
            flat.update(flatten(value, name + ".", keep_none=keep_none))
        elif value is not None or keep_none:
            flat[name] = value
    return flat


def unflatten(flat: Mapping[str, Any]) -> dict[str, Any]:
    """Dotted names -> nested config (inverse of :func:`flatten`)."""
    nested: dict[str, Any] = {}
    for key, value in flat.items():
        parts = str(key).split(".")
        d = nested
        for p in parts[:-1]:
            nxt = d.setdefault(p, {})
            if not isinstance(nxt, dict):
                raise ParameterError(f"{key}: {p!r} is both a value and a section")
            d = nxt
        d[parts[-1]] = value
    return nested
