"""Compensation safety gate: check every friction-compensation mode in closed loop before enabling it.

A fitted model can make a joint worse: a feedback term that cancels the loop's damping, a model
that over-compensates. Before a parameter file enables a mode, :func:`gate_modes` simulates the
tracking loop (``friction_ros.core.harness.run_closed_loop``) on the *identified* plant: inertia
``J`` from the fit, the fitted friction model as the plant's friction, the measured current-loop
lag, velocity filter, encoder resolution and delays. The controller always keeps the nominal
fitted model; the plant's friction is perturbed to cover identification error:

* all force-level coefficients (``fc, fs, fv, sigma0, sigma1, k, ...``) x 0.8 and x 1.2;
* the presliding dynamics alone (``sigma0``/``sigma1``, GMS ``k``/``sigma1``) x 0.8 and x 1.2.

Per case the uncompensated loop runs on the same perturbed plant. A mode is **refused** when, in
any case,

* it is not robustly stable: the run-time limit-cycle detector
  (:mod:`friction_ros.core.control.limit_cycle`) fires while the uncompensated loop on the same
  plant does not oscillate (the oscillation is compensation-induced and not in the reference), the
  RMS error is not finite or above 10x the uncompensated one, the peak command exceeds
  ``command_limit`` (saturation), or the error or the command grows (RMS of the last quarter above
  twice the uncompensated run's peak);
* or its RMS tracking error exceeds the uncompensated one by more than ``tolerance`` (2 %).

Otherwise it is **enabled**, with the worst ratio (mode RMS / uncompensated RMS) as its figure.
The simulated controller is the real one, including the feedback-path stability bound
(:meth:`~friction_ros.core.control.compensation.FrictionCompensator.bound_feedback`); when the
bound limited the model, the verdict's reason says so. Cost: (1 + len(modes)) x len(cases) runs
of ``duration`` (4 s at 1 kHz): about 1 s for 3 modes x 5 cases.
"""

from __future__ import annotations

import copy
import math
from collections.abc import Iterable, Mapping
from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np

from friction_ros.core.control.controller import CompensatingController
from friction_ros.core.control.limit_cycle import LimitCycleDetector
from friction_ros.core.harness import run_closed_loop
from friction_ros.core.plant.params import PlantParams
from friction_ros.core.plant.servo import GearheadServoPlant
from friction_ros.core.validation import check_real

MODES = ("feedforward", "feedback", "blended")
#: force-level coefficients (scaled by the perturbation); shapes (vs, delta, alpha) are kept
FORCE_KEYS = ("fc", "fs", "fv", "fl", "sigma", "sigma0", "sigma1", "k", "attraction")
DYNAMIC_KEYS = ("sigma0", "sigma1", "k", "sigma")


@dataclass
class Verdict:
    """The gate's decision for one compensation mode."""

    mode: str
    enabled: bool
    reason: str
    rms_none: float = math.nan
    rms_mode: float = math.nan
    worst_ratio: float = math.nan
    cases: list[dict] = field(default_factory=list)

    def as_dict(self) -> dict:
        return asdict(self)


def _scale(cfg: Any, factor: float, keys: Iterable[str]) -> Any:
    keys = tuple(keys)
    if isinstance(cfg, Mapping):
        out = {}
        for k, v in cfg.items():
            if k in keys and isinstance(v, (int, float)) and not isinstance(v, bool):
                out[k] = float(v) * factor
            elif k in keys and isinstance(v, (list, tuple)):
                out[k] = [float(x) * factor for x in v]
            elif isinstance(v, Mapping):
                out[k] = _scale(v, factor, keys)
            else:
                out[k] = copy.deepcopy(v)
        return out
    return cfg


