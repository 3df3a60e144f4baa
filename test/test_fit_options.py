"""FitOptions: every option of fit_records with its default, validated once; keyword calls unchanged."""

from __future__ import annotations

import math
import pickle
from pathlib import Path

import numpy as np
import pytest

from friction_ros.core.identification.data.csv_loading import load_csv
from friction_ros.core.identification.fit.fit_options import FitOptions
from friction_ros.core.identification.fit.load_terms import LoadTerms
from friction_ros.core.identification.fit.pipeline import fit_records
from friction_ros.core.identification.report.fit_logs import cross_validate_runs
from friction_ros.core.validation import ParameterError

PD_LOG = Path(__file__).parent / "data" / "dfki_pendulum" / "control_method_pd_system_identification.csv"


def test_defaults_units_and_descriptions():
    o = FitOptions()
    assert (o.train_seconds, o.train_window, o.optimizer, o.popsize, o.seed) == (10.0, "content", "de", 12, 3)
    assert (o.load, o.residual, o.joint_type, o.eps, o.maxiter) == ("auto", "none", "revolute", None, None)
    assert o.ripple_period == 2.0 * math.pi and o.identifiability_check and o.two_stage
    rows = {name: (default, unit, text) for name, default, unit, text in FitOptions.table()}
    assert set(rows) == set(FitOptions.names()) and len(rows) == 17
    assert rows["train_seconds"][1] == "s" and rows["ripple_period"][1] == "rad"
    assert all(text and "\n" not in text for _, _, text in rows.values())
    with pytest.raises(AttributeError):  # frozen
        o.seed = 4  # type: ignore[misc]


@pytest.mark.parametrize(
    ("kw", "message"),
    [
        ({"train_seconds": 0.0}, "train_seconds = 0 is out of range: must be > 0"),
        (
            {"train_window": "last"},
            "train_window = 'last' is not allowed: must be one of content, window, first",
        ),
        ({"optimizer": "pso"}, "optimizer = 'pso' is not allowed: must be one of de, ga, none"),
        ({"maxiter": 0}, "maxiter = 0 is out of range: must be an integer >= 1"),
        ({"maxiter": {"lugre": -2}}, "maxiter['lugre'] = -2 is out of range"),
        ({"popsize": 2.5}, "popsize = 2.5 must be an integer >= 1"),
        ({"eps": -1e-3}, "eps = -0.001 is out of range: must be > 0"),
        ({"load_eps": math.nan}, "load_eps = nan is not finite"),
        ({"identifiability_check": "yes"}, "identifiability_check = 'yes' must be true or false"),
        ({"load": "gravity,wind"}, "load term 'wind' is not allowed"),
        ({"load": 3}, "load = 3 is not allowed: must be auto, none, a term list or LoadTerms"),
        ({"ripple_period": -1.0}, "ripple_period = -1 is out of range: must be > 0 [rad]"),
        ({"residual": "svm"}, "residual = 'svm' is not allowed: must be one of auto, none, mlp, rff"),
        (
            {"joint_type": "rotary"},
            "joint_type = 'rotary' is not allowed: must be one of revolute, prismatic",
        ),
        ({"max_samples": -5}, "max_samples = -5 is out of range"),
    ],
)
def test_a_bad_value_is_refused_naming_the_option(kw, message):
    with pytest.raises(ParameterError) as err:
        FitOptions.from_kwargs(**kw)
    assert message in str(err.value) and "\n" not in str(err.value)
    with pytest.raises(ParameterError, match=next(iter(kw))):  # the keyword call style checks the same
        fit_records([], ["coulomb"], **kw)


def test_unknown_names_are_refused_in_one_line():
    with pytest.raises(ParameterError) as err:
        FitOptions.from_kwargs(train_second=5.0, seed=1)
    text = str(err.value)
    assert "'train_second'" in text and "train_seconds" in text and "\n" not in text
    with pytest.raises(ParameterError, match="unknown parameter.*'popsise'"):
        FitOptions().replace(popsise=8)


def test_replace_resolve_and_pickle():
    o = FitOptions(seed=7, maxiter={"lugre": 5}, load=LoadTerms(offset=True))
    assert o.replace(seed=8).seed == 8 and o.seed == 7
    assert FitOptions.resolve(o, {}) is o and FitOptions.resolve(None, {"seed": 7}).seed == 7
    assert (o.maxiter_for("lugre"), o.maxiter_for("gms4"), FitOptions(maxiter=9).maxiter_for("gms4")) == (
        5,
        None,
        9,
    )
    assert pickle.loads(pickle.dumps(o)) == o  # crosses the process pool of the multi-joint fit
    with pytest.raises(ParameterError, match="must be a FitOptions"):
        FitOptions.resolve({"seed": 3}, {})


@pytest.fixture(scope="module")
def pd_log():
    return load_csv(PD_LOG)


def _numbers(res) -> dict:
    return {
        n: (m.status, m.coefficients, {k: v for k, v in m.metrics.items() if not isinstance(v, str)})
        for n, m in res.models.items()
    }


def test_an_options_object_and_keywords_give_the_same_fit(pd_log):
    kw = dict(identifiability_check=False, train_seconds=1.5, load="none", seed=5)
    by_kw = fit_records([pd_log], ["coulomb_viscous", "stribeck"], maxiter=4, **kw)
    opts = FitOptions(**kw)
    by_obj = fit_records([pd_log], ["coulomb_viscous", "stribeck"], opts, maxiter=4)
    assert _numbers(by_kw) == _numbers(by_obj) and by_kw.recommended == by_obj.recommended
    assert by_kw.models["coulomb_viscous"].fitted and by_kw.options["seed"] == 5
    assert np.isfinite(by_kw.models["coulomb_viscous"].metrics["nmse_percent"])
    # the options reach the fit: another training length gives other numbers
    other = fit_records([pd_log], ["coulomb_viscous"], opts.replace(train_seconds=3.0))
    assert other.options["train_seconds"] == 3.0
    assert other.models["coulomb_viscous"].coefficients != by_obj.models["coulomb_viscous"].coefficients


def test_cross_validation_takes_an_options_object(pd_log):
    half = pd_log.n // 2
    runs = [pd_log.slice(0, half), pd_log.slice(half, pd_log.n)]
    opts = FitOptions(load="none", train_seconds=1.5)
    a = cross_validate_runs(runs, ["coulomb_viscous"], opts)
    b = cross_validate_runs(runs, ["coulomb_viscous"], load="none", train_seconds=1.5)
    assert a == b and len(a["folds"]) == 2
    assert all(math.isfinite(f["nmse_percent"]["coulomb_viscous"]) for f in a["folds"])


def test_cli_names_the_command_line_option(tmp_path, capsys):
    from friction_ros.cli.fit import main

    code = main([str(PD_LOG), "--out", str(tmp_path / "fit"), "--train-seconds", "-2", "--quiet"])
    err = capsys.readouterr().err.strip()
    assert code == 2 and err.count("\n") == 0
    assert err == "friction-fit: error: --train-seconds = -2 is out of range: must be > 0 [s]"
    assert not (tmp_path / "fit").exists()
