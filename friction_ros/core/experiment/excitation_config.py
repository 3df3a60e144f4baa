"""Configuration of the excitation programs: defaults, profiles and validation.

Every key is documented in :mod:`friction_ros.core.experiment.excitation`. :func:`resolve_config`
merges a profile with user values and checks every range once (ParameterError names the key).
"""

from __future__ import annotations

import copy
import math
from collections.abc import Mapping
from typing import Any

from friction_ros.core import validation
from friction_ros.core.config import Names, prefixed
from friction_ros.core.validation import ParameterError

PROGRAM_NAMES = ("plateaus", "breakaway", "random", "chirp", "presliding", "sequence")
ON_LIMIT = ("stop", "skip")

#: The default profile (ABB M19-S scale). Every key is documented in the excitation module docstring.
DEFAULTS: dict[str, Any] = {
    "program": "sequence",
    "control_period": 0.001,
    "sequence": ["breakaway", "plateaus", "presliding", "random", "chirp"],
    "gap": 0.5,
    "bias": 0.0,
    "limits": {"max_travel": 100.0, "max_velocity": 40.0, "max_torque": 2.5, "on_limit": "stop"},
    "velocity_loop": {
        "p": 0.5,
        "i": 20.0,
        "torque_limit": 2.0,
        "inertia": 0.0,
        "damping": 0.0,
        "coulomb": 0.0,
        "remember_integral": True,
    },
    "plateaus": {
        "v_min": 0.1,
        "v_max": 10.0,
        "count": 6,
        "settle": 0.2,
        "hold": 0.5,
        "repeats": 3,
        "settle_travel": 0.0,
        "hold_travel": 0.0,
    },
    "breakaway": {
        "start": 0.6,
        "step": 0.002,
        "step_time": 0.008,
        "max": 1.5,
        "counts": 2,
        "resolution": 2.0 * math.pi / 60000.0,
        "preload_time": 0.3,
        "release": 0.3,
        "repeats": 3,
        "detection_lag": 0.0,
    },
    "random": {
        "duration": 50.0,
        "bandwidth": 4.0,
        "amplitude": 1.0,
        "low_level": 0.1,
        "envelope_period": 10.0,
        "seed": 3,
    },
    "chirp": {"duration": 15.0, "f0": 2.0, "f1": 10.0, "amplitude": 1.2, "final_amplitude": 0.5},
    "presliding": {"amplitudes": [0.3, 0.6, 0.85], "frequency": 1.0, "cycles": 3},
    "motion_check": {"fraction": 0.5, "max_failures": 3, "travel_counts": 10, "reversals": 1},
}

PROFILES: dict[str, dict[str, Any]] = {
    "default": {},
    "quick": {
        "gap": 0.3,
        "plateaus": {"v_min": 0.2, "v_max": 5.0, "count": 4, "repeats": 1},
        "breakaway": {"repeats": 1},
        "random": {"duration": 10.0},
        "chirp": {"duration": 4.0},
        "presliding": {"amplitudes": [0.4, 0.8], "cycles": 2},
    },
}
#: the names of the keys in messages by default: the keys themselves (``limits.max_travel``)
NAMES: Names = prefixed("")

SECTIONS = (
    "limits",
    "velocity_loop",
    "plateaus",
    "breakaway",
    "random",
    "chirp",
    "presliding",
    "motion_check",
)


# ------------------------------------------------------------------------------------------ config
def _merge(base: dict, over: Mapping) -> dict:
    out = copy.deepcopy(base)
    for k, v in over.items():
        if isinstance(v, Mapping) and isinstance(out.get(k), dict):
            out[k] = _merge(out[k], v)
        else:
            out[k] = copy.deepcopy(v)
    return out


def profile_defaults(profile: str = "default") -> dict[str, Any]:
    """The complete default config of ``profile`` (not yet merged with user values)."""
    return _merge(DEFAULTS, PROFILES[validation.check_choice("profile", profile, PROFILES)])


