"""rliable's IQM and percentile-bootstrap interval against brute force and closed forms."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from torchrl_causal.evaluation.seed_statistics import bootstrap_interval, interquartile_mean


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
