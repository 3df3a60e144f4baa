"""GA friction thesis 2002 GA: section 9 item 6 (mechanics) and item 5 (self-recovery), identifiability."""

from __future__ import annotations

import math

import numpy as np
import pytest

from friction_ros.core.identification.fit import ga

# ------------------------------------------------------------------------------ item 6: mechanics
from friction_ros.core.synthetic import ga_thesis_loop


# ------------------------------------------------------------------------------ item 6: mechanics
def test_initialisation_uniform_in_ranges():
    rng = np.random.default_rng(0)
    lo, hi = np.full(3, 0.01), np.full(3, 1.5)
    P = ga.initial_population(lo, hi, 5000, rng)
    assert P.min() >= 0.01 and P.max() <= 1.5
    assert abs(P.mean() - 0.755) < 0.02  # uniform mean
    assert abs(P.std() - 1.49 / math.sqrt(12)) < 0.02


def test_no_clipping_after_initialisation():
    # a quadratic with its optimum at 4.37 (outside [0.01, 1.5]): the GA must get there (gamma case)
    target = np.array([4.3743, 0.2])
    res = ga.run_ga(
        lambda P: np.sum((P - target) ** 2, axis=1),
        np.full(2, 0.01),
        np.full(2, 1.5),
        max_generations=400,
        seed=2,
    )
    assert res.best[0] > 1.5
    assert abs(res.best[0] - 4.3743) < 0.05


def test_repair_abs_and_zero_discard():
    kids = np.array([[-0.5, 1.0], [0.0, 2.0], [0.3, -0.2]])
    fixed, valid = ga.repair(kids)
    assert np.all(fixed >= 0)
    assert fixed[0, 0] == 0.5 and fixed[2, 1] == 0.2
    assert list(valid) == [True, False, True]


def test_mutation_sigma_formula_and_unit_range():
    rng = np.random.default_rng(1)
    lo, hi = np.array([0.01, 2.0]), np.array([1.5, 2.0])  # second gene fixed: range := 1
    s = np.array([ga.mutation_sigma(lo, hi, rng) for _ in range(20000)])
    assert s[:, 0].max() <= 1.49 / math.sqrt(12) + 1e-12
    assert abs(s[:, 0].mean() - 0.5 * 1.49 / math.sqrt(12)) < 0.005  # U(0,1) multiplier
    assert abs(s[:, 1].max() - 1 / math.sqrt(12)) < 0.005


def test_young_parent_mutates_all_old_parent_exactly_one():
    rng = np.random.default_rng(3)
    lo, hi = np.full(6, 0.01), np.full(6, 1.5)
    p = np.full(6, 0.7)
    mask = np.ones(6, bool)
    for _ in range(200):
        young = ga.mutate(p, 3, lo, hi, mask, rng, age_threshold=4)
        assert np.count_nonzero(young != p) == 6
        old = ga.mutate(p, 4, lo, hi, mask, rng, age_threshold=4)
        assert np.count_nonzero(old != p) == 1


def test_mask_freezes_genes():
    rng = np.random.default_rng(4)
    lo, hi = np.full(4, 0.01), np.full(4, 1.5)
    mask = np.array([True, False, True, False])
    p = np.array([0.5, 0.6, 0.7, 0.8])
    for age in (0, 10):
        for _ in range(100):
            c = ga.mutate(p, age, lo, hi, mask, rng)
            assert c[1] == 0.6 and c[3] == 0.8
    w1, w2, _ = ga.crossover(p, p[::-1].copy(), rng, mask)
    assert w1[1] == 0.6 and w2[3] == p[::-1][3]
    init = ga.initial_population(lo, hi, 10, np.random.default_rng(9))
    res = ga.run_ga(
        lambda P: np.sum(P**2, axis=1), lo, hi, mask=mask, initial=init.copy(), max_generations=30
    )
    assert np.array_equal(res.parents[:, ~mask], init[:, ~mask])


def test_crossover_is_convex_combination():
    rng = np.random.default_rng(5)
    x1, x2 = np.array([0.1, 1.0, 3.0]), np.array([0.5, 0.2, 1.0])
    for _ in range(100):
        w1, w2, a = ga.crossover(x1, x2, rng)
        assert 0.0 <= a <= 1.0
        assert np.allclose(w1, a * x1 + (1 - a) * x2) and np.allclose(w2, (1 - a) * x1 + a * x2)
        assert np.all(w1 >= np.minimum(x1, x2) - 1e-15) and np.all(w1 <= np.maximum(x1, x2) + 1e-15)


def test_fit_never_increases_per_parent_and_termination():
    res = ga.run_ga(
        lambda P: np.sum((P - 0.3) ** 2, axis=1),
        np.full(3, 0.01),
        np.full(3, 1.5),
        max_generations=200,
        threshold=1e-6,
        seed=0,
    )
    H = np.array(res.parent_history)
    assert np.all(np.diff(H, axis=0) <= 0)  # elitist per-Parent replacement
    assert res.reason == "threshold" and res.best_fit <= 1e-6
    res = ga.run_ga(
        lambda P: np.ones(P.shape[0]),
        np.full(2, 0.01),
        np.full(2, 1.5),
        max_generations=1000,
        stagnation=25,
        seed=0,
    )
    assert res.reason == "stagnation" and res.generations == 25


# ------------------------------------------------------------------------------ item 5: self-recovery
@pytest.fixture(scope="module")
def ga_thesis_run():
    u = ga_thesis_loop.chirp_input(100.0)  # shortened from 300 s (test budget); h = 5 ms sub-steps
    theta = ga_thesis_loop.simulate(ga_thesis_loop.THESIS, u, substeps=2)
    res = ga_thesis_loop.fit(u, theta, substeps=2, max_generations=150, stagnation=10**6, seed=1)
    return u, theta, res


def test_ga_self_recovery_item5(ga_thesis_run):
    _u, _theta, res = ga_thesis_run
    P, T = res.best, ga_thesis_loop.THESIS
    assert abs(P[5] / T[5] - 1) < 0.05  # J_m within 5 %
    assert abs((P[4] + P[6]) / (T[4] + T[6]) - 1) < 0.20  # sigma + B_m within 20 %
    v = np.concatenate([np.geomspace(0.05, 3.0, 40), -np.geomspace(0.05, 3.0, 40)])
    rel = np.abs(ga_thesis_loop.friction_curve(P, v) / ga_thesis_loop.friction_curve(T, v) - 1)
    assert rel.max() < 0.10  # total curve F + B_m v within 10 % over 0.05..3 rad/s
    H = np.array(res.parent_history)
    assert np.all(np.diff(H, axis=0) <= 0)  # item 5 (a): monotone per Parent


def test_sigma_and_bm_flagged_collinear(ga_thesis_run):
    u, theta, _ = ga_thesis_run
    rep = ga_thesis_loop.identifiability_report(ga_thesis_loop.THESIS, u, theta)
    assert set(rep["not_identifiable"]) == {"sigma", "B_m"}
    nd = rep["collinear_groups"][0]["null_direction"]
    assert nd["sigma"] * nd["B_m"] < 0  # only the sum sigma + B_m is determined
    assert rep["ci95"]["sigma"] is None and rep["ci95"]["J_m"] is not None
