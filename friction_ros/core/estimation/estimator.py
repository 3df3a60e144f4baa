"""``OnlineFrictionEstimator``: friction measurement + online model fit, built from a config dict.

Pipeline per sample (effort = motor torque on the joint side, velocity measured):

1. friction "measurement" ``y``: torque balance with filtered acceleration, or a disturbance
   observer (``method``, :mod:`.measurement`);
2. ``model``:

   * linear in the parameters, fitted by RLS with forgetting and excitation gating
     (:mod:`.rls`), regressors in the filtered velocity ``v_f``:

     ``viscous``                     F = fv v
     ``coulomb_viscous``             F = fc sgn(v) + fv v
     ``asymmetric_coulomb_viscous``  F = fc_pos + fv_pos v (v > 0);  -fc_neg + fv_neg v (v < 0)
     ``stribeck``                    F = [fc + (fs - fc) E(v)] sgn(v) + fv v, E = exp(-|v/vs|^delta),
                                     vs and delta fixed (linear in fc, fs, fv)
     ``asymmetric_stribeck``         the same with a set per direction

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

from friction_ros.core.estimation.lugre_observer import LuGreObserver
from friction_ros.core.estimation.measurement import DisturbanceObserver, TorqueBalanceEstimator
from friction_ros.core.estimation.rls import RecursiveLeastSquares
from friction_ros.core.validation import (
    ParameterError,
    check_choice,
    check_int,
    check_keys,
    check_real,
)

METHODS = ("torque_balance", "disturbance_observer")
ESTIMATOR_MODELS = (
    "viscous",
    "coulomb_viscous",
    "asymmetric_coulomb_viscous",
    "stribeck",
    "asymmetric_stribeck",
    "lugre",
)
_COEF_NAMES = {
    "viscous": ["fv"],
    "coulomb_viscous": ["fc", "fv"],
    "asymmetric_coulomb_viscous": ["fc_pos", "fc_neg", "fv_pos", "fv_neg"],
    "stribeck": ["fc", "fs", "fv"],
    "asymmetric_stribeck": ["fc_pos", "fs_pos", "fv_pos", "fc_neg", "fs_neg", "fv_neg"],
}

ESTIMATOR_DEFAULTS: dict[str, Any] = {
    "method": "torque_balance",
    "model": "coulomb_viscous",
    "inertia": 0.0,  # required > 0 for the disturbance observer
    "filter_time_constant": 0.005,
    "observer_bandwidth": 200.0,
    "initial": None,  # {coefficient: value}; missing -> 0
    "vs": 0.05,
    "delta": 2.0,
    "forgetting_factor": 0.999,
    "initial_covariance": 10.0,
    "min_velocity": 0.01,
    "min_samples": 200,
    "convergence_tolerance": 0.02,
    "std_floor": 1e-3,
    "lugre": None,  # LuGre model config for model = lugre
    "observer_gain": 50.0,
}


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


def regressor(model: str, v: float, vs: float = 0.05, delta: float = 2.0) -> np.ndarray:
    """phi(v) of the linear-in-parameter models (see the module docstring)."""
    return np.array(_regressor(model, v, vs, delta))


def _regressor(model: str, v: float, vs: float, delta: float) -> tuple[float, ...]:
    """phi(v) as a tuple of floats (hot path of :meth:`OnlineFrictionEstimator.update`)."""
    v = float(v)
    s = 1.0 if v > 0 else (-1.0 if v < 0 else 0.0)
    if model == "viscous":
        return (v,)
    if model == "coulomb_viscous":
        return (s, v)
    if model == "asymmetric_coulomb_viscous":
        p, n = float(v > 0), float(v < 0)
        return (p, -n, p * v, n * v)
    E = math.exp(-(abs(v / vs) ** delta))
    if model == "stribeck":
        return (s * (1.0 - E), s * E, v)
    if model == "asymmetric_stribeck":
        p, n = float(v > 0), float(v < 0)
        return (p * (1 - E), p * E, p * v, -n * (1 - E), -n * E, n * v)
    raise ParameterError(f"estimator.model = {model!r} is not linear in its parameters")


class OnlineFrictionEstimator:
    """Online friction estimator façade; see the module docstring and :data:`ESTIMATOR_DEFAULTS`."""

    def __init__(self, config: Mapping[str, Any] | None = None):
        cfg = dict(ESTIMATOR_DEFAULTS)
        given = dict(config or {})
        check_keys("estimator", given, ESTIMATOR_DEFAULTS)
        cfg.update(given)
        n = "estimator"
        self.method = check_choice(f"{n}.method", cfg["method"], METHODS)
        self.model_name = check_choice(f"{n}.model", cfg["model"], ESTIMATOR_MODELS)
        lo_open = self.method == "disturbance_observer"
        self.inertia = check_real(f"{n}.inertia", cfg["inertia"], 0.0, lo_open=lo_open, unit="kg*m^2")
        if self.method == "torque_balance":
            self.front = TorqueBalanceEstimator(self.inertia, cfg["filter_time_constant"])
        else:
            self.front = DisturbanceObserver(self.inertia, cfg["observer_bandwidth"])
        self.filter_time_constant = float(cfg["filter_time_constant"])
        self.observer_bandwidth = float(cfg["observer_bandwidth"])
        self.vs = check_real(f"{n}.vs", cfg["vs"], 0.0, lo_open=True, unit="rad/s")
        self.delta = check_real(f"{n}.delta", cfg["delta"], 0.0, lo_open=True)
        self.min_velocity = check_real(f"{n}.min_velocity", cfg["min_velocity"], 0.0, unit="rad/s")
        self.min_samples = check_int(f"{n}.min_samples", cfg["min_samples"], 1)
        self.convergence_tolerance = check_real(
            f"{n}.convergence_tolerance", cfg["convergence_tolerance"], 0.0, 1.0, lo_open=True
        )
        self.std_floor = check_real(f"{n}.std_floor", cfg["std_floor"], 0.0)
        self.observer_gain = check_real(f"{n}.observer_gain", cfg["observer_gain"], 0.0, unit="1/s")
        self._cfg = cfg
        self.rls = None
        self.lugre = None
        if self.model_name == "lugre":
            from friction_ros.core.control.compensation import build_model

            if cfg["lugre"] is None:
                raise ParameterError(f"{n}.lugre is missing: model = lugre needs a LuGre model config")
            m = build_model(cfg["lugre"], f"{n}.lugre")
            if m is None or m.name != "lugre":
                raise ParameterError(f"{n}.lugre must be a config with model: lugre")
            self.lugre = LuGreObserver(m, 0.0)
            self.coefficient_names = list(m.param_names)
        else:
            names = _COEF_NAMES[self.model_name]
            init = dict(cfg["initial"] or {})
            check_keys(f"{n}.initial", init, names)
            vals = [check_real(f"{n}.initial.{k}", init.get(k, 0.0)) for k in names]
            self.rls = RecursiveLeastSquares(names, vals, cfg["forgetting_factor"], cfg["initial_covariance"])
            self.coefficient_names = names
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
        c = {k: max(v, 0.0) for k, v in self.coefficients.items()} if self.rls is not None else None
        if self.model_name == "lugre":
            return self.lugre.model.to_config()
        if self.model_name == "viscous":
            return {"model": "viscous", "fv": c["fv"]}
        if self.model_name == "coulomb_viscous":
            return {"model": "coulomb_viscous", "fc": c["fc"], "fv": c["fv"]}
        if self.model_name == "asymmetric_coulomb_viscous":
            return {
                "model": "asymmetric",
                "base": "coulomb_viscous",
                "positive": {"fc": c["fc_pos"], "fv": c["fv_pos"]},
                "negative": {"fc": c["fc_neg"], "fv": c["fv_neg"]},
            }

        def strib(fc, fs, fv):
            return {"fc": fc, "fs": max(fs, fc), "vs": self.vs, "delta": self.delta, "fv": fv}

        if self.model_name == "stribeck":
            return {"model": "stribeck", **strib(c["fc"], c["fs"], c["fv"])}
        return {
            "model": "asymmetric",
            "base": "stribeck",
            "positive": strib(c["fc_pos"], c["fs_pos"], c["fv_pos"]),
            "negative": strib(c["fc_neg"], c["fs_neg"], c["fv_neg"]),
        }

    # -- the update ----------------------------------------------------------------------------------
    def update(
        self, t: float, position: float, velocity: float, effort: float, dt: float
    ) -> FrictionEstimateData:
        """One sample: measured position (unused by the static fits), velocity, effort (N*m)."""
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
            std = self.rls.std_list()
            coefficients = list(self.rls.theta_list())
            converged = self._converged(std)
        else:
            obs = self.lugre
            s0 = obs.model.coefficients["sigma0"]
            # correction through the friction-measurement residual (L / sigma0 scales it to z)
            corr = self.observer_gain * (y - self.estimate.model_torque) / s0
            v_raw = float(velocity)  # the observer runs on the measured velocity (no filter lag)
            model_torque = (
                obs.step(v_raw, dt, error=0.0) if corr == 0.0 else self._lugre_step(v_raw, dt, corr)
            )
            state = [obs.z]
            std = []
            coefficients = list(self.coefficients.values())
            converged = True
        self.estimate = FrictionEstimateData(
            time=float(t),
            model=self.model_name,
            friction_torque=float(y),
            model_torque=float(model_torque),
            velocity=float(vf),
            state=state,
            coefficient_names=list(self.coefficient_names),
            coefficients=coefficients,
            coefficient_std=std,
            excitation_ok=bool(excited),
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
