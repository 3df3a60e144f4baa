"""The run-time compensation watch across the presets: it never fires on a model within +-30 % of
the joint's true friction (any source), and catches an over-compensating file (Coulomb x4, gain 2:
the edited file that made a joint hunt with 9x the fitted file's error) wherever compensation matters.
Pure core, lockstep; the ROS side (realtime) is in test_command_safety_ros.py."""

from __future__ import annotations

import numpy as np
import pytest

from friction_ros.core.control.controller import CompensatingController
from friction_ros.core.control.overcompensation import OvercompensationWatch
from friction_ros.core.experiment.joint_scale import JointScale
from friction_ros.core.experiment.tracking_design import tracking_gains, tracking_reference
from friction_ros.core.harness import run_closed_loop
from friction_ros.core.presets import PRESET_NAMES, load_preset

DURATION = 6.0


def _scaled(cfg: dict, k: float) -> dict:
    out = dict(cfg)
    for key in ("fc", "fs"):
        if key in out:
            out[key] = out[key] * k
    for side in ("positive", "negative"):
        if side in out:
            out[side] = _scaled(out[side], k)
    return out


def _run(name: str, k: float, gain: float, source: str):
    preset = load_preset(name)
    scale = JointScale.from_preset(preset, period=1e-3)
    g = tracking_gains(scale)
    cfg = {
        "mode": "pid",
        "effort_limit": scale.torque_limit,
        "pid": {"p": g["p"], "d": g["d"]},
        "inertia": scale.inertia,
        "friction": {"model": _scaled(preset.friction.to_config(), k), "source": source, "gain": gain},
    }
    ctrl = CompensatingController(cfg)
    res = run_closed_loop(preset, ctrl, tracking_reference(scale, duration=DURATION), DURATION, 1e-3)
    return ctrl, res


PRESETS = [n for n in PRESET_NAMES if not n.startswith("arm")]


@pytest.mark.parametrize("name", PRESETS)
def test_no_false_positive_within_30_percent_of_the_true_friction(name):
    for k, source in [(1.0, "feedforward"), (1.0, "blended"), (0.7, "blended"), (1.3, "feedforward")]:
        ctrl, _ = _run(name, k, 1.0, source)
        assert not ctrl.compensation_fallback, (name, k, source, ctrl.fallback_reason)


@pytest.mark.parametrize("name", ["abb_m19s", "seed001_harmonic_drive", "seed004_dc_motor", "seed002_y"])
def test_over_compensation_is_caught_and_switched_off(name):
    late = lambda res: res.t > 4.0  # noqa: E731  (after the fallback and its transient)
    rms = lambda res: float(np.sqrt(np.mean(res.error[late(res)] ** 2)))  # noqa: E731
    _, fitted = _run(name, 1.0, 1.0, "blended")
    _, none = _run(name, 1.0, 0.0, "feedforward")
    for source in ("blended", "feedforward"):
        ctrl, res = _run(name, 4.0, 2.0, source)
        assert ctrl.compensation_fallback and "over-compensation" in ctrl.fallback_reason, (name, source)
        assert 1.0 < ctrl.watch.overcompensation.fired_at < 3.0  # armed after 1 s, then 1 s of evidence
        assert rms(res) < 1.3 * rms(none), (name, source)  # back to the plain loop
    # the same file unwatched: several times the fitted file's error
    preset = load_preset(name)
    scale = JointScale.from_preset(preset, period=1e-3)
    g = tracking_gains(scale)
    cfg = {
        "mode": "pid",
        "effort_limit": scale.torque_limit,
        "limit_cycle_detection": False,
        "pid": {"p": g["p"], "d": g["d"]},
        "friction": {"model": _scaled(preset.friction.to_config(), 4.0), "source": "blended", "gain": 2.0},
    }
    bad = run_closed_loop(preset, cfg, tracking_reference(scale, duration=DURATION), DURATION, 1e-3)
    assert rms(bad) > 2.0 * rms(fitted) and rms(bad) > rms(none)


def test_the_ratio_is_the_same_in_any_unit():
    """R and S are ratios of torques: a joint in kN or in mN*m gives the same firing time."""
    rng = np.random.default_rng(3)
    comp = np.sign(np.sin(np.arange(4000) * 2e-3)) * 0.8
    fb = -0.7 * comp + 0.05 * rng.standard_normal(comp.size)
    times = []
    for unit in (1e-3, 1.0, 1e3):
        w = OvercompensationWatch()
        times.append(
            next(k for k in range(comp.size) if w.update(k * 1e-3, unit * comp[k], unit * fb[k], 1e-3))
        )
    assert len(set(times)) == 1 and 1990 <= times[0] <= 2100
    quiet = OvercompensationWatch()
    assert not any(quiet.update(k * 1e-3, comp[k], -0.3 * comp[k], 1e-3) for k in range(comp.size))