def perturbations(friction_config: Mapping, perturbation: float = 0.2) -> list[tuple[str, dict]]:
    """(label, plant friction config) cases: nominal, all forces +-p, presliding dynamics +-p."""
    lo, hi = 1.0 - perturbation, 1.0 + perturbation
    cases = [
        ("nominal", copy.deepcopy(dict(friction_config))),
        (f"forces x{lo:g}", _scale(friction_config, lo, FORCE_KEYS)),
        (f"forces x{hi:g}", _scale(friction_config, hi, FORCE_KEYS)),
    ]
    text = repr(friction_config)
    if any(f"'{k}'" in text for k in ("sigma0", "sigma1", "k")):
        cases += [
            (f"presliding x{lo:g}", _scale(friction_config, lo, DYNAMIC_KEYS)),
            (f"presliding x{hi:g}", _scale(friction_config, hi, DYNAMIC_KEYS)),
        ]
    return cases


def identified_plant(
    inertia: float,
    friction_config: Mapping | None,
    *,
    current_lag: float = 0.0,
    delay: float = 0.0,
    resolution: float = 0.0,
    velocity_filter_hz: float = 0.0,
    damping: float = 0.0,
):
    """A plant with the identified J and friction (torque in N*m = current in A: unit gains);
    ``damping`` [N*m*s/rad]: viscous damping that is not friction (a voltage drive's back-EMF)."""

    cpr = int(round(2.0 * math.pi / resolution)) if resolution > 0 else 0
    return GearheadServoPlant(
        PlantParams(
            motor_inertia=check_real("inertia", inertia, 0.0, lo_open=True, unit="kg*m^2"),
            torque_constant=1.0,
            actuation="current",
            current_time_constant=current_lag,
            encoder_cpr=cpr,
            velocity_filter_hz=velocity_filter_hz,
            motor_damping=damping,
            measurement_delay=delay,
            friction_motor=dict(friction_config) if friction_config else {"model": "none"},
        )
    )


def _run(plant_args: dict, friction_cfg, controller: dict, reference: dict, duration: float, period: float):

    plant = identified_plant(friction_config=friction_cfg, **plant_args)
    ctrl = CompensatingController(controller)
    res = run_closed_loop(plant, ctrl, reference, duration, period, scale=1.0)
    e = res.reference[:, 0] - res.true_position
    return e, ctrl, res


def _oscillates(res, period: float):
    """The run-time limit-cycle detector run over a recorded loop; returns it when it fired."""

    det = LimitCycleDetector()
    e = res.reference[:, 0] - res.position
    for k in range(e.size):
        if det.update(
            res.t[k], e[k], res.command[k], res.reference[k, 1], res.position[k], period, res.reference[k, 0]
        ):
            return det
    return None


def _rms(x) -> float:
    with np.errstate(all="ignore"):
        r = float(np.sqrt(np.mean(np.square(x))))
    return r if math.isfinite(r) else math.inf


