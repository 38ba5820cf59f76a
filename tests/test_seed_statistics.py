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
    """Every one of the n^n equally likely ordered resamples, then the quantiles of that
    distribution (numpy's inverted distribution function, averaged where it is flat at the
    level): what rliable's sampled percentiles converge to as the draws grow."""
    stats = [interquartile_mean([values[i] for i in idx]) for idx in itertools.product(range(len(values)), repeat=len(values))]
    tail = 100 * (1 - confidence) / 2
    return tuple(np.percentile(stats, [tail, 100 - tail], method="averaged_inverted_cdf"))


@pytest.mark.parametrize("n", [2, 3, 4, 5, 6])
def test_exact_bootstrap_equals_brute_force(n: int) -> None:
    values = np.random.default_rng(n).uniform(0, 100, n).round(1).tolist()
    assert bootstrap_interval(values) == pytest.approx(_brute_force(values), abs=1e-9)
    assert bootstrap_interval(values, confidence=0.5) == pytest.approx(_brute_force(values, 0.5), abs=1e-9)


def test_few_seeds_span_their_range() -> None:
    # With n seeds, "every draw the same seed" has probability n^-n: 1/4 for 2 seeds, 1/27
    # for 3, both above 2.5%, so the 95% interval of the mean runs from the smallest seed to
    # the largest (issue 58: [79.0, 87.4] was reported for these three).
    assert bootstrap_interval([60.0, 100.0]) == (60.0, 100.0)
    assert bootstrap_interval([77.4, 84.6, 88.2]) == pytest.approx((77.4, 88.2))
    # the mean of 4 seeds: 4^-4 = 0.39% < 2.5%, so the interval is strictly inside the range
    # (not so their IQM: 3 draws of the smallest of 4 already make it, 13/256 > 2.5%)
    low, high = bootstrap_interval([10.0, 20.0, 30.0, 40.0], statistic=lambda v: sum(v) / len(v))
    assert 10.0 < low < high < 40.0
    assert bootstrap_interval([10.0, 20.0, 30.0, 40.0])[0] == 10.0
    # at 50%, the two-seed distribution [a (1/4), m (1/2), b (1/4)] is flat at both levels:
    # the limit of the sampled percentiles is not defined there, the average is taken
    assert bootstrap_interval([0.0, 1.0], confidence=0.5) == (0.25, 0.75)
    assert bootstrap_interval([42.0]) == (42.0, 42.0)


@pytest.mark.parametrize("values", [[55.0, 70.0, 72.0, 90.0, 91.0], [77.4, 84.6, 88.2], [60.0, 100.0]])
def test_sampled_bootstrap_approaches_the_exact_one(values) -> None:
    exact = bootstrap_interval(values)
    sampled = bootstrap_interval(values, exact=False, reps=8_000, seed=1)
    assert sampled == pytest.approx(exact, abs=0.03 * (max(values) - min(values)))
    assert bootstrap_interval(values, exact=False, reps=2_000, seed=3) == bootstrap_interval(values, exact=False, reps=2_000, seed=3)


def _brute_force_stratified(tasks, confidence=0.95):
    """Every ordered resample of every task (prod n_i^n_i of them), the IQM of the pooled runs,
    then the quantiles of that distribution (numpy's inverse of the distribution function,
    averaged where it is flat at the level: the limit of the sampled percentiles)."""
    per_task = [list(itertools.product(values, repeat=len(values))) for values in tasks]
    stats = [interquartile_mean([x for resample in combination for x in resample]) for combination in itertools.product(*per_task)]
    tail = 100 * (1 - confidence) / 2
    return tuple(np.percentile(stats, [tail, 100 - tail], method="averaged_inverted_cdf"))


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
