"""Model configs survive the flat FrictionEstimate fields and build the same library model."""

import pytest

from friction_ros.core.coefficient_exchange import from_fields, to_fields
from friction_ros.core.friction import model_from_config
from friction_ros.core.validation import ParameterError

CONFIGS = [
    {"model": "coulomb_viscous", "fc": 0.3, "fv": 0.01},
    {
        "model": "gms",
        "fc": 0.8,
        "fs": 0.95,
        "vs": 0.05,
        "delta": 2.0,
        "attraction": 50.0,
        "fv": 0.01,
        "k": [190.0, 190.0, 142.5, 95.0],
        "alpha": [0.1, 0.2, 0.3, 0.4],
    },
    {
        "model": "asymmetric",
        "base": "stribeck",
        "positive": {"fc": 0.2, "fs": 0.3, "vs": 0.05, "delta": 2.0, "fv": 0.01},
        "negative": {"fc": 0.25, "fs": 0.35, "vs": 0.05, "delta": 2.0, "fv": 0.02},
    },
]


@pytest.mark.parametrize("config", CONFIGS, ids=lambda c: c["model"])
def test_round_trip_is_exact_and_builds_the_same_model(config):
    model, names, values = to_fields(config)
    assert all(isinstance(v, float) for v in values)
    back = from_fields(model, names, values)
    assert back == config
    m1, m2 = model_from_config(config), model_from_config(back)
    assert m1.steady_state([-0.5, 0.01, 0.5]).tolist() == m2.steady_state([-0.5, 0.01, 0.5]).tolist()


def test_inconsistent_fields_are_rejected():
    with pytest.raises(ParameterError, match="2 coefficient names but 1 values"):
        from_fields("coulomb", ["fc", "fv"], [0.1])
    with pytest.raises(ParameterError, match="empty model name"):
        from_fields("", [], [])
