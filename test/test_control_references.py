"""Reference generators: GA friction thesis 2002 parabola/chirp/random steps, ABB M19-S paper band-limited random, others."""

import math

import numpy as np
import pytest

from friction_ros.core.experiment.references import (
    GA_THESIS_PARABOLA_TABLE,
    REFERENCE_TYPES,
    reference_from_config,
)
from friction_ros.core.validation import ParameterError


def test_parabola_reproduces_table_c1_and_is_c1():
    r = reference_from_config({"type": "parabola"})
    expected_end = np.cumsum([2 * dA for _, dA, _ in GA_THESIS_PARABOLA_TABLE])
    for (_, _, end), a in zip(GA_THESIS_PARABOLA_TABLE, expected_end):
        assert r.sample(end)[0] == pytest.approx(a, abs=1e-9)
    t = np.arange(0.0, 141.0, 1e-3)
    p, v, _ = r.arrays(t)
    assert np.max(np.abs(np.diff(v))) < 0.01  # no slope jumps
    assert np.max(p) == pytest.approx(19.2)
    assert np.max(np.abs(v)) == pytest.approx(2.0 / 0.7, rel=1e-3)


def test_chirp_first_peak_ga_thesis():
    r = reference_from_config({"type": "chirp"})
    t = np.arange(0.0, 10.0, 1e-3)
    p, v, a = r.arrays(t)
    k = int(np.argmax(p[:7000]))
    assert p[0] == 0.0
    assert 4.8 <= t[k] <= 5.0 and p[k] == pytest.approx(3.09, abs=0.01)
    assert np.max(np.abs(np.gradient(p, t) - v)) < 1e-3
    assert np.max(np.abs(np.gradient(v, t) - a)[5:-5]) < 1e-2


def test_random_steps_hold_two_seconds():
    r = reference_from_config({"type": "random_steps", "seed": 3})
    t = np.arange(0.0, 20.0, 0.01)
    p, v, _ = r.arrays(t)
    assert np.all(v == 0.0) and np.all(np.abs(p) <= 1.0)
    for k in range(10):
        seg = p[(t >= 2 * k) & (t < 2 * k + 2 - 1e-9)]
        assert np.ptp(seg) == 0.0
    assert len(np.unique(p)) == 10


def test_band_limited_random_abb_m19s():
    r = reference_from_config(
        {"type": "band_limited_random", "amplitude": 0.005, "duration": 20.0, "seed": 1}
    )
    t = np.arange(0.0, 20.0, 1e-3)
    p, v, _ = r.arrays(t)
    assert np.max(np.abs(p)) == pytest.approx(0.005)
    assert abs(p[0]) < 1e-8
    spec = np.abs(np.fft.rfft(p)) ** 2
    f = np.fft.rfftfreq(p.size, 1e-3)
    assert spec[f > 5.0].sum() < 1e-4 * spec.sum()  # 4th-order 1 Hz low-pass
    # deterministic
    r2 = reference_from_config(r.config())
    assert np.array_equal(r2.arrays(t)[0], p)


def test_step_ramp_sinusoid_reversals():
    s = reference_from_config({"type": "step", "amplitude": 0.4, "start_time": 0.1})
    assert s.sample(0.05) == (0.0, 0.0, 0.0) and s.sample(0.2)[0] == 0.4
    b = reference_from_config({"type": "step", "amplitude": 0.4, "rise_time": 0.2})
    assert b.sample(0.2)[0] == pytest.approx(0.4) and b.sample(0.1)[1] == pytest.approx(4.0)
    ramp = reference_from_config({"type": "ramp", "slope": 0.5, "ramp_time": 2.0})
    assert ramp.sample(1.0)[:2] == (0.5, 0.5) and ramp.sample(3.0)[:2] == (1.0, 0.0)
    sin = reference_from_config({"type": "sinusoid", "amplitude": 0.1, "frequency": 1.0})
    assert sin.sample(0.0)[1] == pytest.approx(0.2 * math.pi)
    rev = reference_from_config(
        {"type": "velocity_reversals", "velocity": 0.1, "half_period": 1.0, "acceleration": 1.0}
    )
    t = np.arange(0.0, 10.0, 1e-3)
    p, v, _ = rev.arrays(t)
    assert np.max(v) == pytest.approx(0.1) and np.min(v) == pytest.approx(-0.1)
    assert np.max(np.abs(np.gradient(p, t) - v)) < 1e-3
    assert np.sum(np.diff(np.sign(v[np.abs(v) > 0.05])) != 0) >= 8


@pytest.mark.parametrize(
    "cfg, words",
    [
        ({"type": "stair"}, ["reference.type", "sinusoid"]),
        ({"type": "sinusoid", "frequency": 0.0}, ["frequency", "> 0"]),
        ({"type": "sinusoid", "amplitud": 1.0}, ["unknown", "amplitud"]),
        ({"type": "band_limited_random", "cutoff": 600.0}, ["cutoff"]),
        ({"type": "velocity_reversals", "half_period": 0.1}, ["half_period"]),
    ],
)
def test_validation(cfg, words):
    with pytest.raises(ParameterError) as ei:
        reference_from_config(cfg)
    for w in words:
        assert w in str(ei.value)


def test_every_type_round_trips():
    for kind in REFERENCE_TYPES:
        r = reference_from_config({"type": kind})
        r2 = reference_from_config(r.config())
        assert r2.sample(1.234) == pytest.approx(r.sample(1.234))
