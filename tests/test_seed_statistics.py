"""rliable's IQM and percentile-bootstrap interval against brute force and closed forms."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from torchrl_causal.evaluation.seed_statistics import (
    bootstrap_interval,
    interquartile_mean,
    performance_profile,
    stratified_bootstrap_interval,
)


def test_iqm_drops_a_quarter_at_each_end() -> None:
    # trim_mean(x, 0.25) drops floor(n / 4) values at each end: 2 of 8, 1 of 5, none of 3.
    assert interquartile_mean([7, 1, 3, 100, 5, -50, 2, 4]) == pytest.approx((2 + 3 + 4 + 5) / 4)
    assert interquartile_mean([10, 0, 3, 4, 5]) == pytest.approx(4.0)
    assert interquartile_mean([1, 2, 9]) == pytest.approx(4.0)
    with pytest.raises(ValueError, match="at least one"):
        interquartile_mean([])


def _brute_force(values, confidence=0.95):
    """Every one of the n^n ordered resamples, then numpy's percentiles (what rliable's
    bootstrap converges to)."""
    stats = [interquartile_mean([values[i] for i in idx]) for idx in itertools.product(range(len(values)), repeat=len(values))]
    tail = 100 * (1 - confidence) / 2
    return tuple(np.percentile(stats, [tail, 100 - tail]))


@pytest.mark.parametrize("n", [2, 3, 4, 5, 6])
def test_exact_bootstrap_equals_brute_force(n: int) -> None:
    values = np.random.default_rng(n).uniform(0, 100, n).round(1).tolist()
    assert bootstrap_interval(values) == pytest.approx(_brute_force(values), abs=1e-9)
    assert bootstrap_interval(values, confidence=0.5) == pytest.approx(_brute_force(values, 0.5), abs=1e-9)


def test_two_seeds_closed_form() -> None:
    # Resamples of (a, b): (a, a), (a, b), (b, a), (b, b); IQM of two values is their mean,
    # so the sorted statistics are [a, m, m, b]; the 2.5% percentile sits at 0.075 of the
    # way from a to m (position 0.025 * 3), the 97.5% one at 0.925 of the way from m to b.
    a, b = 60.0, 100.0
    m = (a + b) / 2
    low, high = bootstrap_interval([a, b])
    assert low == pytest.approx(a + 0.075 * (m - a)) and high == pytest.approx(m + 0.925 * (b - m))
    assert bootstrap_interval([42.0]) == (42.0, 42.0)


def test_sampled_bootstrap_approaches_the_exact_one() -> None:
    values = [55.0, 70.0, 72.0, 90.0, 91.0]
    exact = bootstrap_interval(values)
    sampled = bootstrap_interval(values, exact=False, reps=20_000, seed=1)
    assert sampled == pytest.approx(exact, abs=1.0)  # a range of 36 points
    assert bootstrap_interval(values, exact=False, reps=2_000, seed=3) == bootstrap_interval(values, exact=False, reps=2_000, seed=3)


def _brute_force_stratified(tasks, confidence=0.95):
    """Every ordered resample of every task (prod n_i^n_i of them), the IQM of the pooled runs,
    then numpy's percentiles."""
    per_task = [list(itertools.product(values, repeat=len(values))) for values in tasks]
    stats = [interquartile_mean([x for resample in combination for x in resample]) for combination in itertools.product(*per_task)]
    tail = 100 * (1 - confidence) / 2
    return tuple(np.percentile(stats, [tail, 100 - tail]))


@pytest.mark.parametrize("sizes", [(2, 3), (3, 3), (1, 4), (2, 2, 2)])
def test_stratified_bootstrap_equals_brute_force(sizes) -> None:
    rng = np.random.default_rng(sum(sizes))
    tasks = [rng.uniform(0, 1.2, n).round(2).tolist() for n in sizes]
    assert stratified_bootstrap_interval(tasks) == pytest.approx(_brute_force_stratified(tasks), abs=1e-9)
    assert stratified_bootstrap_interval(tasks, confidence=0.6) == pytest.approx(_brute_force_stratified(tasks, 0.6), abs=1e-9)


def test_stratified_bootstrap_of_one_task_is_the_plain_one_and_resamples_within_tasks() -> None:
    values = [0.2, 0.9, 0.5, 0.7]
    assert stratified_bootstrap_interval([values]) == bootstrap_interval(values)
    assert stratified_bootstrap_interval([values], exact=False, reps=500) == bootstrap_interval(values, exact=False, reps=500)
    # Constant tasks have nothing to resample: the interval collapses to the pooled IQM,
    # which a plain bootstrap over the pooled runs (mixing the tasks) would not.
    tasks = [[0.0, 0.0], [1.0, 1.0]]
    assert stratified_bootstrap_interval(tasks) == (0.5, 0.5)
    low, high = bootstrap_interval([0.0, 0.0, 1.0, 1.0])
    assert low < 0.5 < high
    with pytest.raises(ValueError, match="every task"):
        stratified_bootstrap_interval([[0.5], []])


def test_performance_profile_against_counting_and_its_invariants() -> None:
    rng = np.random.default_rng(7)
    tasks = [rng.uniform(0, 1.2, n).tolist() for n in (3, 5, 4)]
    taus = np.linspace(0, 1.3, 27)
    profile = performance_profile(tasks, taus)
    counted = [sum(sum(x > tau for x in values) / len(values) for values in tasks) / len(tasks) for tau in taus]
    assert profile.tolist() == pytest.approx(counted)
    assert np.all(np.diff(profile) <= 0)  # non-increasing in tau
    assert profile[0] == 1.0 and profile[-1] == 0.0  # every score in (0, 1.2]
    # equal runs per task: the fraction of all runs (rliable's mean over the score matrix)
    square = [values[:3] for values in tasks]
    flat = np.asarray(square).ravel()
    assert performance_profile(square, taus).tolist() == pytest.approx([(flat > tau).mean() for tau in taus])
    with pytest.raises(ValueError, match="every task"):
        performance_profile([], [0.5])
