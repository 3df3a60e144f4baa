"""The fit's safety gate: check the recommended model's compensation modes before they are written.

:func:`gate_fit` builds the identified plant's scale (the fitted inertia, the recommended model's
breakaway and the data's encoder resolution and sample period, plus the current-loop lag and
delays the user measured), derives the tracking gains and a reference from it
(:mod:`friction_ros.core.experiment.tracking_design`) and runs :func:`friction_ros.core.compensation_gate.gate_modes`.
The verdicts are kept in ``FitResult.gate`` and in the options the parameter document is built
with, so the written file enables only modes that passed.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from friction_ros.core.compensation_gate import MODES, Verdict, gate_modes
from friction_ros.core.identification.data.data_scale import velocity_scale


def _refuse_all(reason: str) -> dict[str, Verdict]:
    return {m: Verdict(m, False, f"refused: {reason}") for m in MODES}


def gate_fit(
    res,
    *,
    scale=None,
    current_lag: float = 0.0,
    delay: float = 0.0,
    velocity_filter_hz: float = 0.0,
    gains: dict | None = None,
    reference: dict | None = None,
    assumed: str = "",
) -> dict[str, Verdict]:
    """Gate the recommended model of ``res`` (a FitResult); see the module docstring.

    ``scale``: a JointScale of the joint when known (a preset, a probe): its gains and reference
    are used, with the fitted inertia. ``current_lag``/``delay`` [s]: the drive's current-loop time
    constant and pure delays (the control period is added by the loop itself). ``assumed``: a
    warning for the result when those were assumed rather than given.
    """
    from friction_ros.core.experiment.joint_scale import JointScale
    from friction_ros.core.experiment.tracking_design import tracking_gains, tracking_reference

    name = res.recommended
    if name is None or res.models[name].config is None:
        verdicts = _refuse_all("no parametric model was recommended")
    else:
        m = res.models[name]
        J = float(m.coefficients.get("J", 0.0) or 0.0)
        rec = res.train[0]
        resolution = rec.resolution if rec.resolution > 0 else 0.0
        if scale is not None and not J > 0:
            J = scale.inertia
        if not J > 0:
            verdicts = _refuse_all("the inertia was not identified (J = 0): the loop cannot be checked")
        else:
            vsc = velocity_scale(rec)
            v = np.geomspace(1e-6, 1.0, 50) * vsc
            fb = float(max(np.max(np.abs(m.steady_state(v))), np.max(np.abs(m.steady_state(-v))), 1e-12))
            speeds = [abs(p.velocity) for p in res.plateaus] or [float(np.max(np.abs(rec.velocity)))]
            if scale is None:
                lag = current_lag + (
                    1.0 / (2.0 * math.pi * velocity_filter_hz) if velocity_filter_hz > 0 else 0.0
                )
                scale = JointScale(
                    breakaway=fb,
                    inertia=J,
                    torque_limit=10.0 * fb,
                    speed_limit=2.5 * max(speeds),
                    travel=1e3,
                    resolution=resolution if resolution > 0 else 1e-7 * vsc,
                    period=rec.dt,
                    current_lag=lag,
                    delay=delay,
                    load=-float(res.options.get("load_offset", 0.0) or 0.0),
                )
            else:
                scale = replace(scale, inertia=J)
            gains = dict(gains or tracking_gains(scale))
            reference = dict(reference or tracking_reference(scale, 4.0))
            verdicts = gate_modes(
                m.config,
                J,
                gains=gains,
                reference=reference,
                current_lag=current_lag,
                delay=delay,
                period=scale.period,
                resolution=resolution,
                velocity_filter_hz=velocity_filter_hz,
                damping=max(scale.damping - scale.viscous, 0.0),
                load_feedforward=-scale.load,
            )
            res.options["gate_options"] = {"gate": verdicts, "gains": gains, "load_feedforward": -scale.load}
            res.options["gate_reference"] = reference
    res.options.setdefault("gate_options", {"gate": verdicts})
    res.gate = verdicts
    if assumed:
        res.warnings.append(assumed)
    return verdicts


def preset_lags(preset) -> dict:
    """The gate's ``current_lag``, ``delay`` and ``velocity_filter_hz`` of a plant preset (a loaded
    Preset): the same values wherever the gate runs (friction-fit --plant-preset, the demo)."""
    p = preset.params
    return {
        "current_lag": p.current_time_constant if p.actuation == "current" else 0.0,
        "delay": p.measurement_delay + p.actuation_delay,
        "velocity_filter_hz": p.velocity_filter_hz,
    }
