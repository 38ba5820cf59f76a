"""Aggregates over training seeds as rliable defines them (Agarwal et al., 2021).

* :func:`interquartile_mean`: rliable's ``aggregate_iqm``, ``scipy.stats.trim_mean(x, 0.25)``:
  sort, drop ``floor(n / 4)`` values at each end, average the rest (for ``n < 4`` nothing is
  dropped: the mean).
* :func:`bootstrap_interval`: rliable's ``get_interval_estimates`` on one task: resample the
  ``n`` seeds with replacement, compute the statistic on each resample, and take the
  percentile interval (numpy's linear-interpolation percentiles of the draws, as ``arch``'s
  ``conf_int(method="percentile")`` does). With one task rliable's stratified bootstrap is
  this plain one. Where the ``n^n`` equally likely resamples are few enough, the
  bootstrap distribution is enumerated exactly (as multisets with their multinomial
  counts) instead of sampled, and the interval is that distribution's own quantiles: what
  the sampled interval converges to as the draws grow, independent of a random seed.
  Those quantiles are the inverse of the distribution function, not an interpolation
  between the ``n^n`` resamples' sorted values: with 3 seeds each "all the same seed"
  resample has probability 1/27 > 2.5%, so the 95% interval of the mean runs from the
  smallest seed to the largest (rliable's 50,000 draws give the same); interpolating
  between the 27 sorted values as if they were a sample of 27 gave an interval too narrow
  (``[79.0, 87.4]`` instead of ``[77.4, 88.2]`` for the seeds ``77.4, 84.6, 88.2``). Where the
  distribution function equals the level exactly (a flat stretch of it, where the draws'
  percentile has no limit), the two values either side are averaged (numpy's
  ``method="averaged_inverted_cdf"``). Beyond the enumerable sizes it is sampled (``reps``
  draws from a fixed generator, rliable's default 50,000).
* :func:`stratified_bootstrap_interval`: rliable's ``StratifiedBootstrap`` across tasks:
  each task's runs (seeds) are resampled with replacement within the task, the statistic is
  computed on the pooled resample (rliable's IQM of the flattened runs x tasks matrix), and
  the percentile interval is taken as above; exact where the product over tasks of the
  per-task resamples is at most ``EXACT_LIMIT``. :func:`bootstrap_interval` is its one-task case.
* :func:`performance_profile`: rliable's run-score distribution, the fraction of runs whose
  score exceeds each threshold tau (``mean(scores > tau)``); each task weighs the same (the
  mean over tasks of the task's fraction), which is rliable's fraction of the matrix's runs
  when every task has the same number of runs.

rliable itself is not a dependency: it pins ``arch`` (and with it pandas and statsmodels)
for its percentile interval, and samples where these functions enumerate.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Callable, Sequence

import numpy as np

from torchrl_causal.errors import InvalidValueError

__all__ = ["bootstrap_interval", "interquartile_mean", "performance_profile", "stratified_bootstrap_interval"]

# Largest number of distinct resamples (multisets, C(2n - 1, n)) enumerated exactly:
# n <= 9 seeds (24,310 multisets); 10 seeds would be 92,378.
EXACT_LIMIT = 50_000


def interquartile_mean(values: Sequence[float]) -> float:
    """Mean of ``values`` after dropping ``floor(n / 4)`` from each end (rliable's IQM).

    Examples:
        >>> interquartile_mean([0.0, 0.5, 0.6, 1.0])  # drops 0.0 and 1.0
        0.55
        >>> interquartile_mean([0.2, 0.4, 0.9])  # n < 4: the mean
        0.5
    """
    if not len(values):
        raise InvalidValueError("interquartile_mean needs at least one value")
    ordered = sorted(values)
    cut = len(ordered) // 4
    kept = ordered[cut : len(ordered) - cut]
    return math.fsum(kept) / len(kept)


def _quantiles_of_counts(values: np.ndarray, counts: np.ndarray, quantiles: Sequence[float]) -> list[float]:
    """Quantiles of the distribution that gives each of ``values`` probability proportional
    to its count: the smallest value whose distribution function reaches ``q``, averaged
    with the next one where it equals ``q`` exactly (numpy's ``averaged_inverted_cdf`` of the
    list in which each value is repeated ``counts`` times)."""
    order = np.argsort(values, kind="stable")
    values, cumulative = values[order], np.cumsum(counts[order])
    total = int(cumulative[-1])
    out = []
    for q in quantiles:
        target = q * total  # compared in exact integer steps where q * total is whole
        i = int(np.searchsorted(cumulative, target, side="left"))
        i = min(i, len(values) - 1)
        if cumulative[i] == target and i + 1 < len(values):
            out.append(float(values[i] + values[i + 1]) / 2)
        else:
            out.append(float(values[i]))
    return out


def _multisets(n: int) -> list[tuple[tuple[int, ...], int]]:
    """Every resample of ``n`` values with replacement as a multiset of indices, with the
    number of ordered resamples that give it (``n! / prod(m_i!)``)."""
    out = []
    for chosen in itertools.combinations_with_replacement(range(n), n):
        multiplicities = np.bincount(chosen, minlength=n)
        out.append((chosen, math.factorial(n) // math.prod(math.factorial(int(m)) for m in multiplicities)))
    return out


def _exact_distribution(tasks: Sequence[Sequence[float]], statistic: Callable[[Sequence[float]], float]) -> tuple[np.ndarray, np.ndarray]:
    """The statistic of every stratified resample (one multiset per task) and its weight."""
    stats, counts = [], []
    for combination in itertools.product(*(_multisets(len(values)) for values in tasks)):
        pooled = [values[i] for values, (chosen, _) in zip(tasks, combination) for i in chosen]
        stats.append(statistic(pooled))
        counts.append(math.prod(count for _, count in combination))
    return np.asarray(stats, dtype=float), np.asarray(counts, dtype=np.int64)


def _distinct_resamples(sizes: Sequence[int]) -> int:
    return math.prod(math.comb(2 * n - 1, n) for n in sizes)


def stratified_bootstrap_interval(
    tasks: Sequence[Sequence[float]],
    statistic: Callable[[Sequence[float]], float] = interquartile_mean,
    confidence: float = 0.95,
    *,
    reps: int = 50_000,
    seed: int = 0,
    exact: bool | None = None,
) -> tuple[float, float]:
    """Percentile bootstrap interval of ``statistic`` over runs grouped by task, resampling
    the runs of each task within it (rliable's stratified bootstrap).

    Args:
        tasks: per task, one score per run (seed); tasks may hold different numbers of runs.
        statistic: computed on each resample's pooled runs (default: the IQM).
        confidence: the interval's coverage.
        reps: draws when the distribution is sampled.
        seed: the sampling generator's seed.
        exact: enumerate every resample (default: when there are at most ``EXACT_LIMIT``
            distinct ones: the product over tasks of ``C(2n - 1, n)``).

    Returns:
        ``(low, high)``; one run per task gives the statistic twice.

    Raises:
        ValueError: no task, an empty task, or ``confidence`` outside (0, 1).

    Examples:
        >>> # two tasks of two runs: the IQM of four pooled runs is the mean of the middle two
        >>> low, high = stratified_bootstrap_interval([[0.0, 1.0], [0.5, 0.5]])
        >>> round(low, 4), round(high, 4)
        (0.25, 0.75)
        >>> stratified_bootstrap_interval([[0.3], [0.9]])  # nothing to resample
        (0.6, 0.6)
    """
    tasks = [list(values) for values in tasks]
    if not tasks or any(not values for values in tasks):
        raise InvalidValueError(f"stratified_bootstrap_interval needs at least one run in every task, got sizes {[len(t) for t in tasks]}")
    if not 0 < confidence < 1:
        raise InvalidValueError(f"confidence must be in (0, 1), got {confidence}")
    tail = (1 - confidence) / 2
    if exact is None:
        exact = _distinct_resamples([len(values) for values in tasks]) <= EXACT_LIMIT
    if exact:
        stats, counts = _exact_distribution(tasks, statistic)
        low, high = _quantiles_of_counts(stats, counts, (tail, 1 - tail))
        return low, high
    generator = np.random.default_rng(seed)
    arrays = [np.asarray(values, dtype=float) for values in tasks]
    draws = [statistic([x for array in arrays for x in array[generator.integers(0, len(array), len(array))].tolist()]) for _ in range(reps)]
    low, high = np.percentile(draws, [100 * tail, 100 * (1 - tail)])
    return float(low), float(high)


def bootstrap_interval(
    values: Sequence[float],
    statistic: Callable[[Sequence[float]], float] = interquartile_mean,
    confidence: float = 0.95,
    *,
    reps: int = 50_000,
    seed: int = 0,
    exact: bool | None = None,
) -> tuple[float, float]:
    """Percentile bootstrap confidence interval of ``statistic`` over ``values`` (one per seed):
    :func:`stratified_bootstrap_interval` with one task.

    Args:
        values: one score per seed.
        statistic: what is computed on each resample (default: the IQM).
        confidence: the interval's coverage.
        reps: draws when the distribution is sampled.
        seed: the sampling generator's seed.
        exact: enumerate every resample (default: when there are at most ``EXACT_LIMIT``
            distinct ones, i.e. up to 9 seeds).

    Returns:
        ``(low, high)``; a single value gives ``(value, value)``.

    Examples:
        >>> bootstrap_interval([0.0, 1.0])  # resamples' IQM: 0 (1/4), 0.5 (1/2), 1 (1/4)
        (0.0, 1.0)
        >>> bootstrap_interval([77.4, 84.6, 88.2])  # each seed alone: 1/27 > 2.5%
        (77.4, 88.2)
        >>> low, high = bootstrap_interval([0.8, 0.9, 0.85, 0.4])
        >>> 0.4 <= low < interquartile_mean([0.8, 0.9, 0.85, 0.4]) < high <= 0.9
        True
    """
    if not len(values):
        raise InvalidValueError("bootstrap_interval needs at least one value")
    return stratified_bootstrap_interval([values], statistic, confidence, reps=reps, seed=seed, exact=exact)


def performance_profile(tasks: Sequence[Sequence[float]], thresholds: Sequence[float]) -> np.ndarray:
    """Fraction of runs whose score exceeds each threshold (rliable's run-score
    distribution), each task weighing the same.

    Args:
        tasks: per task, one score per run.
        thresholds: the taus.

    Returns:
        One fraction in [0, 1] per threshold, non-increasing in the threshold.

    Raises:
        ValueError: no task, or an empty task.

    Examples:
        >>> performance_profile([[0.2, 0.6, 1.0, 1.1]], [0.0, 0.5, 1.0]).tolist()
        [1.0, 0.75, 0.25]
        >>> performance_profile([[0.0], [1.0, 1.0, 1.0]], [0.5]).tolist()  # half the tasks
        [0.5]
    """
    if not tasks or any(not len(values) for values in tasks):
        raise InvalidValueError(f"performance_profile needs at least one run in every task, got sizes {[len(t) for t in tasks]}")
    taus = np.asarray(thresholds, dtype=float)
    per_task = [(np.asarray(values, dtype=float)[None, :] > taus[:, None]).mean(axis=1) for values in tasks]
    return np.mean(per_task, axis=0)
