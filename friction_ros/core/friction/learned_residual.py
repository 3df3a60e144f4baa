"""Learned residual on top of a physics friction model: the run-time part (numpy and math only).

The physics model stays the backbone; a small learned map adds what it leaves (hysteresis,
presliding, history):

    tau_ff = tau_physics(q, v, a) + r,    r = clip(w(x) * f(x), clip_low, clip_high)

**Causal features** x (one recursion, :class:`FeatureState`, used by :meth:`LearnedResidual.step`,
:meth:`LearnedResidual.predict_batch` and the training in
:mod:`friction_ros.core.identification.fit.residual_learning`), in this order:

* position: ``sin q, cos q`` (``position_input = sincos``), ``q`` (``raw``) or nothing (``none``);
* ``v`` [rad/s];
* low-passed velocities ``v_f,k += alpha_k (v - v_f,k)``, ``alpha_k = 1 - exp(-dt / T_k)``, one per
  ``velocity_time_constants`` T_k [s] (recent motion: ``v - v_f`` is a smoothed acceleration);
* the last direction of motion ``s in {-1, 0, +1}`` (``|v| > reversal_velocity`` sets it, 0 before the
  first motion);
* ``tanh((q - q_r) / d_k)`` per ``displacement_scales`` d_k [rad], with ``q_r`` the turning point of the
  last velocity reversal (the extreme position reached before the direction changed): presliding;
* the torque ``command`` [N*m] when ``use_command`` (the caller's last known command; off by default,
  because a map from the command back onto the feedforward closes a loop of gain ~1 through the
  controller).

**Map** f: standardised inputs ``z = (x - feature_mean) / feature_scale``, hidden layers
``h_{i+1} = act(W_i h_i + b_i)`` (``act = tanh`` for ``mlp``; one ``cos`` layer for ``rff``, random
Fourier features), a linear output, de-standardised ``f = output_mean + output_scale * y``.
``layer_sizes = [n_features, h_1, ..., 1]`` gives the shapes of the flat ``weights`` (each W_i
row-major, shape ``(layer_sizes[i+1], layer_sizes[i])``, concatenated) and ``biases``.

**Sane extrapolation**: the fade ``w(x) = max(0, 1 - max_j e_j / (fade (hi_j - lo_j)))`` with
``e_j = max(0, x_j - hi_j, lo_j - x_j)`` goes from 1 inside the training range ``[feature_low,
feature_high]`` to 0 at ``fade`` times the range beyond it, and the output is clipped to the training
residual range ``[clip_low, clip_high]``: far from the data only the physics model is left.
"""

from __future__ import annotations

import math
from collections.abc import Mapping

import numpy as np

from friction_ros.core.config import Field, Schema, TypedConfig
from friction_ros.core.validation import ParameterError

KINDS = ("none", "mlp", "rff")
_ACTIVATION = {"mlp": np.tanh, "rff": np.cos}

LEARNED_RESIDUAL_SCHEMA = Schema(
    "residual",
    [
        Field(
            "kind",
            "none",
            "learned residual map: none, mlp (tanh layers) or rff (random Fourier features + ridge)",
            choices=KINDS,
            read_only=True,
        ),
        Field("dt", 0.001, "sample period the velocity filters assume", lo=0.0, lo_open=True, unit="s"),
        Field(
            "position_input",
            "sincos",
            "position feature: sin q and cos q, raw q, or none",
            choices=("sincos", "raw", "none"),
        ),
        Field(
            "velocity_time_constants",
            [0.01, 0.1],
            "time constants T_k of the low-passed velocity features v_f,k",
            lo=0.0,
            lo_open=True,
            unit="s",
        ),
        Field(
            "reversal_velocity",
            0.02,
            "|v| above which the direction of motion is taken (reversal detection)",
            lo=0.0,
            lo_open=True,
            unit="rad/s",
        ),
        Field(
            "displacement_scales",
            [0.005, 0.05],
            "scales d_k of the presliding features tanh((q - q_reversal) / d_k)",
            lo=0.0,
            lo_open=True,
            unit="rad",
        ),
        Field("use_command", False, "use the torque command as a feature (closes a loop: see docs)"),
        Field("feature_mean", [], "feature standardisation: mean (one per feature)"),
        Field("feature_scale", [], "feature standardisation: scale (one per feature)", lo=0.0, lo_open=True),
        Field("feature_low", [], "training range of each feature: low end"),
        Field("feature_high", [], "training range of each feature: high end"),
        Field(
            "fade",
            0.1,
            "beyond the training range the residual fades to 0 over this fraction of the range",
            lo=0.0,
        ),
        Field("layer_sizes", [], "layer shapes [n_features, hidden..., 1]", kind=int, lo=1),
        Field("weights", [], "layer weight matrices, row-major, concatenated"),
        Field("biases", [], "layer biases, concatenated"),
        Field("output_mean", 0.0, "output de-standardisation: mean", unit="N*m"),
        Field("output_scale", 1.0, "output de-standardisation: scale", lo=0.0, lo_open=True, unit="N*m"),
        Field("clip_low", 0.0, "lowest residual torque (training residual range)", unit="N*m"),
        Field("clip_high", 0.0, "highest residual torque (training residual range)", unit="N*m"),
    ],
    doc="learned residual torque on top of the physics friction model",
)