def resolve_config(config: Mapping[str, Any] | None = None, names: Names = NAMES) -> dict[str, Any]:
    """Profile defaults merged with ``config`` (``profile`` key, default ``default``), validated.

    Returns the complete config (every key, checked ranges); raises ParameterError naming the key
    as ``names(<dotted key>)`` (default: the key; a joint's names on an arm).
    """
    config = dict(config or {})
    profile = validation.check_choice(names("profile"), config.pop("profile", "default"), PROFILES)
    validation.check_keys("excitation", config, list(DEFAULTS))
    for s in SECTIONS:
        if s in config:
            if not isinstance(config[s], Mapping):
                raise ParameterError(f"{names(s)} = {config[s]!r} must be a mapping of {s} parameters")
            validation.check_keys(names(s), config[s], DEFAULTS[s])
    cfg = _merge(_merge(DEFAULTS, PROFILES[profile]), config)
    cfg["profile"] = profile
    _validate(cfg, names)
    return cfg


def _validate(c: dict, n: Names) -> None:
    validation.check_choice(n("program"), c["program"], PROGRAM_NAMES)
    validation.check_real(n("control_period"), c["control_period"], 1e-5, 0.1, unit="s")
    seq = c["sequence"]
    if isinstance(seq, str):
        seq = [s.strip() for s in seq.split(",") if s.strip()]
    if not isinstance(seq, (list, tuple)) or not seq:
        raise ParameterError(f"{n('sequence')} = {seq!r} must be a non-empty list of programs", n("sequence"))
    for i, name in enumerate(seq):
        validation.check_choice(f"{n('sequence')}[{i}]", name, [p for p in PROGRAM_NAMES if p != "sequence"])
    c["sequence"] = list(seq)
    validation.check_real(n("gap"), c["gap"], 0.0, 60.0, unit="s")
    lim = c["limits"]
    validation.check_real(
        n("bias"), c["bias"], -lim["max_torque"], lim["max_torque"], hi_open=True, lo_open=True, unit="N*m"
    )
    validation.check_real(
        n("limits.max_travel"), lim["max_travel"], 0.0, lo_open=True, unit="rad", allow_inf=True
    )
    validation.check_real(
        n("limits.max_velocity"), lim["max_velocity"], 0.0, lo_open=True, unit="rad/s", allow_inf=True
    )
    validation.check_real(n("limits.max_torque"), lim["max_torque"], 0.0, lo_open=True, unit="N*m")
    validation.check_choice(n("limits.on_limit"), lim["on_limit"], ON_LIMIT)
    vl = c["velocity_loop"]
    validation.check_real(n("velocity_loop.p"), vl["p"], 0.0, unit="N*m*s/rad")
    validation.check_real(n("velocity_loop.i"), vl["i"], 0.0, unit="N*m/rad")
    validation.check_real(
        n("velocity_loop.torque_limit"), vl["torque_limit"], 0.0, lim["max_torque"], lo_open=True, unit="N*m"
    )
    validation.check_real(n("velocity_loop.inertia"), vl["inertia"], 0.0, unit="kg*m^2")
    validation.check_real(n("velocity_loop.damping"), vl["damping"], 0.0, unit="N*m*s/rad")
    validation.check_real(n("velocity_loop.coulomb"), vl["coulomb"], 0.0, unit="N*m")
    validation.check_bool(n("velocity_loop.remember_integral"), vl["remember_integral"])
    p = c["plateaus"]
    validation.check_real(n("plateaus.v_min"), p["v_min"], 0.0, lo_open=True, unit="rad/s")
    validation.check_real(n("plateaus.v_max"), p["v_max"], p["v_min"], unit="rad/s")
    validation.check_int(n("plateaus.count"), p["count"], 1, 1000)
    validation.check_real(n("plateaus.settle"), p["settle"], 0.0, 60.0, unit="s")
    validation.check_real(n("plateaus.hold"), p["hold"], 0.0, 600.0, lo_open=True, unit="s")
    validation.check_int(n("plateaus.repeats"), p["repeats"], 1, 1000)
    validation.check_real(n("plateaus.settle_travel"), p["settle_travel"], 0.0, unit="rad")
    validation.check_real(n("plateaus.hold_travel"), p["hold_travel"], 0.0, unit="rad")
    if p["v_max"] >= lim["max_velocity"]:
        raise ParameterError(
            f"{n('plateaus.v_max')} = {p['v_max']:g} is out of range: must be < "
            f"{n('limits.max_velocity')} = {lim['max_velocity']:g} [rad/s]"
        )
    b = c["breakaway"]
    validation.check_real(n("breakaway.max"), b["max"], 0.0, lim["max_torque"], lo_open=True, unit="N*m")
    validation.check_real(n("breakaway.start"), b["start"], 0.0, b["max"], hi_open=True, unit="N*m")
    validation.check_real(n("breakaway.step"), b["step"], 0.0, b["max"], lo_open=True, unit="N*m")
    validation.check_real(n("breakaway.step_time"), b["step_time"], c["control_period"], 60.0, unit="s")
    validation.check_int(n("breakaway.counts"), b["counts"], 1, 10000)
    validation.check_real(n("breakaway.resolution"), b["resolution"], 0.0, 1.0, lo_open=True, unit="rad")
    validation.check_real(n("breakaway.preload_time"), b["preload_time"], 0.0, 60.0, unit="s")
    validation.check_real(n("breakaway.release"), b["release"], 0.0, 60.0, unit="s")
    validation.check_real(n("breakaway.detection_lag"), b["detection_lag"], 0.0, unit="N*m")
    validation.check_int(n("breakaway.repeats"), b["repeats"], 1, 1000)
    r = c["random"]
    validation.check_real(n("random.duration"), r["duration"], 0.0, 3600.0, lo_open=True, unit="s")
    validation.check_real(
        n("random.bandwidth"), r["bandwidth"], 0.0, 0.45 / c["control_period"], lo_open=True, unit="Hz"
    )
    validation.check_real(
        n("random.amplitude"), r["amplitude"], 0.0, lim["max_velocity"], lo_open=True, unit="rad/s"
    )
    validation.check_real(n("random.low_level"), r["low_level"], 0.0, 1.0)
    validation.check_real(
        n("random.envelope_period"), r["envelope_period"], 0.0, 3600.0, lo_open=True, unit="s"
    )
    validation.check_int(n("random.seed"), r["seed"], 0, 2**32 - 1)
    ch = c["chirp"]
    validation.check_real(n("chirp.duration"), ch["duration"], 0.0, 3600.0, lo_open=True, unit="s")
    validation.check_real(n("chirp.f0"), ch["f0"], 0.0, 0.45 / c["control_period"], lo_open=True, unit="Hz")
    validation.check_real(n("chirp.f1"), ch["f1"], ch["f0"], 0.45 / c["control_period"], unit="Hz")
    validation.check_real(
        n("chirp.amplitude"), ch["amplitude"], 0.0, lim["max_torque"], lo_open=True, unit="N*m"
    )
    validation.check_real(n("chirp.final_amplitude"), ch["final_amplitude"], 0.0, ch["amplitude"], unit="N*m")
    ps = c["presliding"]
    amps = ps["amplitudes"]
    if not isinstance(amps, (list, tuple)) or not amps:
        raise ParameterError(
            f"{n('presliding.amplitudes')} = {amps!r} must be a non-empty list of torques [N*m]",
            n("presliding.amplitudes"),
        )
    ps["amplitudes"] = [
        validation.check_real(
            f"{n('presliding.amplitudes')}[{i}]", a, 0.0, lim["max_torque"], lo_open=True, unit="N*m"
        )
        for i, a in enumerate(amps)
    ]
    validation.check_real(
        n("presliding.frequency"), ps["frequency"], 0.0, 0.45 / c["control_period"], lo_open=True, unit="Hz"
    )
    validation.check_int(n("presliding.cycles"), ps["cycles"], 1, 10000)
    mc = c["motion_check"]
    validation.check_real(n("motion_check.fraction"), mc["fraction"], 0.0, 1.0)
    validation.check_int(n("motion_check.max_failures"), mc["max_failures"], 0, 1000)
    validation.check_int(n("motion_check.travel_counts"), mc["travel_counts"], 0, 1_000_000)
    validation.check_int(n("motion_check.reversals"), mc["reversals"], 0, 1000)
