"""PID with the parameter names of ros2_controllers ``pid_controller`` / control_toolbox ``Pid``.

Law (control_toolbox ``Pid::compute_command`` semantics, anchors section 1.1-1.2), per period dt::

    e      = reference - measurement            (zeroed inside +-error_deadband)
    p_term = p * e
    d_term = d * e_dot_f                         e_dot_f: first-order filtered error rate
    i_term = I                                   integrator state, already multiplied by i
    u      = p_term + i_term + d_term + offset   offset: feed-forward terms of the caller
    u_sat  = clamp(u, max(u_clamp_min, lo), min(u_clamp_max, hi))   lo/hi: caller (rate) bounds

and the integrator is advanced after the output is formed (forward Euler), with the anti-windup
strategy of control_toolbox ``AntiWindupStrategy``:

* ``none``:                    I += i e dt, then I clamped to [i_clamp_min, i_clamp_max]
* ``back_calculation``:        I += dt (i e + (u_sat - u) / T_t), T_t = tracking_time_constant
  (0 -> control_toolbox default: sqrt(d / i) if d != 0 else p / i), then clamped
* ``conditional_integration`` (default; control_toolbox's is ``none``): I += i e dt only if the
  output is not saturated or e drives it out of saturation, then clamped

``integral_lower``/``integral_upper`` of :meth:`Pid.update` bound I further (the façade passes its
torque clamp: an integral beyond the output range can never be applied, only wound up).

"Derivative on measurement" means the caller supplies ``e_dot = v_ref - v_measured`` (no
derivative kick on reference steps); ``derivative_filter_time_constant`` T_f low-pass filters the
rate: e_dot_f += dt / (T_f + dt) (e_dot - e_dot_f) (backward-Euler first-order filter).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from types import SimpleNamespace
from typing import Any

from friction_ros.core.config import Field, Names, Schema, TypedConfig
from friction_ros.core.control.command_safety import PLAUSIBLE_GAIN
from friction_ros.core.validation import ParameterError

ANTIWINDUP_STRATEGIES = ("none", "back_calculation", "conditional_integration")

#: The PID's settings (control_toolbox names): the compensating_controller's ``pid.*`` parameters,
#: with their ranges (no ROS ranges: a refused run-time change is named in these words).
_G = {"lo": 0.0, "hi": PLAUSIBLE_GAIN, "allow_inf": True}
PID_SCHEMA = Schema(
    "pid",
    [
        Field("p", 0.0, "proportional gain: p_term = p * e", unit="N*m/rad", **_G),
        Field("i", 0.0, "integral gain: I += i * e * dt", unit="N*m/(rad*s)", **_G),
        Field("d", 0.0, "derivative gain on the (filtered) error rate", unit="N*m*s/rad", **_G),
        Field("i_clamp_max", math.inf, "upper bound of the integral term I", unit="N*m", allow_inf=True),
        Field(
            "i_clamp_min",
            -math.inf,
            "lower bound of the integral term I (<= i_clamp_max)",
            unit="N*m",
            allow_inf=True,
        ),
        Field(
            "antiwindup_strategy",
            "conditional_integration",
            "none, back_calculation or conditional_integration (control_toolbox AntiWindupStrategy)",
            choices=ANTIWINDUP_STRATEGIES,
        ),
        Field(
            "tracking_time_constant",
            0.0,
            "back_calculation: T_t (0: sqrt(d / i) if d != 0 else p / i)",
            lo=0.0,
            unit="s",
            ros_range=False,
        ),
        Field("u_clamp_max", math.inf, "upper bound of the PID output", unit="N*m", allow_inf=True),
        Field(
            "u_clamp_min",
            -math.inf,
            "lower bound of the PID output (< u_clamp_max)",
            unit="N*m",
            allow_inf=True,
        ),
        Field("error_deadband", 0.0, "|e| below this counts as 0", lo=0.0, unit="rad", ros_range=False),
        Field(
            "derivative_filter_time_constant",
            0.0,
            "first-order filter of the error rate (0: unfiltered)",
            lo=0.0,
            unit="s",
            ros_range=False,
        ),
    ],
    doc="PID gains and limits",
)
PID_DEFAULTS: dict[str, Any] = PID_SCHEMA.defaults()


@dataclass(slots=True)
class PidOutput:
    """Terms of one PID evaluation (N*m)."""

    p_term: float
    i_term: float
    d_term: float
    error: float
    error_dot: float
    unlimited: float
    command: float
    saturated: bool


class Pid:
    """PID controller; see the module docstring for the law and the anti-windup strategies."""

    def __init__(self, config: Mapping[str, Any] | None = None, *, prefix: str = "pid", **kwargs):
        """From a dict of control_toolbox names and/or keywords (``Pid(p=1.0)``), typed once with
        :data:`PID_SCHEMA`; messages name ``prefix.<key>``."""
        typed = PID_SCHEMA.typed({**dict(config or {}), **kwargs}, prefix)
        self._set(typed, typed.path)
        self.reset()

    @classmethod
    def from_config(cls, config: TypedConfig) -> Pid:
        """From a typed ``pid`` section (:data:`PID_SCHEMA`), as it is."""
        self = cls.__new__(cls)
        self._set(config, config.path)
        self.reset()
        return self

    @classmethod
    def from_checked(cls, names: Names, **values: Any) -> Pid:
        """From gains that a typed section of the owner checked already against the ranges of
        :data:`PID_SCHEMA` (the cascade's velocity PI: the cascade's own fields), the other keys at
        their defaults; only the rules across fields run. ``names``: the parameter names in messages."""
        self = cls.__new__(cls)
        self._set(SimpleNamespace(**{**PID_DEFAULTS, **values}), names)
        self.reset()
        return self

    def _set(self, cfg: TypedConfig | SimpleNamespace, names: Names) -> None:
        """Take checked values (a typed section); only the rules across fields are checked here."""
        imax, imin, umax, umin = cfg.i_clamp_max, cfg.i_clamp_min, cfg.u_clamp_max, cfg.u_clamp_min
        if imin > imax:
            raise ParameterError(f"{names('i_clamp_min')} = {imin:g} is out of range: must be <= {imax:g}")
        if umin >= umax:
            raise ParameterError(f"{names('u_clamp_min')} = {umin:g} is out of range: must be < u_clamp_max")
        self._names = names
        self.p, self.i, self.d = cfg.p, cfg.i, cfg.d
        self.i_clamp_max, self.i_clamp_min = imax, imin
        self.u_clamp_max, self.u_clamp_min = umax, umin
        self.antiwindup_strategy = cfg.antiwindup_strategy
        self.tracking_time_constant = cfg.tracking_time_constant
        self.error_deadband = cfg.error_deadband
        self.derivative_filter_time_constant = cfg.derivative_filter_time_constant

    @property
    def prefix(self) -> str:
        """How messages name this PID's section."""
        return self._names("")

    def config(self) -> dict[str, Any]:
        """Current parameters as a dict with control_toolbox names."""
        return {k: getattr(self, k) for k in PID_DEFAULTS}

    def set_gains(self, **kwargs) -> None:
        """Change parameters at run time (typed as a whole; nothing changes on error)."""
        self._set(PID_SCHEMA.typed({**self.config(), **kwargs}, names=self._names), self._names)
        self.integral = min(max(self.integral, self.i_clamp_min), self.i_clamp_max)

    def reset(self, integral: float = 0.0) -> None:
        self.integral = float(integral)
        self._edot_f = None
        self._prev_error = None

    def _effective_tt(self) -> float:
        if self.tracking_time_constant > 0.0:
            return self.tracking_time_constant
        if self.i <= 0.0:
            return math.inf
        if self.d > 0.0:
            return math.sqrt(self.d / self.i)
        return self.p / self.i if self.p > 0.0 else 1.0

    def update(
        self,
        error: float,
        dt: float,
        error_dot: float | None = None,
        offset: float = 0.0,
        lower: float = -math.inf,
        upper: float = math.inf,
        integral_lower: float = -math.inf,
        integral_upper: float = math.inf,
    ) -> PidOutput:
        """One period. ``error_dot`` None -> filtered backward difference of ``error``.

        ``offset`` (feed-forward) is added before limiting so anti-windup sees the real command;
        ``lower``/``upper`` are extra command bounds (e.g. from a rate limit);
        ``integral_lower``/``integral_upper`` extra bounds of the integrator state.
        """
        if not dt > 0.0:
            raise ParameterError(f"{self.prefix}: dt = {dt!r} is out of range: must be > 0 [s]")
        e = float(error)
        if abs(e) <= self.error_deadband:
            e = 0.0
        if error_dot is None:
            raw = 0.0 if self._prev_error is None else (e - self._prev_error) / dt
        else:
            raw = float(error_dot)
        self._prev_error = e
        tf = self.derivative_filter_time_constant
        if tf > 0.0 and self._edot_f is not None:
            self._edot_f += dt / (tf + dt) * (raw - self._edot_f)
        else:
            self._edot_f = raw
        edot = self._edot_f
        p_term = self.p * e
        d_term = self.d * edot
        i_term = self.integral
        u = p_term + i_term + d_term + offset
        lo = max(self.u_clamp_min, lower)
        hi = min(self.u_clamp_max, upper)
        if lo > hi:  # rate window outside the clamp range: the clamp wins
            lo = hi = min(max(0.5 * (lower + upper), self.u_clamp_min), self.u_clamp_max)
        u_sat = min(max(u, lo), hi)
        saturated = u_sat != u
        # integrator update (forward Euler, after use)
        if self.i > 0.0:
            if self.antiwindup_strategy == "back_calculation":
                self.integral += dt * (self.i * e + (u_sat - u) / self._effective_tt())
            elif self.antiwindup_strategy == "conditional_integration":
                if not saturated or (e * (u - u_sat) < 0.0):
                    self.integral += dt * self.i * e
            else:
                self.integral += dt * self.i * e
            self.integral = min(
                max(self.integral, self.i_clamp_min, integral_lower), self.i_clamp_max, integral_upper
            )
        return PidOutput(p_term, i_term, d_term, e, edot, u, u_sat, saturated)