def gate_modes(
    friction_config: Mapping,
    inertia: float,
    *,
    gains: Mapping[str, float],
    reference: Mapping[str, Any],
    current_lag: float = 0.0,
    delay: float = 0.0,
    period: float = 1e-3,
    resolution: float = 0.0,
    velocity_filter_hz: float = 0.0,
    damping: float = 0.0,
    load_feedforward: float = 0.0,
    modes: Iterable[str] = MODES,
    perturbation: float = 0.2,
    duration: float = 4.0,
    tolerance: float = 0.02,
    command_limit: float = math.inf,
    feedback_bound: float | None = None,
) -> dict[str, Verdict]:
    """Verdict per compensation mode (module docstring).

    ``friction_config``/``inertia`` [kg*m^2]: the fitted model and J; ``gains``: the tracking PID
    (``p`` N*m/rad, ``d`` N*m*s/rad ...); ``reference``: the tracking reference config;
    ``current_lag`` [s] current-loop time constant; ``delay`` [s] measurement delay excluding the
    control ``period`` [s]; ``resolution`` [rad] encoder count; ``velocity_filter_hz`` [Hz];
    ``damping`` [N*m*s/rad]; ``perturbation``: relative change of the plant's coefficients;
    ``duration`` [s] per run; ``tolerance``: allowed relative RMS increase; ``command_limit``
    [N*m]: peak command that counts as saturation; ``feedback_bound``: the controller's
    ``friction.feedback_bound`` (None: its default).
    """
    modes = tuple(modes)
    ref = dict(reference, duration=max(float(reference.get("duration", duration)), duration))
    plant_args = {
        "inertia": inertia,
        "current_lag": current_lag,
        "delay": delay,
        "resolution": resolution,
        "velocity_filter_hz": velocity_filter_hz,
        "damping": damping,
    }
    # no run-time fallback in the simulation: the gate judges what the mode does
    base = {
        "mode": "pid",
        "pid": dict(gains),
        "inertia": float(inertia),
        "load_feedforward": load_feedforward,
        "limit_cycle_detection": False,
    }
    cases = perturbations(friction_config, perturbation)
    none_runs = {}
    for label, cfg in cases:
        e, _, r0 = _run(plant_args, cfg, base, ref, duration, period)
        none_runs[label] = (e, np.asarray(r0.command, dtype=float), _oscillates(r0, period) is not None)
    out: dict[str, Verdict] = {}
    for mode in modes:
        comp = {"model": dict(friction_config), "source": mode}
        if feedback_bound is not None:
            comp["feedback_bound"] = feedback_bound
        ctrl_cfg = dict(base, friction=comp)
        rows, refused, bound_note = [], [], ""
        for label, cfg in cases:
            e, ctrl, r1 = _run(plant_args, cfg, ctrl_cfg, ref, duration, period)
            bound_note = bound_note or ctrl.feedback_bound_note
            e0, u0, none_osc = none_runs[label]
            u = np.asarray(r1.command, dtype=float)
            q = max(len(e) // 4, 1)
            rms0, rms = _rms(e0), _rms(e)
            with np.errstate(all="ignore"):
                u_peak = float(np.max(np.abs(u)))
            u_peak = u_peak if math.isfinite(u_peak) else math.inf
            growing = (
                _rms(e[-q:]) > 2.0 * float(np.max(np.abs(e0))) + 1e-12
                or _rms(u[-q:]) > 2.0 * float(np.max(np.abs(u0))) + 1e-12
            )
            lc = _oscillates(r1, period)
            cycle = lc is not None and not none_osc
            ratio = rms / rms0 if rms0 > 0 else math.inf
            rows.append(
                {
                    "case": label,
                    "rms_none": rms0,
                    "rms": rms,
                    "ratio": ratio,
                    "limit_cycle": cycle,
                    "growing": growing,
                    "peak_command": u_peak,
                }
            )
            if not math.isfinite(ratio) or ratio > 10.0:
                refused.append(f"unstable: the error grows without bound with plant friction {label}")
            elif cycle:
                refused.append(
                    f"limit cycle ({lc.frequency:.0f} Hz, not in the reference) with plant friction {label}"
                )
            elif u_peak > command_limit:
                refused.append(
                    f"saturates: peak command {u_peak:.3g} above the limit {command_limit:g} "
                    f"with plant friction {label}"
                )
            elif ratio > 1.0 + tolerance:
                refused.append(
                    f"{100.0 * (ratio - 1.0):.0f} % worse than no compensation with plant friction {label}"
                )
            elif growing:
                refused.append(f"error or command grows with plant friction {label}")
        worst = max(r["ratio"] for r in rows)
        nominal = rows[0]
        bound = f"; {bound_note}" if bound_note else ""
        if refused:
            more = f" (+{len(refused) - 1} more cases)" if len(refused) > 1 else ""
            reason = "refused: " + refused[0] + more
        else:
            reason = (
                f"enabled: {100.0 * (1.0 - nominal['ratio']):.0f} % lower RMS error on the identified plant, "
                f"{100.0 * (1.0 - worst):.0f} % lower in the worst of {len(rows)} cases "
                f"(+-{100 * perturbation:.0f} % coefficients)"
            )
        out[mode] = Verdict(
            mode, not refused, reason + bound, nominal["rms_none"], nominal["rms"], worst, rows
        )
    return out
