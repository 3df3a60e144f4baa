"""User limits constrain the experiment (pure core + the CLI's sizing step): speeds and amplitudes are
re-derived within limits.max_travel / max_velocity instead of running into them; a value the user
set that cannot fit is refused with one line naming it."""

from __future__ import annotations

import numpy as np
import pytest

from friction_ros.core.experiment.excitation import make_program
from friction_ros.core.experiment.excitation_config import resolve_config
from friction_ros.core.experiment.experiment_sizing import LIMIT_SHARE, fit_to_limits, plateau_travel
from friction_ros.core.experiment.velocity_programs import random_velocity
from friction_ros.core.presets import load_preset
from friction_ros.core.validation import ParameterError


def _plateau_speeds(cfg):
    return [abs(s.target) for s in make_program(cfg).segments if s.program == "plateaus"]


def test_the_profile_plateaus_fit_a_small_travel():
    cfg = resolve_config({"program": "plateaus", "limits": {"max_travel": 3.0}})
    fitted = fit_to_limits(cfg)
    p = fitted["plateaus"]
    assert p["v_max"] == pytest.approx(1.5 / 0.7, rel=1e-6)  # half the travel in settle + hold
    assert p["v_min"] / p["v_max"] == pytest.approx(0.1 / 10.0)  # the profile's span is kept
    for v in _plateau_speeds(fitted):
        assert plateau_travel(p, v) <= LIMIT_SHARE * 3.0 + 1e-9
    assert cfg["plateaus"]["v_max"] == 10.0  # input untouched


def test_the_speed_limit_bounds_the_fastest_plateau_and_the_random_peak():
    cfg = resolve_config({"limits": {"max_velocity": 4.0}, "plateaus": {"v_max": 3.9}})
    fitted = fit_to_limits(cfg)
    assert fitted["plateaus"]["v_max"] == pytest.approx(2.0)
    v = random_velocity(fitted)
    assert np.max(np.abs(v)) <= 2.0 + 1e-9 and fitted["random"]["amplitude"] < 1.0


def test_the_random_excursion_fits_the_travel():
    cfg = resolve_config({"program": "random", "limits": {"max_travel": 0.5}})
    fitted = fit_to_limits(cfg)
    x = np.cumsum(random_velocity(fitted)) * fitted["control_period"]
    assert np.max(np.abs(x)) == pytest.approx(0.25, rel=1e-6)
    assert (
        np.max(np.abs(np.cumsum(random_velocity(cfg)) * cfg["control_period"])) > 0.25
    )  # it did not fit before


def test_defaults_are_left_as_they_are():
    for program in ("sequence", "plateaus", "random"):
        cfg = resolve_config({"program": program})
        assert fit_to_limits(cfg) == cfg


def test_a_user_value_that_cannot_fit_is_refused_naming_it():
    cfg = resolve_config({"program": "plateaus", "plateaus": {"v_max": 10.0}, "limits": {"max_travel": 3.0}})
    with pytest.raises(
        ParameterError, match=r"plateaus.v_max = 10 rad/s .* limits.max_travel = 3 rad.*at most 2.143"
    ):
        fit_to_limits(cfg, keep={"plateaus.v_max", "limits.max_travel"})
    cfg = resolve_config({"program": "random", "random": {"amplitude": 1.0}, "limits": {"max_travel": 0.5}})
    with pytest.raises(ParameterError, match="random.amplitude = 1 rad/s"):
        fit_to_limits(cfg, keep={"random.amplitude"})


def test_set_limits_bound_the_joint_the_program_is_sized_to():
    from friction_ros.cli.experiment import build_parser
    from friction_ros.cli.experiment_config import sized_config

    args = build_parser().parse_args(["--profile", "quick"])
    preset = load_preset("abb_m19s")
    free = sized_config(args, preset)
    bound = sized_config(args, preset, {"limits.max_travel": 3.0, "limits.max_velocity": 20.0})
    p = bound["plateaus"]
    assert free["plateaus"]["v_max"] > 20.0  # the preset allows far more
    assert bound["limits"]["max_travel"] == 3.0 and bound["limits"]["max_velocity"] == 20.0
    assert p["v_max"] <= 0.4 * 20.0 and p["v_max"] * (p["settle"] + p["hold"]) <= 0.5 * 3.0 + 1e-9
    assert fit_to_limits(resolve_config({**bound, "program": "sequence"}))["plateaus"] == p  # fits already
    with pytest.raises(ParameterError, match="the --set limits leave no room"):
        sized_config(args, preset, {"limits.max_torque": 0.5})  # below the breakaway torque
