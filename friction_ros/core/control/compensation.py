"""Friction compensation with any model of the library: feedforward, feedback, blended, observer.

Terms (N*m, added to the command; friction opposes motion so compensation has the model's sign):

* feedforward (ABB M19-S paper A.4.1, Fig. 6; AI friction chapter section 2):
  ``tau_ff = g_c * w * F_hat(theta_dot_d)``; a dynamic model (LuGre, GMS ...) has its state
  integrated from the *desired* velocity (ABB M19-S paper: "model state driven by theta_dot_d").
* feedback (GA friction thesis 2002 section 6.1: ``c = sat(e + k_c F_hat(omega_hat))``; AI friction chapter eq. (22)
  ``u_in = u_c + u_f_hat(theta_dot)``): ``tau_fb = g_c * (1 - w) * F_hat(theta_dot)`` with the
  measured or estimated velocity; a dynamic model is driven by the measured velocity.
* blended: both, weights ``w`` = ``blend`` and ``1 - w``.
* observer: the LuGre observer of Canudas de Wit et al. (1995)
  (:class:`~friction_ros.core.estimation.lugre_observer.LuGreObserver`) driven by the measured
  velocity and the tracking error ``e = theta_d - theta``. For non-LuGre models ``observer`` falls
  back to ``feedback``.

Feedback-path stability bound (``feedback_bound`` f, default 0.5; :meth:`FrictionCompensator.bound_feedback`):
the presliding stiffness/damping of a dynamic model fed back from measured motion is limited to
``g w_fb k_hat <= f K_p`` and ``g w_fb sigma1 <= f K_d`` of the loop's gains.

``g_c`` is the compensation gain (GA friction thesis 2002 used 0.95 so that a slightly over-estimating model does
not act as negative friction, GA friction thesis 2002 section 6.1 / 9 item 9).

Smoothing near zero velocity (GA friction thesis 2002 section 6.2, Tilakaratna et al. 2004 B-T9; in none of the source documents):
``none`` keeps the model as is (sgn(0) = 0), ``tanh`` uses ``F(v) tanh(|v| / v_eps)``, ``linear``
replaces the model inside |v| < v_eps by the line ``F(v_eps sgn v) |v| / v_eps`` (the finite-slope
zone of ABB M19-S paper A.2.1). Smoothing applies to static models only (dynamic models are already
continuous).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

import numpy as np

from friction_ros.core.config import Field, Schema, TypedConfig
from friction_ros.core.estimation.lugre_observer import LuGreObserver
from friction_ros.core.validation import ParameterError

SOURCES = ("none", "feedforward", "feedback", "blended", "observer")
SMOOTHING = ("none", "tanh", "linear")

#: How the model is applied: the compensating_controller's ``compensation.*`` parameters, with their
#: ranges (no ROS ranges: a refused run-time change is named in these words). ``refused`` /
#: ``refused_reasons``: the sources the fitter's safety gate refused (compensation_gate) and why.
_NO_ROS = {"ros_range": False}
COMPENSATION_SCHEMA = Schema(
    "compensation",
    [
        Field("source", "feedforward", "none, feedforward, feedback, blended or observer", choices=SOURCES),
        Field(
            "gain",
            1.0,
            "compensation gain g_c in [0, 2] (GA friction thesis 2002 used 0.95)",
            lo=0.0,
            hi=2.0,
            **_NO_ROS,
        ),
        Field("blend", 0.5, "blended: feedforward weight w (feedback gets 1 - w)", lo=0.0, hi=1.0, **_NO_ROS),
        Field("smoothing", "none", "static models near v = 0: none, tanh or linear", choices=SMOOTHING),
        Field("smoothing_velocity", 1e-3, "v_eps of the smoothing", lo=0.0, unit="rad/s", **_NO_ROS),
        Field("observer_gain", 0.0, "observer: LuGre observer gain L", lo=0.0, unit="1/s", **_NO_ROS),
        Field(
            "feedback_bound",
            0.5,
            "feedback path: share f of the loop's Kp / Kd that fed-back presliding "
            "stiffness / damping may remove",
            lo=0.0,
            hi=1.0,
            lo_open=True,
            **_NO_ROS,
        ),
        Field(
            "allow_refused",
            False,
            "run a source the safety gate refused (written by friction-fit in ``refused``) anyway",
        ),
        Field(
            "refused",
            [],
            "sources the fitter's safety gate refused (written by friction-fit)",
            kind=str,
            choices=SOURCES,
        ),
        Field("refused_reasons", [], "why each refused source was refused", kind=str),
    ],
    doc="how the friction model is applied",
)
#: model config dict {"model": name, coef: value ...} or None (no compensation); refused sources
#: and their reasons as written by the fitter's safety gate (compensation_gate)
COMPENSATION_DEFAULTS: dict[str, Any] = {
    "model": None,
    **COMPENSATION_SCHEMA.defaults(),
    "refused": None,
    "refused_reasons": None,
}


def compensation_settings(config: Mapping[str, Any], prefix: str = "friction") -> TypedConfig:
    """The typed settings of a core ``friction`` section (its keys but ``model``; None: default)."""
    return COMPENSATION_SCHEMA.typed(
        {k: v for k, v in config.items() if k != "model" and v is not None}, prefix
    )


def build_model(model: Any, name: str = "friction.model", path: str = ""):
    """:func:`friction_ros.core.friction.registry.build_model`, imported on first use (the models
    load their compiled kernels)."""
    from friction_ros.core.friction.registry import build_model as build

    return build(model, name, path)


def model_of(section: TypedConfig):
    """:func:`friction_ros.core.friction.registry.model_from_section` (the library model of a typed
    ``friction`` section; None for ``none``), imported on first use like :func:`build_model`."""
    from friction_ros.core.friction.registry import model_from_section

    return model_from_section(section)


def smoothed_static(model, v: float, smoothing: str, v_eps: float) -> float:
    """Static-model friction at ``v`` with the chosen near-zero smoothing (see module docstring)."""
    if smoothing == "tanh" and v_eps > 0.0:
        return model.steady_scalar(v) * math.tanh(abs(v) / v_eps)
    if smoothing == "linear" and v_eps > 0.0 and abs(v) < v_eps:
        return model.steady_scalar(math.copysign(v_eps, v)) * abs(v) / v_eps if v != 0.0 else 0.0
    return model.steady_scalar(v)


def _presliding_bound(
    name: str, cfg: Mapping, w: float, kp: float, kd: float, f: float
) -> tuple[dict, list[str]]:
    """The coefficient changes that keep ``w d_hat <= f K_d`` and ``w k_hat <= f K_p`` for one
    model config (see :meth:`FrictionCompensator._apply_bound`), with a note per change."""
    changes, notes = {}, []
    s1 = cfg.get("sigma1")
    if isinstance(s1, (int, float)) and s1 > 0.0 and w * s1 > f * kd:
        changes["sigma1"] = f * max(kd, 0.0) / w
        notes.append(f"sigma1 {s1:.4g} -> {changes['sigma1']:.4g} N*m*s/rad (<= {f:g} Kd {kd:.4g})")
    from friction_ros.core.friction import MODEL_CLASSES

    cls = MODEL_CLASSES.get(name)
    stiff_key = cls.STIFFNESS if cls is not None else None
    k = cfg.get(stiff_key) if stiff_key else None
    if k is not None:
        k_sum = float(sum(k)) if isinstance(k, (list, tuple)) else float(k)
        if k_sum > 0.0 and w * k_sum > f * kp:
            # a stiffness must stay > 0 for the model to validate: a loop without Kp keeps 1e-9
            scale = max(f * kp / w, 1e-9) / k_sum
            changes[stiff_key] = [x * scale for x in k] if isinstance(k, (list, tuple)) else k * scale
            notes.append(
                f"presliding stiffness {k_sum:.4g} -> {k_sum * scale:.4g} N*m/rad (<= {f:g} Kp {kp:.4g})"
            )
    return changes, notes


class FrictionCompensator:
    """Friction compensation term(s) from a library model; see the module docstring."""

    def __init__(
        self,
        config: Mapping[str, Any] | None = None,
        *,
        prefix: str = "friction",
        model_path: str = "",
        **kwargs,
    ):
        """From a core ``friction`` section (the settings and ``model``: a model config, a model or
        None), typed once. ``prefix``: how messages name this section; ``model_path``: the model's
        section (``friction`` in the ROS layout; default: the model's name)."""
        given = {**dict(config or {}), **kwargs}
        settings = compensation_settings(given, prefix)
        self._setup(settings, build_model(given.get("model"), f"{prefix}.model", model_path), model_path)

    @classmethod
    def from_config(
        cls, settings: TypedConfig, model, model_path: str = "", loop_gains: tuple[float, float] | None = None
    ) -> FrictionCompensator:
        """From a typed ``compensation`` section (:data:`COMPENSATION_SCHEMA`), as it is, and the
        library model (None: no compensation); ``loop_gains`` (K_p, K_d): the feedback path is
        bounded from the start (:meth:`bound_feedback`)."""
        self = cls.__new__(cls)
        if loop_gains is not None:
            self._loop_gains = (float(loop_gains[0]), float(loop_gains[1]))
        self._setup(settings, model, model_path)
        return self

    def _setup(self, c: TypedConfig, model, model_path: str) -> None:
        self._settings, self.model_path = c, model_path
        self.source, self.gain, self.blend = c.source, c.gain, c.blend
        self.smoothing, self.smoothing_velocity = c.smoothing, c.smoothing_velocity
        self.observer_gain, self.feedback_bound = c.observer_gain, c.feedback_bound
        self.refused, self.refused_reasons = list(c.refused), list(c.refused_reasons)
        self.allow_refused = c.allow_refused
        if self.source in self.refused and not self.allow_refused and model is not None:
            i = self.refused.index(self.source)
            why = self.refused_reasons[i] if i < len(self.refused_reasons) else "see the fit report"
            ok = [x for x in ("feedforward", "feedback", "blended") if x not in self.refused]
            prefix = self.prefix
            section = (
                prefix if prefix.endswith("compensation") else f"{prefix.rsplit('.', 1)[0]}.compensation"
            )
            raise ParameterError(
                f"{section}.source = {self.source} was refused by the safety gate "
                f"({why}): use {', '.join(ok + ['none'])}, or set compensation.allow_refused: true"
            )
        self._install(model)

    @property
    def prefix(self) -> str:
        """How messages name this section."""
        return self._settings.path()

    # -- model management -------------------------------------------------------------------------
    def _install(self, model) -> None:
        self.model = model
        self._ff_model = build_model(model) if model is not None else None
        self._fb_model = build_model(model) if model is not None else None
        self.bound_note = ""
        if getattr(self, "_loop_gains", None) is not None:  # bounds the feedback model
            self.bound_note = self._apply_bound(*self._loop_gains)
        self._observer = None
        if model is not None and self.source == "observer" and LuGreObserver.observes(model):
            self._observer = LuGreObserver(self._fb_model, self.observer_gain)

    def config(self) -> dict[str, Any]:
        return {
            "model": None if self.model is None else self.model.to_config(),
            "source": self.source,
            "gain": self.gain,
            "blend": self.blend,
            "smoothing": self.smoothing,
            "smoothing_velocity": self.smoothing_velocity,
            "observer_gain": self.observer_gain,
            "feedback_bound": self.feedback_bound,
            "refused": list(self.refused) or None,
            "refused_reasons": list(self.refused_reasons) or None,
            "allow_refused": self.allow_refused,
        }

    def set_model(self, model) -> None:
        """Replace the model (config dict or instance); validated before anything changes.

        Dynamic states restart from the new model's initial state.
        """
        self._install(build_model(model, f"{self.prefix}.model", self.model_path))

    def set_coefficients(self, **coefficients: Any) -> None:
        """Hot-swap some coefficients of the current model (validated; states are kept if compatible)."""
        if self.model is None:
            raise ParameterError(f"{self.prefix}.model is not set: cannot change coefficients")
        new = self.model.with_coefficients(**coefficients)
        states = [
            m.state.copy() if (m is not None and m.is_dynamic) else None
            for m in (self._ff_model, self._fb_model)
        ]
        obs = self._observer.z if self._observer is not None else None
        self._install(new)
        for m, s in zip((self._ff_model, self._fb_model), states):
            if m is not None and s is not None and m.state.shape == s.shape:
                m.reset(s)
        if self._observer is not None and obs is not None:
            self._observer.z = obs

    def bound_feedback(self, kp: float, kd: float) -> str:
        """Apply (and keep applying after model changes) the feedback-path bound for the loop gains
        ``kp`` [N*m/rad], ``kd`` [N*m*s/rad]; returns ``bound_note`` (see :meth:`_apply_bound`)."""
        self._loop_gains = (float(kp), float(kd))
        self._install(self.model)
        return self.bound_note

    def _apply_bound(self, kp: float, kd: float) -> str:
        """Stability bound of the feedback path; returns a note when it limited the model ('' if not).

        Derivation (loop ``J s^2 x = -(K_d s + K_p) x + tau_fb - F_plant``): in presliding a dynamic
        model driven by the measured motion is linear, ``F_hat ~ k_hat x + d_hat v`` with stiffness
        ``k_hat`` = LuGre ``sigma0``, GMS ``sum k_i``, Dahl ``sigma`` and damping ``d_hat`` =
        ``sigma1`` (``dz/dt ~ v``). Fed back with weight ``g w_fb`` it turns the loop into
        ``J s^2 + (K_d + d_p - g w_fb d_hat) s + (K_p + k_p - g w_fb k_hat)`` where ``d_p, k_p`` are
        the plant's own presliding damping and stiffness. Those are poorly identified (a LuGre fit
        can return sigma0 = 1e5 for a joint whose bristles are ~600 N*m/rad) and lag the command by
        the current loop and the period, so the loop is only guaranteed to keep its tuning if the
        compensation alone removes no more than a share ``f`` (``feedback_bound``, default 0.5)::

            g w_fb d_hat <= f K_d        g w_fb k_hat <= f K_p

        Beyond that the feedback model's presliding damping/stiffness is scaled down to the bound
        (the presliding range ``g(v)/sigma0`` grows accordingly; the sliding levels fc, fs, fv are
        unchanged). The feedforward path (driven by the reference) is not affected. Static models
        have no presliding terms: nothing to bound here, the safety gate judges them.

        Measured (abb_m19s, PD 200/0.15, fitted LuGre sigma0 = 1e5, sigma1 = 0.9 in feedback, 10 s
        band-limited random): unbounded 29.0 mrad RMS (56 Hz limit cycle; none 3.28); the sigma1
        bound alone 29.0 (the stiff bristles switch the full Coulomb level within 10 urad while the
        joint's build up over mrad); both bounds 1.36. Cost: in a soft loop (K_p ~ 11 N*m/rad) the
        bounded presliding stiffness leaves pure feedback compensation without benefit.
        """
        m = self._fb_model
        _wff, wfb = self.weights
        w = self.gain * wfb
        if m is None or w <= 0.0 or not m.is_dynamic:
            return ""
        cfg = m.to_config()
        f = self.feedback_bound
        if m.name == "asymmetric":  # a direction-dependent model: bound each direction's set
            notes = []
            new = dict(cfg)
            for d in ("positive", "negative"):
                ch, nt = _presliding_bound(cfg["base"], cfg[d], w, kp, kd, f)
                new[d] = {**cfg[d], **ch}
                notes += [f"{d} {n}" for n in nt]
            changes = {"positive": new["positive"], "negative": new["negative"]} if notes else {}
        else:
            changes, notes = _presliding_bound(m.name, cfg, w, kp, kd, f)
        if not changes:
            return ""
        self._fb_model = build_model({**cfg, **changes})
        return (
            f"feedback path of {m.name} limited for loop stability: {'; '.join(notes)} "
            f"(gain x feedback weight {w:.3g})"
        )

    def reset(self) -> None:
        for m in (self._ff_model, self._fb_model):
            if m is not None and m.is_dynamic:
                m.reset()
        if self._observer is not None:
            self._observer.reset()

    @property
    def weights(self) -> tuple[float, float]:
        """(feedforward weight, feedback weight) of the chosen source."""
        key = (self.source, self.blend)
        if self._weights_key != key:  # computed once per source/blend, not every period
            self._weights_key = key
            self._weights = {
                "none": (0.0, 0.0),
                "feedforward": (1.0, 0.0),
                "feedback": (0.0, 1.0),
                "observer": (0.0, 1.0),
                "blended": (self.blend, 1.0 - self.blend),
            }[self.source]
        return self._weights

    _weights_key: tuple | None = None
    _weights = (0.0, 0.0)

    def _eval(self, m, v: float, dt: float) -> float:
        if m.is_dynamic:
            return float(m.step(v, dt))
        return smoothed_static(m, v, self.smoothing, self.smoothing_velocity)

    def update(self, v_ref: float, v_meas: float, dt: float, error: float = 0.0) -> tuple[float, float]:
        """Return (friction_feedforward, friction_feedback) in N*m for this period."""
        if self.model is None:
            return 0.0, 0.0
        wff, wfb = self.weights
        ff = fb = 0.0
        if wff > 0.0:
            ff = self.gain * wff * self._eval(self._ff_model, v_ref, dt)
        if wfb > 0.0:
            if self._observer is not None:
                fb = self.gain * wfb * self._observer.step(v_meas, dt, error)
            else:
                fb = self.gain * wfb * self._eval(self._fb_model, v_meas, dt)
        return ff, fb

    @property
    def state(self) -> np.ndarray:
        """Internal states (observer z_hat, or the feedback/feedforward model state)."""
        if self._observer is not None:
            return self._observer.state
        wff, wfb = self.weights
        order = (self._fb_model, self._ff_model) if wfb > 0.0 else (self._ff_model, self._fb_model)
        for m in order:
            if m is not None and m.is_dynamic:
                return np.asarray(m.state, dtype=float).copy()
        return np.zeros(0)
