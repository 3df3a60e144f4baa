"""One name per coefficient: identification, estimator and message fields use the library's names."""

import numpy as np
import pytest

from friction_ros.core.coefficient_exchange import to_fields
from friction_ros.core.estimation.estimator import ESTIMATOR_MODELS, OnlineFrictionEstimator
from friction_ros.core.friction import MODEL_CLASSES, model_from_config
from friction_ros.core.identification.fit.fit_registry import library_config
from friction_ros.core.identification.fit.models import spec_for
from friction_ros.core.identification.report.export import estimator_section


@pytest.mark.parametrize("model", [m for m in ESTIMATOR_MODELS if m != "lugre"])
def test_estimator_coefficient_names_are_the_message_field_names(model):
    est = OnlineFrictionEstimator({"model": model})
    _, names, _ = to_fields(est.model_config())
    assert set(est.coefficient_names) <= set(names)
    assert est.estimate.coefficient_names == est.coefficient_names


@pytest.mark.parametrize("base", ["coulomb_viscous", "stribeck"])
def test_exported_estimator_section_starts_from_the_fitted_levels(base):
    side = (
        {"fc": 0.3, "fv": 0.02}
        if base == "coulomb_viscous"
        else {"fc": 0.3, "fs": 0.4, "vs": 0.05, "delta": 2.0, "fv": 0.02}
    )
    neg = {k: 1.5 * v if k in ("fc", "fs", "fv") else v for k, v in side.items()}
    config = {"model": "asymmetric", "base": base, "positive": side, "negative": neg}
    est = OnlineFrictionEstimator(estimator_section(config, inertia=0.01))
    for name, value in est.coefficients.items():
        direction, key = name.split(".")
        assert value == pytest.approx(config[direction][key])


def test_fitted_dynamic_coefficients_carry_the_library_names():
    lugre = spec_for("lugre").coefficients(
        np.array([0.8, 0.05, 2.0, 500.0]), np.array([1.0, 0.1, 0.01, 0.001])
    )
    gms = spec_for("gms2").coefficients(
        np.array([0.8, 0.05, 2.0, 50.0, 1e-3, 2e-3]), np.array([0.4, 0.6, 0.01, 0.001])
    )
    for model, c in (("lugre", lugre), ("gms", gms)):
        library = {co.name for co in MODEL_CLASSES[model].COEFS}
        assert set(c) - {"J"} <= library
        cfg = library_config("gms2" if model == "gms" else model, c)
        m = model_from_config(cfg)
        for k in set(c) - {"J", "alpha"}:
            assert m[k] == pytest.approx(c[k])
