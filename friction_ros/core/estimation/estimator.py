"""``OnlineFrictionEstimator``: friction measurement + online model fit, built from a config dict.

Pipeline per sample (effort = motor torque on the joint side, velocity measured):

1. friction "measurement" ``y``: torque balance with filtered acceleration, or a disturbance
   observer (``method``, :mod:`.measurement`);
2. ``model``:

   * linear in the parameters, fitted by RLS with forgetting and excitation gating
     (:mod:`.rls`), regressors in the filtered velocity ``v_f``: ``viscous``, ``coulomb_viscous``,
     ``asymmetric_coulomb_viscous``, ``stribeck`` (vs and delta fixed), ``asymmetric_stribeck``
     (equations and library configs in :mod:`.adapted_models`).

   The coefficients carry the names of the friction library model that
   :meth:`OnlineFrictionEstimator.model_config` returns, flattened as in the FrictionEstimate message
   (:mod:`friction_ros.core.coefficient_exchange`): ``fc`` [N*m], ``fs`` [N*m], ``fv`` [N*m*s/rad],
   and for the asymmetric models ``positive.fc``, ``negative.fv`` ... (units and equations:
   docs/coefficients.md). ``initial`` gives their start values in the library config's layout,
   e.g. ``initial: {positive: {fc: 0.4, fv: 0.05}, negative: {fc: 0.4, fv: 0.05}}``.

   * ``lugre``: LuGre state observer with fixed coefficients (``lugre`` model config):
     ``dz/dt = v - sigma0 |v| z / g(v) + L (y - F_hat) / sigma0``, F_hat = sigma0 z + sigma1 dz/dt
     + fv v (Canudas de Wit et al. 1995 structure; the correction uses the friction measurement).

Excitation check: a sample updates the fit only when |v_f| >= ``min_velocity`` and |v| (raw) >=
``min_velocity`` (gross sliding, not at rest / presliding). ``converged`` is true once at least
``min_samples`` excited samples were used and every coefficient's relative one-sigma std is below
``convergence_tolerance`` (absolute floor ``std_floor``).

The coefficients in :meth:`model_config` use the friction library's names, so the controller can
adopt them with ``CompensatingController.set_coefficients(estimator.model_config())``.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np

from friction_ros.core.config import Field, Names, Schema, within
from friction_ros.core.estimation.adapted_models import ADAPTED
from friction_ros.core.estimation.lugre_observer import LuGreObserver
from friction_ros.core.estimation.measurement import NAMES, DisturbanceObserver, TorqueBalanceEstimator
from friction_ros.core.estimation.rls import RecursiveLeastSquares
from friction_ros.core.validation import (
    ParameterError,
    check_keys,
    check_real,
)

METHODS = ("torque_balance", "disturbance_observer")
#: the RLS-adapted models (:mod:`.adapted_models`) and the LuGre observer
ESTIMATOR_MODELS = (*ADAPTED, "lugre")

ESTIMATOR_SCHEMA = Schema(
    "estimator",
    [
        Field(
            "method",
            "torque_balance",
            "friction measurement: torque_balance (filtered acceleration) or disturbance_observer",
            choices=METHODS,
        ),
        Field("model", "coulomb_viscous", "adapted model (lugre: observer)", choices=ESTIMATOR_MODELS),
        Field(
            "inertia",
            0.0,
            "J_hat of the joint (joint side); > 0 for the disturbance observer",
            lo=0.0,
            unit="kg*m^2",
        ),
        Field(
            "filter_time_constant",
            0.005,
            "acceleration/velocity filter time constant (torque_balance)",
            unit="s",
        ),
        Field(
            "observer_bandwidth", 200.0, "disturbance observer bandwidth (disturbance_observer)", unit="rad/s"
        ),
        Schema(
            "initial",
            doc="initial coefficient values in the library layout, e.g. positive.fc (missing: 0)",
            open=True,
        ),
        Field("vs", 0.05, "Stribeck velocity (fixed shape)", lo=0.0, lo_open=True, unit="rad/s"),
        Field("delta", 2.0, "Stribeck exponent (fixed shape)", lo=0.0, lo_open=True),
        Field("forgetting_factor", 0.999, "RLS forgetting factor (0.5, 1]"),
        Field("initial_covariance", 10.0, "RLS initial covariance (> 0)"),
        Field("min_velocity", 0.01, "excitation: adapt only while |v| >= this", lo=0.0, unit="rad/s"),
        Field("min_samples", 200, "excited samples before convergence can be declared", lo=1),
        Field(
            "convergence_tolerance",
            0.02,
            "relative one-sigma std below which a coefficient counts as converged",
            lo=0.0,
            hi=1.0,
            lo_open=True,
        ),
        Field("std_floor", 1e-3, "absolute std floor for convergence", lo=0.0),
        Schema("lugre", doc="LuGre model config for model = lugre (model: lugre + coefficients)", open=True),
        Field("observer_gain", 50.0, "LuGre observer correction gain", lo=0.0, unit="1/s"),
    ],
    doc="online friction estimator",
)
"""Configuration of :class:`OnlineFrictionEstimator` (the friction_estimator node's parameters)."""


@dataclass
class FrictionEstimateData:
    """One estimate (friction_msgs/FrictionEstimate fields, SI units)."""

    time: float = 0.0
    model: str = ""
    friction_torque: float = 0.0
    model_torque: float = 0.0
    velocity: float = 0.0
    state: list[float] = field(default_factory=list)
    coefficient_names: list[str] = field(default_factory=list)
    coefficients: list[float] = field(default_factory=list)
    coefficient_std: list[float] = field(default_factory=list)
    excitation_ok: bool = False
    converged: bool = False

    def as_dict(self) -> dict[str, Any]:
        return asdict(self)


def _dotted(mapping: Mapping[str, Any], prefix: str = "", where: str = "estimator.initial"):
    """(dotted name, value) of the leaves of a nested mapping: ``{positive: {fc: x}}`` ->
    ``("positive.fc", x)``, the names :func:`~friction_ros.core.coefficient_exchange.to_fields` gives."""
    if not isinstance(mapping, Mapping):
        raise ParameterError(f"{where} = {mapping!r} must be a mapping of coefficient values", where)
    for k, v in mapping.items():
        if isinstance(v, Mapping):
            yield from _dotted(v, f"{prefix}{k}.", where)
        else:
            yield f"{prefix}{k}", v


def regressor(model: str, v: float, vs: float = 0.05, delta: float = 2.0) -> np.ndarray:
    """phi(v) of the linear-in-parameter models (see the module docstring)."""
    return np.array(_regressor(model, v, vs, delta))


def _regressor(model: str, v: float, vs: float, delta: float) -> tuple[float, ...]:
    """phi(v) as a tuple of floats (hot path of :meth:`OnlineFrictionEstimator.update`)."""
    m = ADAPTED.get(model)
    if m is None:
        raise ParameterError(f"estimator.model = {model!r} is not linear in its parameters")
    return m.regressor(float(v), vs, delta)


class OnlineFrictionEstimator:
    """Online friction estimator façade; see the module docstring and :data:`ESTIMATOR_SCHEMA`."""

    def __init__(self, config: Mapping[str, Any] | None = None, names: Names = NAMES):
        """``names``: the parameter names in messages (default ``estimator.<key>``; a node gives its
        ROS names, a joint's :class:`~friction_ros.core.joint_config.JointNames` on several joints)."""
        cfg = ESTIMATOR_SCHEMA.validate(config, names=names)
        self.method = cfg["method"]
        self.model_name = cfg["model"]
        self.inertia = cfg["inertia"]
        if self.method == "torque_balance":
            self.front = TorqueBalanceEstimator(self.inertia, cfg["filter_time_constant"], names)
        else:  # checks inertia > 0
            self.front = DisturbanceObserver(self.inertia, cfg["observer_bandwidth"], names)
        self.filter_time_constant = cfg["filter_time_constant"]
        self.observer_bandwidth = cfg["observer_bandwidth"]
        self.vs, self.delta = cfg["vs"], cfg["delta"]
        self.min_velocity = cfg["min_velocity"]
        self.min_samples = cfg["min_samples"]
        self.convergence_tolerance = cfg["convergence_tolerance"]
        self.std_floor = cfg["std_floor"]
        self.observer_gain = cfg["observer_gain"]
        self._cfg = cfg
        self.rls = None
        self.lugre = None
        if self.model_name not in ADAPTED:  # lugre: the observer (ESTIMATOR_MODELS has no other)
            from friction_ros.core.friction.registry import build_model  # loads the models' kernels

            if not cfg["lugre"]:
                raise ParameterError(f"{names('lugre')} is missing: model = lugre needs a LuGre model config")
            m = build_model(cfg["lugre"], names("lugre"), within(names, "lugre"))
            if m is None or m.name != "lugre":
                raise ParameterError(f"{names('lugre')} must be a config with model: lugre")
            self.lugre = LuGreObserver(m, 0.0)
            self.coefficient_names = list(m.param_names)
        else:
            coefs = list(ADAPTED[self.model_name].names)
            init = dict(_dotted(cfg["initial"] or {}, "", names("initial")))
            check_keys(names("initial"), init, coefs)
            vals = [check_real(names(f"initial.{k}"), init.get(k, 0.0)) for k in coefs]
            self.rls = RecursiveLeastSquares(
                coefs, vals, cfg["forgetting_factor"], cfg["initial_covariance"], param_names=names
            )
            self.coefficient_names = coefs
        self.reset()

    def config(self) -> dict[str, Any]:
        return dict(self._cfg)

    def reset(self) -> None:
        self.front.reset()
        if self.rls is not None:
            self.rls.reset()
        if self.lugre is not None:
            self.lugre.reset()
        self.excited_samples = 0
        self.estimate = FrictionEstimateData(
            model=self.model_name, coefficient_names=list(self.coefficient_names)
        )
        # the last sample: time, friction torque, model torque, filtered velocity, state, excited
        self._sample: tuple = (0.0, 0.0, 0.0, 0.0, [], False)

    # -- results -------------------------------------------------------------------------------------
    @property
    def coefficients(self) -> dict[str, float]:
        if self.rls is not None:
            return dict(zip(self.coefficient_names, self.rls.theta_list()))
        return dict(zip(self.coefficient_names, (float(x) for x in self.lugre.model.param_vector())))

    @property
    def coefficient_std(self) -> dict[str, float]:
        if self.rls is None:
            return {}
        return dict(zip(self.coefficient_names, self.rls.std_list()))

    @property
    def converged(self) -> bool:
        if self.rls is None:
            return True
        return self._converged(self.rls.std_list())

    def _converged(self, std: list[float]) -> bool:
        if self.excited_samples < self.min_samples:
            return False
        tol, floor = self.convergence_tolerance, self.std_floor
        return all(s <= max(tol * abs(t), floor) for s, t in zip(std, self.rls.theta_list()))

    def predict(self, v: float) -> float:
        """Model friction at velocity ``v`` with the current coefficients (static models)."""
        if self.rls is None:
            return float(self.lugre.model.steady_state(v))
        return self.rls.predict(_regressor(self.model_name, v, self.vs, self.delta))

    def model_config(self) -> dict[str, Any]:
        """Current estimate as a friction-library model config (projected onto the valid range)."""
        if self.rls is None:
            return self.lugre.model.to_config()
        c = {k: max(v, 0.0) for k, v in self.coefficients.items()}
        return ADAPTED[self.model_name].config(c, self.vs, self.delta)

    # -- the update ----------------------------------------------------------------------------------
    def update(
        self, t: float, position: float, velocity: float, effort: float, dt: float
    ) -> FrictionEstimateData:
        """One sample: measured position (unused by the static fits), velocity, effort (N*m).
        Returns the whole estimate record (also kept in ``estimate``)."""
        self.step(t, position, velocity, effort, dt)
        return self.record()

    def step(self, t: float, position: float, velocity: float, effort: float, dt: float) -> bool:
        """One sample without building the estimate record (a node's per-sample path: the record's
        coefficient lists and convergence test are made only when published, :meth:`record`).
        Returns whether the sample excited the model."""
        if not (isinstance(dt, (int, float)) and dt > 0.0 and math.isfinite(dt)):
            raise ParameterError(f"estimator: dt = {dt!r} is out of range: must be > 0 [s]")
        y, vf, _ = self.front.update(effort, velocity, dt)
        excited = abs(vf) >= self.min_velocity and abs(float(velocity)) >= self.min_velocity
        if self.rls is not None:
            phi = _regressor(self.model_name, vf, self.vs, self.delta)
            self.rls.update(phi, y, excited=excited)
            if excited:
                self.excited_samples += 1
            model_torque = self.rls.predict(phi)
            state: list[float] = []
        else:
            obs = self.lugre
            s0 = obs.model.coefficients["sigma0"]
            # correction through the friction-measurement residual (L / sigma0 scales it to z)
            corr = self.observer_gain * (y - self._sample[2]) / s0
            v_raw = float(velocity)  # the observer runs on the measured velocity (no filter lag)
            model_torque = (
                obs.step(v_raw, dt, error=0.0) if corr == 0.0 else self._lugre_step(v_raw, dt, corr)
            )
            state = [obs.z]
        self._sample = (float(t), float(y), float(model_torque), float(vf), state, bool(excited))
        return excited

    def record(self) -> FrictionEstimateData:
        """The estimate record of the last sample (friction_msgs/FrictionEstimate fields)."""
        t, y, model_torque, vf, state, excited = self._sample
        if self.rls is not None:
            std = self.rls.std_list()
            coefficients = list(self.rls.theta_list())
            converged = self._converged(std)
        else:
            std = []
            coefficients = list(self.coefficients.values())
            converged = True
        self.estimate = FrictionEstimateData(
            time=t,
            model=self.model_name,
            friction_torque=y,
            model_torque=model_torque,
            velocity=vf,
            state=list(state),
            coefficient_names=list(self.coefficient_names),
            coefficients=coefficients,
            coefficient_std=std,
            excitation_ok=excited,
            converged=converged,
        )
        return self.estimate

    def _lugre_step(self, v: float, dt: float, corr: float) -> float:
        obs = self.lugre
        obs.gain = 1.0
        try:
            return obs.step(v, dt, error=corr)
        finally:
            obs.gain = 0.0
