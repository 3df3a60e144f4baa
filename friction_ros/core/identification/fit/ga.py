"""The genetic algorithm of the GA friction thesis 2002 (sections 3.1-3.6), exactly as its notes specify it.

* Real-valued encoding ``P = {p_1..p_n}`` with a **mask** selecting the genes that may change.
* ``N_P`` Parents, each an independent search, ``N_C`` Children per Parent (experiment: 10 and 8).
* Initialisation uniform in per-gene ranges ``[lo, hi]`` (experiment: [0.01, 1.5]); the ranges are
  initialisation ranges, **not bounds** (no clipping afterwards).
* Children (sec. 4.1.5): ``c_i = p_i + N(0, s_i)`` with (eq. 27)
  ``s_i = (Param_max,i - Param_min,i) / sqrt(12) * Random(0..1)`` (drawn per gene per Child;
  range := 1 when min == max). A Parent younger than ``g`` (= 4) generations perturbs **every**
  masked gene; an older Parent perturbs **exactly one** randomly chosen masked gene.
* Feasibility repair: negative genes take their absolute value; a Child with a zero gene is
  discarded.
* Arithmetic crossover (eq. 16) "at random intervals": with probability ``crossover_rate`` per
  generation two random Parents produce ``w1 = a x1 + (1-a) x2`` and ``w2 = (1-a) x1 + a x2``,
  ``a ~ U(0, 1)``, which compete as extra Children of Parent 1 and Parent 2.
* Selection (sec. 3.5): the best Child whose Fit is smaller than its Parent's replaces it (age
  reset to 0); otherwise the Parent ages by one. Each Parent's Fit therefore never increases.
* Termination (sec. 3.6): any Parent's Fit <= ``threshold``, or no change of the best Fit for
  ``stagnation`` generations ("a few hundred"), or ``max_generations`` / ``time_limit``.

The cost is evaluated for all Children of a generation in one call (``cost_batch``), so the
simulation can be vectorised/compiled over the population.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from friction_ros.core.validation import ParameterError, check_int, check_real


def initial_population(lo: np.ndarray, hi: np.ndarray, n: int, rng: np.random.Generator) -> np.ndarray:
    """n Parents uniform in [lo, hi] per gene (GA friction thesis 2002 sec. 3.3)."""
    return lo + (hi - lo) * rng.random((n, lo.shape[0]))


def mutation_sigma(lo: np.ndarray, hi: np.ndarray, rng: np.random.Generator, shape=None) -> np.ndarray:
    """Eq. (27): s_i = range_i / sqrt(12) * U(0,1), range := 1 where min == max."""
    rng_ = np.where(hi > lo, hi - lo, 1.0)
    u = rng.random(shape if shape is not None else lo.shape)
    return rng_ / math.sqrt(12.0) * u


def mutate(
    parent: np.ndarray,
    age: int,
    lo: np.ndarray,
    hi: np.ndarray,
    mask: np.ndarray,
    rng: np.random.Generator,
    age_threshold: int = 4,
) -> np.ndarray:
    """One Child of ``parent`` (sec. 4.1.5.1 young / 4.1.5.2 old Parent). No repair here."""
    child = parent.copy()
    genes = np.nonzero(mask)[0]
    if genes.size == 0:
        return child
    if age < age_threshold:
        sel = genes
    else:
        sel = np.array([rng.choice(genes)])
    s = mutation_sigma(lo[sel], hi[sel], rng)
    child[sel] = parent[sel] + rng.normal(0.0, 1.0, sel.size) * s
    return child


def repair(children: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """abs() of negative genes; returns (children, valid) where a zero gene invalidates a Child."""
    c = np.abs(children)
    valid = np.all(c != 0.0, axis=1) & np.all(np.isfinite(c), axis=1)
    return c, valid


def crossover(
    x1: np.ndarray, x2: np.ndarray, rng: np.random.Generator, mask: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray, float]:
    """Arithmetic crossover (eq. 16); frozen (unmasked) genes keep each parent's value."""
    a = float(rng.random())
    w1 = a * x1 + (1.0 - a) * x2
    w2 = (1.0 - a) * x1 + a * x2
    if mask is not None:
        w1 = np.where(mask, w1, x1)
        w2 = np.where(mask, w2, x2)
    return w1, w2, a