FEATURE_KEYS = (
    "dt",
    "position_input",
    "velocity_time_constants",
    "reversal_velocity",
    "displacement_scales",
    "use_command",
)


PREDICT_BLOCK = 16384  # rows per block of predict_features (a 200-wide layer: 26 MB)


def feature_settings(section: Mapping | None = None, prefix: str = "residual") -> dict:
    """The feature settings (defaults filled in, validated) from a ``residual`` section or a partial dict."""
    given = {k: v for k, v in (section or {}).items() if k in FEATURE_KEYS}
    c = LEARNED_RESIDUAL_SCHEMA.validate(given, prefix)
    return {k: c[k] for k in FEATURE_KEYS}


def feature_names(settings: Mapping) -> list[str]:
    """Names of the features, in the order of the feature vector."""
    pos = {"sincos": ["sin_q", "cos_q"], "raw": ["q"], "none": []}[settings["position_input"]]
    names = [*pos, "v"]
    names += [f"v_f({t:g} s)" for t in settings["velocity_time_constants"]]
    names.append("direction")
    names += [f"tanh(dq_rev / {d:g})" for d in settings["displacement_scales"]]
    if settings["use_command"]:
        names.append("command")
    return names


class FeatureState:
    """The causal feature recursion of the module docstring (one sample per :meth:`update`)."""

    def __init__(self, settings: Mapping):
        self.position_input = settings["position_input"]
        dt = float(settings["dt"])
        self.alphas = [1.0 - math.exp(-dt / float(t)) for t in settings["velocity_time_constants"]]
        self.inv_d = [1.0 / float(d) for d in settings["displacement_scales"]]
        self.v_eps = float(settings["reversal_velocity"])
        self.use_command = bool(settings["use_command"])
        self.n = len(feature_names(settings))
        self.reset()

    def reset(self) -> None:
        self.started = False
        self.vf = [0.0] * len(self.alphas)
        self.direction = 0.0
        self.q_ext = 0.0  # extreme position since the last change of direction
        self.q_rev = 0.0  # turning point of the last reversal

    def update(self, q: float, v: float, command: float) -> list[float]:
        """Advance one sample and return the feature vector."""
        vf = self.vf
        if not self.started:
            self.started = True
            for k in range(len(vf)):
                vf[k] = v
            self.q_ext = self.q_rev = q
        else:
            for k, a in enumerate(self.alphas):
                vf[k] += a * (v - vf[k])
        d = self.direction
        new = 1.0 if v > self.v_eps else (-1.0 if v < -self.v_eps else d)
        if new != d:
            self.q_rev = self.q_ext
            self.direction = d = new
            self.q_ext = q
        elif d > 0.0:
            if q > self.q_ext:
                self.q_ext = q
        elif d < 0.0:
            if q < self.q_ext:
                self.q_ext = q
        else:
            self.q_ext = q
        if self.position_input == "sincos":
            x = [math.sin(q), math.cos(q), v]
        elif self.position_input == "raw":
            x = [q, v]
        else:
            x = [v]
        x.extend(vf)
        x.append(d)
        dq = q - self.q_rev
        x.extend([math.tanh(dq * s) for s in self.inv_d])
        if self.use_command:
            x.append(command)
        return x

    def batch(self, q, v, command=None) -> np.ndarray:
        """Features of a whole record (shape (N, n)), continuing from the current state."""
        q = np.asarray(q, dtype=float).ravel()
        v = np.asarray(v, dtype=float).ravel()
        c = np.zeros_like(q) if command is None else np.asarray(command, dtype=float).ravel()
        if not (q.size == v.size == c.size):
            raise ParameterError(f"q, v and command have different lengths ({q.size}, {v.size}, {c.size})")
        out = np.empty((q.size, self.n))
        upd = self.update
        for i, (qi, vi, ci) in enumerate(zip(q.tolist(), v.tolist(), c.tolist())):
            out[i] = upd(qi, vi, ci)
        return out


