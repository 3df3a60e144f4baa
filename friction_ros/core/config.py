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
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator, Mapping, Sequence
from dataclasses import dataclass
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


@dataclass(frozen=True)
class Field:
    """One setting: name, default (None: required), meaning, range, choices, unit, type, list-ness.

    ``kind`` (bool, int, float or str) is taken from the default when not given (float for a
    required field). ``lo``/``hi`` bound numbers (and every element of a number list), open when
    ``lo_open``/``hi_open``. ``read_only`` settings are fixed once the owner is built (a node
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
            raise ParameterError(f"{key} is missing: required {self._required_text()}")
        if self.is_list:
            if isinstance(value, (str, bytes)) or not isinstance(value, (Sequence, np.ndarray)):
                what = "numbers (flat float list)" if self.kind in (int, float) else "strings"
                raise ParameterError(f"{key} = {value!r} must be a list of {what}")
            items = [self._check_one(x, f"{key}[{i}]") for i, x in enumerate(list(value))]
            if not items and self.required:
                raise ParameterError(f"{key} is empty: must hold at least one element")
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
            raise ParameterError(f"{key} = {value!r} has type {type(value).__name__}: must be str")
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

    def validate(self, config: Mapping[str, Any] | None, prefix: str | None = None) -> dict[str, Any]:
        """Validate a nested config: unknown keys, missing required values, types, ranges, choices.

        Returns a new nested dict with every field (defaults filled in, values normalised). Names in
        messages start with ``prefix`` (default: the schema's name; '' for none).
        """
        config = dict(config or {})
        prefix = self.name if prefix is None else prefix
        dot = f"{prefix}." if prefix else ""
        if not self.open:
            check_keys(prefix or self.name, config, self.items)
        out: dict[str, Any] = {k: v for k, v in config.items() if k not in self.items}
        for name, item in self.items.items():
            if isinstance(item, Schema):
                out[name] = item.validate(config.get(name), f"{dot}{name}")
            else:
                out[name] = item.check(config.get(name, item.default), f"{dot}{name}")
        return out


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