@dataclass
class GAResult:
    best: np.ndarray
    best_fit: float
    parents: np.ndarray
    fits: np.ndarray
    generations: int
    evaluations: int
    reason: str
    history: list[float] = field(default_factory=list)
    parent_history: list[np.ndarray] = field(default_factory=list)
    seconds: float = 0.0


def run_ga(
    cost_batch: Callable[[np.ndarray], np.ndarray],
    lo,
    hi,
    *,
    n_parents: int = 10,
    n_children: int = 8,
    age_threshold: int = 4,
    mask=None,
    initial: np.ndarray | None = None,
    crossover_rate: float = 0.2,
    threshold: float = 0.0,
    stagnation: int = 300,
    max_generations: int = 1000,
    time_limit: float | None = None,
    seed: int | None = 0,
    callback: Callable[[int, float], None] | None = None,
) -> GAResult:
    """Minimise ``cost_batch(P) -> fits`` with GA friction thesis 2002's GA (see module docstring)."""
    lo = np.asarray(lo, dtype=float)
    hi = np.asarray(hi, dtype=float)
    if lo.shape != hi.shape or lo.ndim != 1:
        raise ParameterError("ga: lo and hi must be 1-D arrays of the same length")
    if np.any(hi < lo):
        raise ParameterError("ga: every initialisation range needs lo <= hi")
    n_parents = check_int("ga.n_parents", n_parents, 1)
    n_children = check_int("ga.n_children", n_children, 1)
    age_threshold = check_int("ga.age_threshold", age_threshold, 0)
    crossover_rate = check_real("ga.crossover_rate", crossover_rate, 0.0, 1.0)
    max_generations = check_int("ga.max_generations", max_generations, 1)
    mask = np.ones(lo.shape, bool) if mask is None else np.asarray(mask, bool)
    rng = np.random.default_rng(seed)
    t_start = time.perf_counter()
    parents = initial_population(lo, hi, n_parents, rng) if initial is None else np.array(initial, float)
    if parents.shape != (n_parents, lo.shape[0]):
        raise ParameterError(f"ga.initial must have shape ({n_parents}, {lo.shape[0]})")
    fits = np.asarray(cost_batch(parents), dtype=float)
    fits = np.where(np.isfinite(fits), fits, np.inf)
    ages = np.zeros(n_parents, dtype=int)
    evals = n_parents
    history = [float(fits.min())]
    parent_hist = [fits.copy()]
    last_change = 0
    reason = "max_generations"
    gen = 0
    for gen in range(1, max_generations + 1):
        kids = np.empty((n_parents * n_children, lo.shape[0]))
        owner = np.repeat(np.arange(n_parents), n_children)
        for p in range(n_parents):
            for c in range(n_children):
                kids[p * n_children + c] = mutate(parents[p], ages[p], lo, hi, mask, rng, age_threshold)
        if n_parents >= 2 and rng.random() < crossover_rate:
            i, j = rng.choice(n_parents, 2, replace=False)
            w1, w2, _ = crossover(parents[i], parents[j], rng, mask)
            kids = np.vstack([kids, w1, w2])
            owner = np.concatenate([owner, [i, j]])
        kids, valid = repair(kids)
        kfit = np.full(kids.shape[0], np.inf)
        if valid.any():
            kfit[valid] = np.asarray(cost_batch(kids[valid]), dtype=float)
            evals += int(valid.sum())
        kfit = np.where(np.isfinite(kfit), kfit, np.inf)
        for p in range(n_parents):
            idx = np.nonzero(owner == p)[0]
            if idx.size:
                b = idx[np.argmin(kfit[idx])]
                if kfit[b] < fits[p]:
                    parents[p] = kids[b]
                    fits[p] = kfit[b]
                    ages[p] = 0
                    continue
            ages[p] += 1
        best = float(fits.min())
        if best < history[-1]:
            last_change = gen
        history.append(best)
        parent_hist.append(fits.copy())
        if callback is not None:
            callback(gen, best)
        if best <= threshold:
            reason = "threshold"
            break
        if gen - last_change >= stagnation:
            reason = "stagnation"
            break
        if time_limit is not None and time.perf_counter() - t_start > time_limit:
            reason = "time_limit"
            break
    b = int(np.argmin(fits))
    return GAResult(
        parents[b].copy(),
        float(fits[b]),
        parents,
        fits,
        gen,
        evals,
        reason,
        history,
        parent_hist,
        time.perf_counter() - t_start,
    )