def _float_array(config: TypedConfig, key: str, n: int, prefix: str) -> np.ndarray:
    a = np.asarray(getattr(config, key), dtype=float)
    if a.size != n:
        raise ParameterError(f"{prefix}.{key} has {a.size} values: must have {n} (one per feature)")
    return a


def _listed(value):
    return list(value) if isinstance(value, tuple) else value


class LearnedResidual:
    """The run-time residual map: ``step`` per sample (1 kHz loop), ``predict_batch`` over records."""

    def __init__(self, config: Mapping | TypedConfig, prefix: str = "residual"):
        """From a ``residual`` section: a dict (typed once, messages name ``prefix.<key>``) or a
        typed section (:data:`LEARNED_RESIDUAL_SCHEMA`), as it is."""
        c = config if isinstance(config, TypedConfig) else LEARNED_RESIDUAL_SCHEMA.typed(config, prefix)
        prefix = c.path()
        if c.kind == "none":
            raise ParameterError(
                f"{prefix}.kind = none: no learned residual to build (from_config gives None)"
            )
        self._config = c
        self.kind = c.kind
        self.settings = {k: _listed(getattr(c, k)) for k in FEATURE_KEYS}
        self.features = FeatureState(self.settings)
        n = self.features.n
        sizes = [int(s) for s in c.layer_sizes]
        if len(sizes) < 3 or sizes[0] != n or sizes[-1] != 1:
            raise ParameterError(
                f"{prefix}.layer_sizes = {sizes} must be [n_features = {n}, hidden..., 1] "
                f"(features: {', '.join(feature_names(self.settings))})"
            )
        if self.kind == "rff" and len(sizes) != 3:
            raise ParameterError(f"{prefix}.layer_sizes = {sizes}: rff has one hidden layer [n, D, 1]")
        n_w = sum(a * b for a, b in zip(sizes[:-1], sizes[1:]))
        n_b = sum(sizes[1:])
        w = np.asarray(c.weights, dtype=float)
        b = np.asarray(c.biases, dtype=float)
        if w.size != n_w:
            raise ParameterError(
                f"{prefix}.weights has {w.size} values: must have {n_w} for layer_sizes {sizes}"
            )
        if b.size != n_b:
            raise ParameterError(
                f"{prefix}.biases has {b.size} values: must have {n_b} for layer_sizes {sizes}"
            )
        mean = _float_array(c, "feature_mean", n, prefix)
        scale = _float_array(c, "feature_scale", n, prefix)
        lo = _float_array(c, "feature_low", n, prefix)
        hi = _float_array(c, "feature_high", n, prefix)
        if np.any(hi < lo):
            j = int(np.argmax(hi < lo))
            raise ParameterError(
                f"{prefix}.feature_high[{j}] = {hi[j]:g} is below {prefix}.feature_low[{j}] = {lo[j]:g}"
            )
        if c.clip_high < c.clip_low:
            raise ParameterError(
                f"{prefix}.clip_high = {c.clip_high:g} is below {prefix}.clip_low = {c.clip_low:g}"
            )
        # layers, standardisation folded in: W1' = W1 / scale, b1' = b1 - W1' mean; output likewise
        self.layers: list[tuple[np.ndarray, np.ndarray]] = []
        iw = ib = 0
        for a, bsz in zip(sizes[:-1], sizes[1:]):
            self.layers.append((w[iw : iw + a * bsz].reshape(bsz, a).copy(), b[ib : ib + bsz].copy()))
            iw += a * bsz
            ib += bsz
        w0, b0 = self.layers[0]
        w0 = w0 / scale[None, :]
        self.layers[0] = (w0, b0 - w0 @ mean)
        wl, bl = self.layers[-1]
        self._w_out = wl[0] * c.output_scale
        self._b_out = float(bl[0] * c.output_scale + c.output_mean)
        self._hidden = self.layers[:-1]
        self._act = _ACTIVATION[self.kind]
        self._lo, self._hi = lo, hi
        width = np.maximum(hi - lo, 1e-9 * (1.0 + np.abs(hi)))
        self._inv_fade = 1.0 / (c.fade * width) if c.fade > 0.0 else np.full(n, np.inf)
        self._fade_rows = list(zip(lo.tolist(), hi.tolist(), self._inv_fade.tolist()))
        self.clip_low = float(c.clip_low)
        self.clip_high = float(c.clip_high)

    # ------------------------------------------------------------------------------ config
    @classmethod
    def from_config(cls, section: Mapping | None, prefix: str = "residual") -> LearnedResidual | None:
        """Validated from a ``residual`` section (flat values); None when ``kind`` is ``none``."""
        return cls.from_section(LEARNED_RESIDUAL_SCHEMA.typed(section or {}, prefix))

    @classmethod
    def from_section(cls, section: TypedConfig) -> LearnedResidual | None:
        """From a typed ``residual`` section, as it is; None when ``kind`` is ``none``."""
        return None if section.kind == "none" else cls(section)

    @property
    def period(self) -> float:
        """The sample period the map's velocity filters assume (``dt``) [s]."""
        return float(self.settings["dt"])

    def to_config(self) -> dict:
        """Flat ROS-parameter values (str, float, bool, int list, float lists); round-trips."""
        c = self._config
        out: dict = {}
        for name, f in LEARNED_RESIDUAL_SCHEMA.fields():
            v = getattr(c, name)
            if f.is_list:
                out[name] = [f.kind(x) for x in v]
            else:
                out[name] = f.kind(v)
        return out

    @property
    def feature_names(self) -> list[str]:
        return feature_names(self.settings)

    # ------------------------------------------------------------------------------ run time
    def reset(self) -> None:
        """Forget the history (filters, direction, reversal point)."""
        self.features.reset()

    def _fade_scalar(self, x: list[float]) -> float:
        worst = 0.0
        for xi, (lo, hi, inv) in zip(x, self._fade_rows):
            if xi > hi:
                e = (xi - hi) * inv
            elif xi < lo:
                e = (lo - xi) * inv
            else:
                continue
            if e > worst:
                worst = e
        return 1.0 - worst if worst < 1.0 else 0.0

    def step(self, q: float, v: float, command: float = 0.0) -> float:
        """The residual torque r [N*m] for this sample (advances the history)."""
        x = self.features.update(q, v, command)
        w = self._fade_scalar(x)
        if w <= 0.0:
            return min(max(0.0, self.clip_low), self.clip_high)
        h = np.array(x)
        act = self._act
        for wi, bi in self._hidden:
            h = act(wi @ h + bi)
        y = w * (float(self._w_out @ h) + self._b_out)
        return min(max(y, self.clip_low), self.clip_high)

    def predict_features(self, x: np.ndarray) -> np.ndarray:
        """r for a feature matrix (shape (N, n)), the same arithmetic as :meth:`step` (in blocks of
        PREDICT_BLOCK rows: a long record's hidden layers would otherwise take N x width floats each)."""
        x = np.asarray(x, dtype=float)
        if x.shape[0] > PREDICT_BLOCK:
            return np.concatenate(
                [self.predict_features(x[i : i + PREDICT_BLOCK]) for i in range(0, x.shape[0], PREDICT_BLOCK)]
            )
        e = np.maximum(x - self._hi[None, :], self._lo[None, :] - x)
        e = np.where(e > 0.0, e * self._inv_fade[None, :], 0.0)
        worst = e.max(axis=1)
        w = np.where(worst < 1.0, 1.0 - worst, 0.0)
        h = x
        for wi, bi in self._hidden:
            h = self._act(h @ wi.T + bi[None, :])
        y = w * (h @ self._w_out + self._b_out)
        y = np.where(w <= 0.0, 0.0, y)
        return np.clip(y, self.clip_low, self.clip_high)

    def predict_batch(self, q, v, command=None) -> np.ndarray:
        """r over a record: the causal recursion of :meth:`step` from a reset history (a fresh one:
        the state of :meth:`step` is left alone), equal to reset() and step() in a loop."""
        return self.predict_features(FeatureState(self.settings).batch(q, v, command))
