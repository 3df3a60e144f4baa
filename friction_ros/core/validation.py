"""Parameter validation shared by every core object.

Every bad value raises :class:`ParameterError` with a message that names the parameter, the value
and the allowed range or values, so nodes and CLIs can print one clear line instead of a traceback.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping
from typing import Any

import numpy as np


class ParameterError(ValueError):
    """A parameter is missing, of the wrong type or outside its allowed range.

    ``parameter``: the name of the one parameter the message is about (as the check was given it),
    None for a rule across several values.
    """

    def __init__(self, message: str = "", parameter: str | None = None):
        super().__init__(message)
        self.parameter = parameter


def range_text(lo: float | None, hi: float | None, lo_open: bool = False, hi_open: bool = False) -> str:
    """``in [lo, hi], i.e. >= lo and <= hi`` (round brackets for open bounds), ``>= lo``, ``<= hi``, or ``finite``."""
    if lo is not None and hi is not None:
        interval = f"{'(' if lo_open else '['}{lo:g}, {hi:g}{')' if hi_open else ']'}"
        return f"in {interval}, i.e. {'>' if lo_open else '>='} {lo:g} and {'<' if hi_open else '<='} {hi:g}"
    if lo is not None:
        return f"{'>' if lo_open else '>='} {lo:g}"
    if hi is not None:
        return f"{'<' if hi_open else '<='} {hi:g}"
    return "finite"


def check_real(
    name: str,
    value: Any,
    lo: float | None = None,
    hi: float | None = None,
    *,
    lo_open: bool = False,
    hi_open: bool = False,
    unit: str = "",
    allow_inf: bool = False,
) -> float:
    """Return ``value`` as float, or raise ParameterError naming ``name`` and the allowed range."""
    unit_s = f" [{unit}]" if unit else ""
    allowed = range_text(lo, hi, lo_open, hi_open)
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        try:
            if isinstance(value, np.generic) and np.isreal(value):
                value = float(value)
            else:
                raise TypeError
        except TypeError:
            raise ParameterError(
                f"{name} = {value!r} has type {type(value).__name__}: must be float, a number"
                + ("" if allowed == "finite" else f" {allowed}")
                + unit_s,
                name,
            ) from None
    x = float(value)
    if math.isnan(x):
        raise ParameterError(
            f"{name} = nan is not finite (nan is not a number): must be {allowed}{unit_s}", name
        )
    if math.isinf(x) and not allow_inf:
        raise ParameterError(f"{name} = {x} is not finite: must be a number {allowed}{unit_s}", name)
    bad = (lo is not None and (x <= lo if lo_open else x < lo)) or (
        hi is not None and (x >= hi if hi_open else x > hi)
    )
    if bad:
        raise ParameterError(f"{name} = {x:g} is out of range: must be {allowed}{unit_s}", name)
    return x


def check_int(name: str, value: Any, lo: int | None = None, hi: int | None = None) -> int:
    """Return ``value`` as int, or raise ParameterError naming the allowed range."""
    allowed = "" if lo is None and hi is None else " " + range_text(lo, hi)
    if isinstance(value, bool) or not isinstance(value, int):
        if isinstance(value, float) and value.is_integer():
            value = int(value)
        else:
            raise ParameterError(f"{name} = {value!r} must be an integer{allowed}", name)
    if (lo is not None and value < lo) or (hi is not None and value > hi):
        raise ParameterError(f"{name} = {value} is out of range: must be an integer{allowed}", name)
    return int(value)


def check_choice(name: str, value: Any, choices: Iterable[str]) -> str:
    """Return ``value`` if it is one of ``choices``, else raise ParameterError listing them."""
    choices = list(choices)
    if value not in choices:
        raise ParameterError(
            f"{name} = {value!r} is not allowed: must be one of {', '.join(map(str, choices))}", name
        )
    return value


def check_bool(name: str, value: Any) -> bool:
    """Return ``value`` if it is a bool, else raise ParameterError."""
    if not isinstance(value, bool):
        raise ParameterError(f"{name} = {value!r} must be true or false", name)
    return value


def check_keys(section: str, given: Mapping[str, Any], allowed: Iterable[str]) -> None:
    """Raise ParameterError if ``given`` has keys outside ``allowed`` (typos in YAML files)."""
    allowed = list(allowed)
    unknown = [k for k in given if k not in allowed]
    if unknown:
        raise ParameterError(
            f"{section}: unknown parameter(s) {', '.join(map(repr, unknown))}: "
            f"allowed are {', '.join(allowed)}",
            section,
        )
