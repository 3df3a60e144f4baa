"""Load, gravity and position-dependent terms of a real joint, beside its friction model.

A geared joint on a robot carries more than friction. The torque it needs (REP-103 signs, SI):

    tau = J a + tau_load(q) + F(v) + k_L |tau_tr| sgn_eps(v) + sgn_eps(v) R(q)

* ``tau_load(q) = gravity sin(q + gravity_phase) + offset + spring q``: gravity of a link whose
  centre of mass is at angle ``-gravity_phase`` from the joint's zero (``gravity = m g l`` [N*m]),
  a constant torque (a counterweight, a cable, or an offset of the torque measurement) and a linear
  spring (cables, hoses, a gas spring) [N*m/rad];
* ``k_L |tau_tr|``: load-dependent friction, the friction a gear adds in proportion to the torque it
  transmits (gear efficiency; Rhoban BAM's load-dependent models, TMotorCANControl's ``fl``), with
  ``tau_tr = tau_load(q) + J a`` the torque the gear passes to the link (``load_friction`` = k_L
  [-]);
* ``R(q) = sum_k c_k cos(k w q) + s_k sin(k w q)``, ``w = 2 pi / ripple_period``: position-dependent
  friction, the Coulomb level rippling with gear meshing or harmonic-drive wave-generator angle
  (``ripple_period`` = 2 pi / N for a ripple at the motor angle of an N:1 gear);
* ``sgn_eps(v) = clip(v / eps, -1, 1)`` (ABB M19-S paper A.2.1).

``F(v)`` is the friction model (any of the library's); this module holds the rest, identified
jointly with inertia and friction by :mod:`friction_ros.core.identification.fit.load_terms` and used by
the controller as feedforward.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np

from friction_ros.core.config import Field, Schema, TypedConfig
from friction_ros.core.validation import ParameterError

JOINT_LOAD_SCHEMA = Schema(
    "load",
    [
        Field(
            "gravity",
            0.0,
            "gravity torque amplitude m*g*l: tau_g = gravity * sin(q + gravity_phase)",
            unit="N*m",
        ),
        Field(
            "gravity_phase",
            0.0,
            "angle added to q in the gravity term (centre of mass at q = -gravity_phase is horizontal)",
            lo=-math.pi,
            hi=math.pi,
            unit="rad",
        ),
        Field("offset", 0.0, "constant torque on the joint (tau_load += offset)", unit="N*m"),
        Field("spring", 0.0, "linear spring: tau_load += spring * q", unit="N*m/rad"),
        Field(
            "load_friction",
            0.0,
            "load-dependent friction k_L: friction += k_L * |tau_load(q) + J a| * sgn_eps(v)",
            lo=0.0,
            hi=1.0,
        ),
        Field(
            "ripple_period",
            2.0 * math.pi,
            "period of the position-dependent friction R(q) (2 pi / N for a ripple at the motor angle)",
            lo=0.0,
            lo_open=True,
            unit="rad",
        ),
        Field(
            "ripple_cos",
            [],
            "cosine coefficients c_k of R(q) = sum c_k cos(k w q) + s_k sin(k w q)",
            unit="N*m",
        ),
        Field("ripple_sin", [], "sine coefficients s_k of R(q) (same length as ripple_cos)", unit="N*m"),
        Field(
            "eps",
            1e-3,
            "linear-zone width of sgn(v) in the load-dependent and position-dependent friction",
            lo=0.0,
            lo_open=True,
            unit="rad/s",
        ),
    ],
    doc="load, gravity and position-dependent friction terms of the joint (feedforward)",
)


@dataclass
class JointLoad:
    """The terms of the module docstring, vectorised over arrays and cheap per scalar sample."""

    gravity: float = 0.0
    gravity_phase: float = 0.0
    offset: float = 0.0
    spring: float = 0.0
    load_friction: float = 0.0
    ripple_period: float = 2.0 * math.pi
    ripple_cos: list[float] = field(default_factory=list)
    ripple_sin: list[float] = field(default_factory=list)
    eps: float = 1e-3

    def __post_init__(self) -> None:
        if len(self.ripple_cos) != len(self.ripple_sin):
            raise ParameterError(
                f"load.ripple_sin has {len(self.ripple_sin)} values: must have as many as load.ripple_cos "
                f"({len(self.ripple_cos)})"
            )
        self._c = np.asarray(self.ripple_cos, dtype=float)
        self._s = np.asarray(self.ripple_sin, dtype=float)
        self._k = np.arange(1, self._c.size + 1, dtype=float) * (2.0 * math.pi / self.ripple_period)
        self._harmonics = tuple(
            (float(k), float(c), float(s)) for k, c, s in zip(self._k, self._c, self._s) if c or s
        )

    @classmethod
    def from_config(cls, config: Mapping | None, prefix: str = "load") -> JointLoad:
        """Validated from a ``load`` section (nested dict); unknown keys and bad values name the key."""
        return cls.from_section(JOINT_LOAD_SCHEMA.typed(config or {}, prefix))

    @classmethod
    def from_section(cls, c: TypedConfig) -> JointLoad:
        """From a typed ``load`` section (:data:`JOINT_LOAD_SCHEMA`), as it is; the one rule across
        its fields (as many sine as cosine coefficients) names the section's parameters."""
        if len(c.ripple_cos) != len(c.ripple_sin):
            raise ParameterError(
                f"{c.path('ripple_sin')} has {len(c.ripple_sin)} values: must have as many as "
                f"{c.path('ripple_cos')} ({len(c.ripple_cos)})"
            )
        return cls(
            c.gravity,
            c.gravity_phase,
            c.offset,
            c.spring,
            c.load_friction,
            c.ripple_period,
            list(c.ripple_cos),
            list(c.ripple_sin),
            c.eps,
        )

    def to_config(self) -> dict:
        return {
            "gravity": float(self.gravity),
            "gravity_phase": float(self.gravity_phase),
            "offset": float(self.offset),
            "spring": float(self.spring),
            "load_friction": float(self.load_friction),
            "ripple_period": float(self.ripple_period),
            "ripple_cos": [float(x) for x in self.ripple_cos],
            "ripple_sin": [float(x) for x in self.ripple_sin],
            "eps": float(self.eps),
        }

    @property
    def active(self) -> bool:
        return bool(
            self.gravity
            or self.offset
            or self.spring
            or self.load_friction
            or np.any(self._c)
            or np.any(self._s)
        )

    def load_torque(self, q):
        """tau_load(q) = gravity sin(q + gravity_phase) + offset + spring q [N*m]."""
        return (
            self.gravity * np.sin(np.asarray(q, dtype=float) + self.gravity_phase)
            + self.offset
            + self.spring * q
        )

    def ripple(self, q):
        """R(q) [N*m] (0 without harmonics)."""
        q = np.asarray(q, dtype=float)
        if not self._c.size:
            return np.zeros_like(q)
        arg = np.multiply.outer(q, self._k)
        return np.cos(arg) @ self._c + np.sin(arg) @ self._s

    def friction(self, v, q, transmitted):
        """The load- and position-dependent friction [N*m] for velocity v, angle q and transmitted
        torque ``transmitted`` (``tau_load(q) + J a``)."""
        sg = np.clip(np.asarray(v, dtype=float) / self.eps, -1.0, 1.0)
        return sg * (self.load_friction * np.abs(transmitted) + self.ripple(q))

    def torque(self, q, v, acceleration=0.0, inertia: float = 0.0):
        """Everything but F(v) and J a: tau_load(q) + load-dependent and position-dependent friction."""
        tl = self.load_torque(q)
        return tl + self.friction(v, q, tl + inertia * np.asarray(acceleration, dtype=float))

    def scalar_parts(self, q: float, acceleration: float = 0.0, inertia: float = 0.0) -> tuple[float, float]:
        """``(tau_load(q), k_L |tau_load(q) + J a| + R(q))`` for one sample, math only (no numpy):
        the load torque and the friction level that sgn_eps(v) multiplies (a 1 kHz loop's cost:
        one sin, plus a cos/sin pair per ripple harmonic)."""
        tl = self.gravity * math.sin(q + self.gravity_phase) + self.offset + self.spring * q
        level = self.load_friction * abs(tl + inertia * acceleration) if self.load_friction else 0.0
        for k, c, s in self._harmonics:
            a = k * q
            level += c * math.cos(a) + s * math.sin(a)
        return tl, level

    def torque_scalar(self, q: float, v: float, acceleration: float = 0.0, inertia: float = 0.0) -> float:
        """:meth:`torque` for one sample, without numpy (a few microseconds in a 1 kHz loop)."""
        tl, level = self.scalar_parts(q, acceleration, inertia)
        return tl + min(max(v / self.eps, -1.0), 1.0) * level
