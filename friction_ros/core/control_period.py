"""The control period: its default and allowed range, owned here for the plant presets
(:class:`~friction_ros.core.presets.Preset` ``control_period``) and every node's ``control_period``
parameter (drive_interface's too). A module of its own so a node that
needs only the parameter does not load the plant and its compiled kernels."""

from __future__ import annotations

from typing import Any

from friction_ros.core.config import Field
from friction_ros.core.validation import check_real

#: The control period [s] of a plant whose preset does not give one, and the default of every node's
#: ``control_period`` parameter.
DEFAULT_CONTROL_PERIOD = 1e-3
#: The range [s] a control period must lie in (the plant's preset and the nodes' parameters).
CONTROL_PERIOD_RANGE = (1e-5, 0.1)


def control_period_field(doc: str, hi: float = CONTROL_PERIOD_RANGE[1]) -> Field:
    """A node's read-only ``control_period`` parameter [s]: default and range owned here."""
    return Field(
        "control_period",
        DEFAULT_CONTROL_PERIOD,
        doc,
        lo=CONTROL_PERIOD_RANGE[0],
        hi=hi,
        unit="s",
        read_only=True,
    )


def check_control_period(name: str, value: Any) -> float:
    """``value`` as a control period [s] within :data:`CONTROL_PERIOD_RANGE`, else ParameterError."""
    return check_real(name, value, *CONTROL_PERIOD_RANGE, unit="s")
