"""The source documents' specific control schemes (feedback parts; the façade adds feed-forward and limits).

* :class:`DNPF` ABB M19-S paper A.4.2 (Southward et al. 1991): discontinuous nonlinear proportional
  feedback, constant ``tau_st + epsilon`` inside the presliding distance ``Q_h``.
* :class:`GainScheduling` ABB M19-S paper A.4.3 (Fig. 10): mode 1 PD + Coulomb compensation, mode 2
  presliding gains scheduled from the describing-function stiffness ``k_e(A)`` and damping
  ``c_e(A)`` of the GMS virgin curve (eqs. (5)-(6), sign of (6) fixed: the OCR text garbles it).
* :class:`Cascade` ABB M19-S paper A.4.4: position P -> velocity PI with velocity feed-forward (the
  integrating baseline).
* :class:`SlidingMode` Chatterjee et al. 2017 A.5.1 (b)-(d): ``S = e_dot + lambda e``,
  ``u = J_hat lambda e_dot + k_s S + M sat(S / phi)`` (phi = 0: relay ``M sign(S)``).
* :func:`sliding_mode_relay` Chatterjee et al. 2017 A.5.2 (``f_motor_smc.m``):
  ``u = u0 - du sign_dz(x; band)``.

Every scheme has ``compute(e, e_dot, ref, meas, dt) -> SchemeOutput`` and ``reset()``.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from friction_ros.core.config import Field, Schema, TypedConfig, within
from friction_ros.core.control.command_safety import PLAUSIBLE_GAIN
from friction_ros.core.control.pid import Pid
from friction_ros.core.validation import ParameterError, check_real

COULOMB_SOURCES = ("measured", "reference")
SCHEDULES = ("bias", "stiffness")

# ---------------------------------------------------------------------------------------------------
# describing function of a presliding virgin curve (ABB M19-S paper A.4.3 eqs. (5)-(6))


def maxwell_virgin_curve(k: Sequence[float], alpha: Sequence[float], fs: float) -> Callable:
    """Maxwell-slip virgin curve y(x) = sum_i min(k_i |x|, alpha_i Fs) sgn(x) (ABB M19-S paper A.2.4)."""
    k = np.asarray(k, dtype=float)[:, None]
    w = (np.asarray(alpha, dtype=float) * float(fs))[:, None]

    def y(x):
        x = np.asarray(x, dtype=float)
        ax = np.abs(x).reshape(1, -1)
        out = np.minimum(k * ax, w).sum(axis=0).reshape(x.shape)
        return np.sign(x) * out

    return y


def describing_stiffness(y: Callable, A: float, n: int = 2001) -> float:
    """k_e(A) = -(4 / (A pi)) int_0^pi y((A/2)(1 - cos th)) cos th dth  (ABB M19-S paper eq. (5))."""
    th = np.linspace(0.0, math.pi, n)
    f = y(0.5 * A * (1.0 - np.cos(th))) * np.cos(th)
    return float(-4.0 / (A * math.pi) * np.trapezoid(f, th))


def describing_damping(y: Callable, A: float, omega: float = 1.0, n: int = 2001) -> float:
    """c_e(A) = +(8 / (pi A^2 omega)) int_0^A (y(u) - y(A)/2) du >= 0.

    ABB M19-S paper eq. (6) with its sign fixed (section A.4.3 of the notes on it): the printed form gives
    c_e omega <= 0 for a concave virgin curve; the magnitude is the equivalent viscous damping.
    With ``omega = 1`` the value returned is ``c_e * omega``.
    """
    u = np.linspace(0.0, A, n)
    f = y(u) - 0.5 * float(y(np.array([A]))[0])
    return float(8.0 / (math.pi * A * A * omega) * np.trapezoid(f, u))


@dataclass(slots=True)
class SchemeOutput:
    """Feedback terms of one scheme evaluation (N*m)."""

    p_term: float = 0.0
    i_term: float = 0.0
    d_term: float = 0.0
    velocity_feedforward: float = 0.0
    friction_feedback: float = 0.0


def _f(name: str, default: Any, doc: str, unit: str = "", **bounds: Any) -> Field:
    """A scheme setting; its range is checked when the section is typed (no ROS range)."""
    return Field(name, default, doc, unit=unit, ros_range=False, **bounds)


class _Scheme:
    """A scheme is built from its typed section (``SCHEMA``, typed by the controller's config);
    :meth:`from_dict` types a section dict first (scripts, tests)."""

    SCHEMA: Schema

    @classmethod
    def from_dict(cls, config: Mapping[str, Any] | None = None, *args: Any):
        """From a section dict: typed once against ``SCHEMA`` (messages name ``<section>.<key>``)."""
        return cls(cls.SCHEMA.typed(config or {}, cls.SCHEMA.name), *args)


# ---------------------------------------------------------------------------------------------------


class DNPF(_Scheme):
    """ABB M19-S paper A.4.2 DNPF (Southward et al. 1991), used without feed-forward.

    u_P(e) = K_p e for |e| > Q_h; (tau_st + epsilon) sgn(e) for zero_band < |e| <= Q_h; 0 inside
    zero_band (default: none); u = u_P(e) + K_d e_dot. ``kp = 0`` selects the continuous choice
    K_p = (tau_st + epsilon) / Q_h.
    """

    SCHEMA = Schema(
        "dnpf",
        [
            _f("q_h", 0.004, "presliding distance Q_h", "rad", lo=0.0, lo_open=True),
            _f("tau_st", 0.95, "breakaway torque tau_st", "N*m", lo=0.0),
            _f("epsilon", 0.05, "margin epsilon above tau_st", "N*m", lo=0.0),
            _f("kp", 0.0, "K_p beyond Q_h (0: (tau_st + epsilon) / Q_h)", "N*m/rad", lo=0.0),
            _f("kd", 0.15, "K_d", "N*m*s/rad", lo=0.0),
            _f("zero_band", 0.0, "no torque inside |e| <= zero_band (<= q_h)", "rad", lo=0.0),
        ],
        doc="dnpf parameter",
    )
    DEFAULTS = SCHEMA.defaults()

    def __init__(self, c: TypedConfig):
        self.q_h, self.tau_st, self.epsilon, self.kd = c.q_h, c.tau_st, c.epsilon, c.kd
        self.kp = c.kp if c.kp > 0.0 else (self.tau_st + self.epsilon) / self.q_h
        if c.zero_band > self.q_h:
            raise ParameterError(
                f"{c.path('zero_band')} = {c.zero_band:g} is out of range: must be in [0, {self.q_h:g}], "
                f"i.e. >= 0 and <= {self.q_h:g} [rad]"
            )
        self.zero_band = c.zero_band

    def config(self) -> dict[str, Any]:
        return {k: getattr(self, k) for k in self.DEFAULTS}

    def proportional(self, e: float) -> float:
        ae = abs(e)
        if ae <= self.zero_band or e == 0.0:
            return 0.0
        if ae <= self.q_h:
            return math.copysign(self.tau_st + self.epsilon, e)
        return self.kp * e

    def reset(self) -> None:
        pass

    def compute(self, e, edot, ref, meas, dt) -> SchemeOutput:
        return SchemeOutput(p_term=self.proportional(e), d_term=self.kd * edot)


class GainScheduling(_Scheme):
    """ABB M19-S paper A.4.3 gain-scheduling controller (Fig. 10), no integrator.

    Mode 1 (gross sliding): ``u = kp e + kd e_dot + F_c sgn(v_c)`` (Coulomb compensation with a
    linear zone |v_c| < coulomb_velocity; v_c = measured velocity, or the reference velocity with
    ``coulomb_source = reference``). ``coulomb_deadband`` > 0 switches the compensation off while
    |v_c| <= coulomb_deadband (a measured-velocity linear zone acts as negative damping
    F_c / coulomb_velocity on the presliding spring; a dead band does not).
    Switch to mode 2 when |v| <= standstill_velocity, |e| < q_h and the reference rests
    (presliding); back to mode 1 when |e| > q_h or the reference moves. In mode 2 the terms are
    re-scheduled at entry and again at every standstill that lasts ``dwell`` seconds while
    |e| > tolerance ("gains adjusted repeatedly", A.4.3), with A = |e|, k_e(A) from eq. (5) and
    c_e(A) from eq. (6) of the GMS virgin curve [schedules NOT IN PAPER]:

    ``schedule = bias`` (default, ours): the frictional presliding spring is k_e(A); the torque
    that moves the stuck shaft the remaining distance A is held as a bias,

        u_b <- u_b + (kp + k_e(A)) e,   kd2 = max(0, kd - c_e(A))   (total damping kd kept)
        u = kp e + kd2 e_dot + u_b

    (a linear spring reaches e = 0 in one re-adjustment; the softening virgin curve needs 1-3).
    ``schedule = stiffness`` (ABB M19-S paper A.4.3 suggestion, made cumulative):

        kp2 <- min(kp2 + k_e(A), kp_max)
        kd2 <- max(0, 2 zeta sqrt((kp2 + k_e(A)) J) - c_e(A) omega_A),  omega_A = sqrt((kp2 + k_e) / J)
        u = kp2 e + kd2 e_dot

    so the residual error shrinks geometrically, e <- k_e / (kp2 + k_e) e, until kp_max.
    The virgin curve is the GMS one: ``k``, ``alpha``, ``fs`` (or a GMS ``model`` config).
    """

    SCHEMA = Schema(
        "gain_scheduling",
        [
            _f("kp", 200.0, "mode 1 K_p", "N*m/rad", lo=0.0),
            _f("kd", 0.15, "mode 1 K_d", "N*m*s/rad", lo=0.0),
            _f("coulomb", 0.8, "Coulomb compensation F_c", "N*m", lo=0.0),
            _f("coulomb_velocity", 0.01, "linear zone of the Coulomb compensation", "rad/s", lo=0.0),
            Field(
                "coulomb_source", "measured", "velocity of the Coulomb compensation", choices=COULOMB_SOURCES
            ),
            _f("coulomb_deadband", 0.0, "no Coulomb compensation while |v_c| <= this", "rad/s", lo=0.0),
            Field("schedule", "bias", "mode 2 schedule: bias or stiffness", choices=SCHEDULES),
            _f("q_h", 0.004, "presliding distance: mode 2 while |e| < q_h", "rad", lo=0.0, lo_open=True),
            _f("standstill_velocity", 1e-3, "standstill: |v| <= this", "rad/s", lo=0.0),
            _f("dwell", 0.01, "standstill time before a re-adjustment", "s", lo=0.0),
            _f("tolerance", 5e-5, "no re-adjustment while |e| <= this", "rad", lo=0.0),
            _f("zeta", 0.7, "damping ratio of the stiffness schedule", lo=0.0, hi=5.0),
            _f("kp_max", 2000.0, "largest scheduled K_p (>= kp)", "N*m/rad", lo=0.0),
            _f("inertia", 0.0012, "J of the stiffness schedule", "kg*m^2", lo=0.0, lo_open=True),
        ],
        doc="gain_scheduling parameter: the virgin curve k, alpha, fs (or a GMS model config) is checked by GainScheduling",
        open=True,
    )
    DEFAULTS = {**SCHEMA.defaults(), "k": None, "alpha": None, "fs": None, "model": None}

    @staticmethod
    def has_virgin_curve(model) -> bool:
        """Whether a library ``model`` carries a Maxwell-slip virgin curve (``k``, ``alpha``, ``fs``)."""
        c = model.coefficients
        return all(key in c for key in ("k", "alpha", "fs"))

    def __init__(self, c: TypedConfig, model=None):
        """``model``: a library model whose virgin curve is used when the section gives none."""
        self.kp, self.kd, self.coulomb = c.kp, c.kd, c.coulomb
        self.coulomb_velocity, self.coulomb_source = c.coulomb_velocity, c.coulomb_source
        self.coulomb_deadband, self.schedule_kind, self.q_h = c.coulomb_deadband, c.schedule, c.q_h
        self.standstill_velocity, self.dwell, self.tolerance = c.standstill_velocity, c.dwell, c.tolerance
        self.zeta, self.inertia = c.zeta, c.inertia
        if c.kp_max < self.kp:
            raise ParameterError(
                f"{c.path('kp_max')} = {c.kp_max:g} is out of range: must be >= {self.kp:g} [N*m/rad]"
            )
        self.kp_max = c.kp_max
        extra, n = c.extras, c.path()
        k, alpha, fs, given_model = (extra.get(key) for key in ("k", "alpha", "fs", "model"))
        if k is None and given_model is None and model is not None and self.has_virgin_curve(model):
            given_model = model
        if given_model is not None:
            m = given_model
            coefs = m.coefficients if hasattr(m, "coefficients") else m
            try:
                k, alpha, fs = coefs["k"], coefs["alpha"], coefs["fs"]
            except KeyError:
                raise ParameterError(
                    f"{n}.model must be a GMS model config with k, alpha and fs (got keys {sorted(coefs)})"
                ) from None
        if k is None or alpha is None or fs is None:
            raise ParameterError(f"{n}: the virgin curve needs k, alpha and fs (or a GMS model config)")
        k = [check_real(f"{n}.k[{i}]", x, 0.0, lo_open=True, unit="N*m/rad") for i, x in enumerate(k)]
        alpha = [check_real(f"{n}.alpha[{i}]", x, 0.0, lo_open=True) for i, x in enumerate(alpha)]
        if len(k) != len(alpha) or not k:
            raise ParameterError(f"{n}: k has {len(k)} elements, alpha {len(alpha)}: must be equal and > 0")
        self.k, self.alpha = k, alpha
        self.fs = check_real(f"{n}.fs", fs, 0.0, lo_open=True, unit="N*m")
        self.virgin = maxwell_virgin_curve(k, alpha, self.fs)
        self.reset()

    def config(self) -> dict[str, Any]:
        out = {k: getattr(self, k) for k in self.DEFAULTS if k not in ("model", "schedule")}
        out["schedule"] = self.schedule_kind
        return out

    def reset(self) -> None:
        self.mode = 1
        self.kp2 = self.kp
        self.kd2 = self.kd
        self._still = 0.0
        self._adjusted = False
        self.adjustments = 0
        self.bias = 0.0

    def schedule(self, A: float) -> tuple[float, float]:
        """Return (kp2, kd2) after one ``stiffness`` re-adjustment at amplitude A (class docstring)."""
        A = max(A, 1e-9)
        ke = describing_stiffness(self.virgin, A)
        kp2 = min(self.kp2 + ke, self.kp_max)
        w = math.sqrt((kp2 + ke) / self.inertia)
        ce = describing_damping(self.virgin, A) / w
        kd2 = max(0.0, 2.0 * self.zeta * math.sqrt((kp2 + ke) * self.inertia) - ce)
        return kp2, kd2

    def adjust_bias(self, e: float) -> tuple[float, float]:
        """Return (u_b, kd2) after one ``bias`` re-adjustment at error e (class docstring)."""
        A = max(abs(e), 1e-9)
        ke = describing_stiffness(self.virgin, A)
        ce = describing_damping(self.virgin, A) / math.sqrt((self.kp + ke) / self.inertia)
        return self.bias + (self.kp + ke) * e, max(0.0, self.kd - ce)

    def compute(self, e, edot, ref, meas, dt) -> SchemeOutput:
        v = meas[1]
        still = abs(v) <= self.standstill_velocity
        ref_rests = abs(ref[1]) <= self.standstill_velocity
        self._still = self._still + dt if still else 0.0
        if self.mode == 1 and still and abs(e) < self.q_h and ref_rests:
            self.mode = 2
            self.kp2, self.kd2, self.bias = self.kp, self.kd, 0.0
            self._adjusted = False
        elif self.mode == 2 and (abs(e) > self.q_h or not ref_rests):
            self.mode = 1
            self.kp2, self.kd2, self.bias = self.kp, self.kd, 0.0
        if self.mode == 2:
            if not still:
                self._adjusted = False
            elif self._still >= self.dwell and not self._adjusted and abs(e) > self.tolerance:
                if self.schedule_kind == "bias":
                    self.bias, self.kd2 = self.adjust_bias(e)
                else:
                    self.kp2, self.kd2 = self.schedule(abs(e))
                self._adjusted = True
                self.adjustments += 1
            return SchemeOutput(p_term=self.kp2 * e + self.bias, d_term=self.kd2 * edot)
        vc = ref[1] if self.coulomb_source == "reference" else v
        if abs(vc) <= self.coulomb_deadband:
            fc = 0.0
        elif self.coulomb_velocity > 0.0:
            fc = self.coulomb * max(-1.0, min(1.0, vc / self.coulomb_velocity))
        else:
            fc = math.copysign(self.coulomb, vc) if vc != 0.0 else 0.0
        return SchemeOutput(p_term=self.kp * e, d_term=self.kd * edot, friction_feedback=fc)


class Cascade(_Scheme):
    """ABB M19-S paper A.4.4 classical cascade: v_cmd = kp_position e + velocity_feedforward v_ref;
    u = PI(v_cmd - v) (velocity PI with back-calculation anti-windup), integrating baseline.
    """

    SCHEMA = Schema(
        "cascade",
        [
            _f("kp_position", 60.0, "position loop gain", "1/s", lo=0.0),
            # the velocity PI's gains: the PID's range (Pid.from_checked takes them as checked here)
            _f("kp_velocity", 0.3, "velocity PI: proportional gain", "N*m*s/rad", lo=0.0, hi=PLAUSIBLE_GAIN),
            _f("ki_velocity", 6.0, "velocity PI: integral gain", "N*m/rad", lo=0.0, hi=PLAUSIBLE_GAIN),
            _f("velocity_feedforward", 1.0, "velocity feedforward share", lo=0.0, hi=2.0),
            _f("i_clamp", 2.0, "velocity PI: integral bound", "N*m", lo=0.0, allow_inf=True),
        ],
        doc="cascade parameter",
    )
    DEFAULTS = SCHEMA.defaults()

    def __init__(self, c: TypedConfig):
        self.kp_position, self.kp_velocity, self.ki_velocity = c.kp_position, c.kp_velocity, c.ki_velocity
        self.velocity_feedforward, self.i_clamp = c.velocity_feedforward, c.i_clamp
        self.pi = Pid.from_checked(
            within(c.path, "velocity_pi"),
            p=self.kp_velocity,
            i=self.ki_velocity,
            i_clamp_max=self.i_clamp,
            i_clamp_min=-self.i_clamp,
            antiwindup_strategy="back_calculation",
        )

    def config(self) -> dict[str, Any]:
        return {k: getattr(self, k) for k in self.DEFAULTS}

    def reset(self) -> None:
        self.pi.reset()

    def compute(self, e, edot, ref, meas, dt) -> SchemeOutput:
        vff = self.velocity_feedforward * ref[1]
        v_cmd = self.kp_position * e + vff
        out = self.pi.update(v_cmd - meas[1], dt, error_dot=0.0)
        return SchemeOutput(
            p_term=self.kp_velocity * self.kp_position * e,
            i_term=out.i_term,
            d_term=-self.kp_velocity * meas[1],
            velocity_feedforward=self.kp_velocity * vff,
        )


class SlidingMode(_Scheme):
    """Chatterjee et al. 2017 A.5.1 sliding-mode compensator: S = e_dot + lambda e,
    u = J_hat lambda e_dot + k_s S + M sat(S / phi)   (phi = 0: M sign(S), the relay of (5.2.6.3)).

    Reachability S S_dot < 0 holds when M > |f| (bounded friction/disturbance, eq. (5.2.9.3)).
    The inertia feed-forward J_hat theta_ddot_d is added by the façade.
    """

    SCHEMA = Schema(
        "sliding_mode",
        [
            _f("lambda", 50.0, "sliding surface S = e_dot + lambda e", "1/s", lo=0.0),
            _f("gain", 1.0, "switching gain M", "N*m", lo=0.0),
            _f("k_s", 0.0, "linear gain on S", "N*m*s/rad", lo=0.0),
            _f("boundary_layer", 0.0, "boundary layer phi (0: relay)", "rad/s", lo=0.0),
            _f("inertia", 0.0, "J_hat of J_hat lambda e_dot", "kg*m^2", lo=0.0),
        ],
        doc="sliding_mode parameter",
    )
    DEFAULTS = SCHEMA.defaults()

    def __init__(self, c: TypedConfig):
        self.lam, self.gain, self.k_s = c.lambda_, c.gain, c.k_s
        self.boundary_layer, self.inertia = c.boundary_layer, c.inertia

    def config(self) -> dict[str, Any]:
        return {
            "lambda": self.lam,
            "gain": self.gain,
            "k_s": self.k_s,
            "boundary_layer": self.boundary_layer,
            "inertia": self.inertia,
        }

    def reset(self) -> None:
        pass

    def compute(self, e, edot, ref, meas, dt) -> SchemeOutput:
        S = edot + self.lam * e
        if self.boundary_layer > 0.0:
            sw = self.gain * max(-1.0, min(1.0, S / self.boundary_layer))
        else:
            sw = math.copysign(self.gain, S) if S != 0.0 else 0.0
        return SchemeOutput(
            p_term=self.k_s * self.lam * e,
            d_term=self.k_s * edot + self.inertia * self.lam * edot,
            friction_feedback=sw,
        )


def sliding_mode_relay(x, nominal: float = 1.0, amplitude: float = 0.1, deadband: float = 0.01):
    """Chatterjee et al. 2017 A.5.2 ``f_motor_smc.m``: u = nominal - amplitude if x >= deadband,
    nominal + amplitude if x <= -deadband, else nominal (x: model-predicted friction signal)."""
    x = np.asarray(x, dtype=float)
    u = np.where(x >= deadband, nominal - amplitude, np.where(x <= -deadband, nominal + amplitude, nominal))
    return float(u) if u.ndim == 0 else u


def loop_gains(mode: str, pid, scheme) -> tuple[float, float]:
    """(K_p, K_d) of the loop's linear feedback ``u = K_p e + K_d e_dot + ...`` per mode [N*m/rad,
    N*m*s/rad]: pid ``p, d``; dnpf / gain_scheduling ``kp, kd`` (the configured baseline);
    cascade ``kp_velocity kp_position, kp_velocity``; sliding_mode ``k_s lambda, k_s`` (its
    relay adds no linear stiffness). Used by the feedback-path stability bound."""
    if scheme is None:
        c = pid.config()
        return float(c.get("p", 0.0)), float(c.get("d", 0.0))
    if isinstance(scheme, Cascade):
        return scheme.kp_velocity * scheme.kp_position, scheme.kp_velocity
    if isinstance(scheme, SlidingMode):
        return scheme.k_s * scheme.lam, scheme.k_s
    return float(scheme.kp), float(scheme.kd)
