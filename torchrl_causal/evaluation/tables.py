"""The paper's tables from evaluation results: Table 1, the raw table, episode lengths.

Table 1 (Section 4) lists, per task, the expert and the eight algorithms in the order
Expert, C-BC, C-GAIL, C-SQIL, C-IQ-Learn, BC, GAIL, SQIL, IQ-Learn, with the normalised
``E[Y]`` (the return shifted so that the worst algorithm of the row sits at 0, since the
reward is purely negative; the spread is unchanged) and the success rate, each with its
spread (standard deviation of the return, standard error of the success rate).
Appendix F adds the unnormalised table and the mean length of successful episodes.
"""

from __future__ import annotations

import csv
import math
from collections import defaultdict
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

from torchrl_causal.algorithms import TABLE1_FAMILIES, TABLE1_ROWS, Row, algorithm
from torchrl_causal.envs.base import REGIMES
from torchrl_causal.errors import InvalidValueError
from torchrl_causal.evaluation.metrics import SUMMARY_COLUMNS, EvaluationResult, metrics_summary
from torchrl_causal.evaluation.runs import RunRecord, Setting
from torchrl_causal.evaluation.seed_statistics import bootstrap_interval, interquartile_mean, stratified_bootstrap_interval

__all__ = [
    "TABLE1_ALGORITHMS",
    "ReportedResult",
    "read_reported_rows",
    "CSV_COLUMNS",
    "REGIMES",
    "display_name",
    "ordered_labels",
    "aggregate",
    "normalised_returns",
    "csv_rows",
    "write_csv",
    "table1_markdown",
    "raw_markdown",
    "lengths_markdown",
    "seed_spread",
    "iqm_with_interval",
    "seeds_markdown",
    "EffectCheck",
    "EffectTargets",
    "effect_checks",
    "seed_effect_checks",
    "effect_markdown",
    "NormalisedScores",
    "normalised_scores",
    "aggregate_markdown",
]

#: Table 1's row labels in its order (:data:`torchrl_causal.algorithms.TABLE1_ROWS`).
TABLE1_ALGORITHMS: tuple[str, ...] = tuple(row.name for row in TABLE1_ROWS)
#: The rows the paper's causal claim is checked on: Table 1's causal off-policy algorithms.
_CAUSAL_OFF_POLICY: tuple[str, ...] = tuple(Row(name, causal=True).name for name in TABLE1_FAMILIES if algorithm(name).off_policy)
CSV_COLUMNS: tuple[str, ...] = ("algorithm", *SUMMARY_COLUMNS)


@dataclass(frozen=True)
class ReportedResult:
    """One row of an earlier report's CSV: the metrics of an evaluation without its
    episodes, for a table row whose run records are gone (see
    :func:`~torchrl_causal.evaluation.write_report`'s ``carried``). It has
    :class:`EvaluationResult`'s metrics and :meth:`~EvaluationResult.summary`, so every
    table prints it as it printed the pooled result; it cannot be pooled with other
    seeds, since the episodes are not there.

    Examples:
        >>> r = EvaluationResult("deploy", [True, False], [-1.0, -9.0], [4, 9], seeds=[0])
        >>> ReportedResult.from_row(r.summary()).summary() == r.summary()
        True
    """

    regime: str
    success_rate: float
    success_se: float
    return_mean: float
    return_std: float
    ep_len_mean: float
    ep_len_std: float
    n_episodes: int
    seed_count: int

    @classmethod
    def from_row(cls, row: Mapping[str, float | str]) -> ReportedResult:
        """From a results-CSV row (:data:`CSV_COLUMNS`; an empty cell is NaN)."""

        def number(key: str) -> float:
            value = row[key]
            return math.nan if value == "" else float(value)

        return cls(
            regime=str(row["regime"]),
            success_rate=number("success_rate"),
            success_se=number("success_se"),
            return_mean=number("return_mean"),
            return_std=number("return_std"),
            ep_len_mean=number("ep_len_mean"),
            ep_len_std=number("ep_len_std"),
            n_episodes=int(row["n_episodes"]),
            seed_count=int(row["seeds"]),
        )

    def summary(self) -> dict[str, float | int | str]:
        """The metrics as :meth:`EvaluationResult.summary` lists them (:func:`metrics_summary`)."""
        return metrics_summary(self)


# label -> regime -> result pooled over seeds (or an earlier report's row)
Table = Mapping[str, Mapping[str, EvaluationResult | ReportedResult]]


def read_reported_rows(path: str | Path) -> dict[Setting, dict[str, dict[str, ReportedResult]]]:
    """The rows of a report's ``<name>_all.csv`` (setting columns, then
    :data:`CSV_COLUMNS`), grouped as :func:`aggregate` groups runs.

    Raises:
        FileNotFoundError: ``path`` does not exist.
        ValueError: a column is missing.
    """
    with open(path, newline="") as handle:
        reader = csv.DictReader(handle)
        missing = {"env", "horizon", "strength", "k", *CSV_COLUMNS} - set(reader.fieldnames or ())
        if missing:
            raise InvalidValueError(f"{path} is not a report's _all.csv: it lacks the column(s) {sorted(missing)}")
        table: dict[Setting, dict[str, dict[str, ReportedResult]]] = defaultdict(lambda: defaultdict(dict))
        for row in reader:
            setting = Setting(row["env"], int(row["horizon"]), float(row["strength"]), int(row["k"]))
            table[setting][row["algorithm"]][row["regime"]] = ReportedResult.from_row(row)
    return {setting: dict(labels) for setting, labels in table.items()}


def display_name(label: str) -> str:
    """Column header of a run label (:attr:`torchrl_causal.algorithms.Row.label`; a label
    no registered algorithm makes is its own header).

    Examples:
        >>> display_name("c_iq_learn"), display_name("sqil_wm"), display_name("c_bc_no-X")
        ('C-IQ-Learn', 'SQIL (window-matched)', 'C-BC (no X)')
    """
    row = Row.parse(label)
    return label if row is None else row.label


def ordered_labels(labels: Iterable[str]) -> list[str]:
    """Table 1's order first, any other label (window-matched baselines) after, sorted."""
    labels = set(labels)
    return [a for a in TABLE1_ALGORITHMS if a in labels] + sorted(labels - set(TABLE1_ALGORITHMS))


def aggregate(runs: Iterable[RunRecord]) -> dict[Setting, dict[str, dict[str, EvaluationResult]]]:
    """Groups runs by setting and label and pools each regime's episodes over seeds."""
    grouped: dict[Setting, dict[str, dict[str, list[EvaluationResult]]]] = defaultdict(lambda: defaultdict(lambda: defaultdict(list)))
    for run in runs:
        for regime, result in run.evaluations.items():
            grouped[run.setting][run.label][regime].append(result)
    return {
        setting: {
            label: {regime: EvaluationResult.pool(results) for regime, results in regimes.items()} for label, regimes in labels.items()
        }
        for setting, labels in grouped.items()
    }


def normalised_returns(table: Table, regime: str = "deploy") -> dict[str, float]:
    """Mean returns shifted so that the worst algorithm of ``regime`` sits at 0; NaN
    (printed "—") when ``regime`` has a single algorithm, which has no worst to sit above.

    Examples:
        >>> r = lambda ret: {"deploy": EvaluationResult("deploy", [False], [ret], [1])}
        >>> normalised_returns({"expert": r(-104.0), "bc": r(-375.3), "c_sqil": r(-99.6)})
        {'expert': 271.3, 'bc': 0.0, 'c_sqil': 275.7}
        >>> normalised_returns({"c_sqil": r(-99.6)})
        {'c_sqil': nan}
    """
    means = {label: regimes[regime].return_mean for label, regimes in table.items() if regime in regimes}
    if len(means) < 2:
        return {label: math.nan for label in means}
    worst = min(means.values())
    return {label: round(mean - worst, 10) for label, mean in means.items()}


def csv_rows(table: Table) -> list[dict[str, object]]:
    """One row per algorithm and regime, with :data:`CSV_COLUMNS`."""
    rows: list[dict[str, object]] = []
    for label in ordered_labels(table):
        for regime in REGIMES:
            if regime in table[label]:
                rows.append({"algorithm": label, **table[label][regime].summary()})
    return rows


def write_csv(rows: Sequence[Mapping[str, object]], path: str | Path, columns: Sequence[str] = CSV_COLUMNS) -> None:
    with open(path, "w", newline="") as handle:
        writer = csv.DictWriter(handle, fieldnames=list(columns), extrasaction="ignore")
        writer.writeheader()
        for row in rows:
            writer.writerow({k: ("" if isinstance(v, float) and math.isnan(v) else v) for k, v in row.items()})


def _pm(value: float, spread: float, digits: int = 1, bold: bool = False) -> str:
    if math.isnan(value):
        return "—"
    text = f"{value:.{digits}f}"
    text = f"**{text}**" if bold else text
    return f"{text} ± {spread:.{digits}f}" if not math.isnan(spread) else text


def _best_non_expert(values: Mapping[str, float]) -> str | None:
    candidates = {label: v for label, v in values.items() if label != "expert" and not math.isnan(v)}
    return max(candidates, key=candidates.__getitem__) if candidates else None


def _markdown(header: Sequence[str], rows: Iterable[Sequence[str]]) -> str:
    lines = ["| " + " | ".join(header) + " |", "|" + "|".join("---" for _ in header) + "|"]
    lines += ["| " + " | ".join(row) + " |" for row in rows]
    return "\n".join(lines)


def table1_markdown(table: Table, regime: str = "deploy") -> str:
    """Table 1's layout: one column per algorithm, normalised E[Y] and success rate rows.

    The best non-expert entry of each row is bold, as in the paper.
    """
    labels = [label for label in ordered_labels(table) if regime in table[label]]
    results = {label: table[label][regime] for label in labels}
    normalised = normalised_returns(table, regime)
    success = {label: 100 * r.success_rate for label, r in results.items()}
    # ties go to the first in Table 1's order, whatever order the table was built in
    best_return = _best_non_expert({label: normalised[label] for label in labels})
    best_success = _best_non_expert(success)
    header = [""] + [display_name(label) for label in labels]
    rows = [
        ["Norm. E[Y]"] + [_pm(normalised[label], results[label].return_std, bold=label == best_return) for label in labels],
        ["Success rate (%)"] + [_pm(success[label], 100 * results[label].success_se, bold=label == best_success) for label in labels],
    ]
    return _markdown(header, rows)


def raw_markdown(table: Table) -> str:
    """Appendix F's unnormalised table, both regimes side by side."""
    header = ["Algorithm"]
    for regime in REGIMES:
        header += [f"E[Y] ({regime})", f"SR % ({regime})"]
    header += ["episodes (train / deploy)", "seeds"]
    rows = []
    for label in ordered_labels(table):
        row = [display_name(label)]
        for regime in REGIMES:
            result = table[label].get(regime)
            row += (
                [_pm(result.return_mean, result.return_std), _pm(100 * result.success_rate, 100 * result.success_se)]
                if result is not None
                else ["—", "—"]
            )
        counts = [str(table[label][regime].n_episodes) if regime in table[label] else "—" for regime in REGIMES]
        seeds = max(int(result.summary()["seeds"]) for result in table[label].values())
        row += [" / ".join(counts), str(seeds)]
        rows.append(row)
    return _markdown(header, rows)


def lengths_markdown(table: Table) -> str:
    """Appendix F's mean length (± std) of successful episodes; ``—`` when none succeeded."""
    header = ["Algorithm"] + [f"length ({regime})" for regime in REGIMES]
    rows = []
    for label in ordered_labels(table):
        row = [display_name(label)]
        for regime in REGIMES:
            result = table[label].get(regime)
            row.append(_pm(result.ep_len_mean, result.ep_len_std, digits=0) if result is not None else "—")
        rows.append(row)
    return _markdown(header, rows)


def seed_spread(values: Sequence[float]) -> tuple[float, float]:
    """Mean and standard error over seeds: ``std(ddof=1) / sqrt(n)``, ``nan`` for one seed.

    Examples:
        >>> seed_spread([0.9, 1.0, 0.8])
        (0.9, 0.05773502691896256)
        >>> seed_spread([0.5])
        (0.5, nan)
    """
    n = len(values)
    if not n:
        raise InvalidValueError("seed_spread needs at least one value")
    mean = math.fsum(values) / n
    if n == 1:
        return mean, math.nan
    variance = math.fsum((v - mean) ** 2 for v in values) / (n - 1)
    return mean, math.sqrt(variance / n)


def _results_by_seed(runs: Iterable[RunRecord]) -> dict[str, dict[str, dict[int, EvaluationResult]]]:
    """label -> regime -> {seed: evaluation}, seeds in ascending order."""
    results: dict[str, dict[str, dict[int, EvaluationResult]]] = defaultdict(lambda: defaultdict(dict))
    for run in sorted(runs, key=lambda r: r.seed):
        for regime, result in run.evaluations.items():
            results[run.label][regime][run.seed] = result
    return results


def _success_by_seed(runs: Iterable[RunRecord]) -> dict[str, dict[str, dict[int, float]]]:
    """label -> regime -> {seed: success rate}, seeds in ascending order."""
    return {
        label: {regime: {seed: result.success_rate for seed, result in by_seed.items()} for regime, by_seed in regimes.items()}
        for label, regimes in _results_by_seed(runs).items()
    }


def iqm_with_interval(values: Sequence[float], digits: int = 1) -> str:
    """``IQM [low, high]``: the interquartile mean over seeds and its 95% percentile-bootstrap
    interval (rliable's estimators, :mod:`~torchrl_causal.evaluation.seed_statistics`); one
    seed gives its value alone.

    Examples:
        >>> iqm_with_interval([80.0, 90.0, 100.0])
        '90.0 [80.0, 100.0]'
        >>> iqm_with_interval([95.0])
        '95.0'
    """
    iqm = interquartile_mean(values)
    if len(values) < 2:
        return f"{iqm:.{digits}f}"
    low, high = bootstrap_interval(values)
    return f"{iqm:.{digits}f} [{low:.{digits}f}, {high:.{digits}f}]"


def seeds_markdown(runs: Iterable[RunRecord]) -> str:
    """Success rate of every seed (``seed: %``, so that a row missing a seed says which),
    the rate pooled over their episodes, the mean ± standard error over seeds and the
    interquartile mean with its 95% bootstrap interval over seeds, both regimes.

    The other tables pool the episodes of all seeds (their ± is the episode-level standard
    error, which is what the paper's Table 1 reports: 87.6 ± 1.0 is the binomial error of
    1000 episodes); this one shows how much the training seed matters: a gap between two
    rows that their seed intervals span may be seed noise.
    """
    results = _results_by_seed(runs)
    header = ["Algorithm"]
    for regime in REGIMES:
        header += [
            f"SR % per seed ({regime})",
            f"pooled SR % ({regime})",
            f"mean ± SE over seeds ({regime})",
            f"IQM [95% bootstrap CI] over seeds ({regime})",
        ]
    rows = []
    for label in ordered_labels(results):
        row = [display_name(label)]
        for regime in REGIMES:
            by_seed = results[label].get(regime, {})
            if not by_seed:
                row += ["—"] * 4
                continue
            rates = [100 * result.success_rate for result in by_seed.values()]
            row.append(", ".join(f"{seed}: {rate:.1f}" for seed, rate in zip(by_seed, rates)))
            row.append(f"{100 * EvaluationResult.pool(list(by_seed.values())).success_rate:.1f}")
            row.append(_pm(*seed_spread(rates)))
            row.append(iqm_with_interval(rates))
        rows.append(row)
    return _markdown(header, rows)


@dataclass(frozen=True)
class EffectCheck:
    """One of the paper's qualitative claims, measured on a table."""

    claim: str
    measured: str
    passed: bool
    #: How far the measured value lies on the passing side of the threshold, in points
    #: (negative: the claim fails); NaN where a check does not compute one.
    margin: float = float("nan")


@dataclass(frozen=True)
class EffectTargets:
    """The thresholds :func:`effect_checks` holds a table to.

    Args:
        causal_fraction: the least deploy success each causal off-policy method keeps, as a
            fraction of the expert's (the paper's Table 1: 0.96-1.04 on AntMaze).
        non_causal_fraction: the most deploy success a non-causal method keeps, as a fraction
            of the expert's (the paper: 0 for all four).
        train_gap_points: how many points of train-regime success a non-causal method may
            lie from its causal twin.

    Examples:
        >>> EffectTargets(causal_fraction=0.9, non_causal_fraction=0.1)
        EffectTargets(causal_fraction=0.9, non_causal_fraction=0.1, train_gap_points=10.0)
        >>> EffectTargets(causal_fraction=-1)
        Traceback (most recent call last):
        ...
        torchrl_causal.errors.InvalidValueError: EffectTargets' thresholds must be finite and >= 0, got causal_fraction=-1
        >>> EffectTargets(causal_fraction=2)  # no method keeps twice the expert's success
        Traceback (most recent call last):
        ...
        torchrl_causal.errors.InvalidValueError: EffectTargets' causal_fraction is a fraction of the expert's success, in [0, 1], got 2
    """

    causal_fraction: float = 0.8
    non_causal_fraction: float = 0.2
    train_gap_points: float = 10.0

    def __post_init__(self) -> None:
        for name in ("causal_fraction", "non_causal_fraction", "train_gap_points"):
            value = getattr(self, name)
            if isinstance(value, bool) or not (isinstance(value, (int, float)) and math.isfinite(value) and value >= 0):
                raise InvalidValueError(f"EffectTargets' thresholds must be finite and >= 0, got {name}={value!r}")
        for name in ("causal_fraction", "non_causal_fraction"):
            if getattr(self, name) > 1:
                raise InvalidValueError(
                    f"EffectTargets' {name} is a fraction of the expert's success, in [0, 1], got {getattr(self, name)!r}"
                )


def effect_checks(table: Table, targets: EffectTargets = EffectTargets()) -> list[EffectCheck]:
    """The paper's effect as checks: causal off-policy methods keep ``targets.causal_fraction``
    of the expert's deploy success, non-causal methods keep at most
    ``targets.non_causal_fraction`` of it, and in the train regime each non-causal method is
    within ``targets.train_gap_points`` of its causal counterpart. Checks whose runs are
    missing are skipped.
    """
    causal_fraction, non_causal_fraction = targets.causal_fraction, targets.non_causal_fraction
    train_gap_points = targets.train_gap_points
    checks: list[EffectCheck] = []

    def rate(label: str, regime: str) -> float | None:
        result = table.get(label, {}).get(regime)
        return None if result is None else result.success_rate

    expert = rate("expert", "deploy")
    if expert is not None:
        for label in _CAUSAL_OFF_POLICY:
            value = rate(label, "deploy")
            if value is not None:
                checks.append(
                    EffectCheck(
                        f"{display_name(label)} deploy success >= {causal_fraction:.0%} of the expert's",
                        f"{100 * value:.1f}% vs {100 * expert:.1f}% ({value / expert:.0%})" if expert else f"{100 * value:.1f}%",
                        value >= causal_fraction * expert,
                        100 * (value - causal_fraction * expert),
                    )
                )
        for label in TABLE1_FAMILIES:
            value = rate(label, "deploy")
            if value is not None:
                checks.append(
                    EffectCheck(
                        f"{display_name(label)} deploy success <= {non_causal_fraction:.0%} of the expert's",
                        f"{100 * value:.1f}% vs {100 * expert:.1f}%",
                        value <= non_causal_fraction * expert,
                        100 * (non_causal_fraction * expert - value),
                    )
                )
    for label in TABLE1_FAMILIES:
        causal_label = Row(label, causal=True).name
        plain, causal = rate(label, "train"), rate(causal_label, "train")
        if plain is not None and causal is not None:
            gap = 100 * (plain - causal)
            checks.append(
                EffectCheck(
                    f"{display_name(label)} within {train_gap_points:g} points of {display_name(causal_label)} (train regime)",
                    f"{100 * plain:.1f}% vs {100 * causal:.1f}% ({gap:+.1f} points)",
                    abs(gap) <= train_gap_points,
                    train_gap_points - abs(gap),
                )
            )
    return checks


def seed_effect_checks(runs: Iterable[RunRecord], targets: EffectTargets = EffectTargets()) -> list[EffectCheck]:
    """:func:`effect_checks`' causal claim seed by seed: each causal off-policy method keeps
    ``targets.causal_fraction`` of the expert's deploy success in every training seed (the
    expert pooled over its runs, since it does not train). Skipped without an expert run."""
    causal_fraction = targets.causal_fraction
    runs = list(runs)
    expert = [run.evaluations["deploy"] for run in runs if run.label == "expert" and "deploy" in run.evaluations]
    if not expert:
        return []
    expert_rate = EvaluationResult.pool(expert).success_rate
    rates = _success_by_seed(runs)
    checks = []
    for label in _CAUSAL_OFF_POLICY:
        by_seed = rates.get(label, {}).get("deploy", {})
        if not by_seed or not expert_rate:
            continue
        fractions = {seed: rate / expert_rate for seed, rate in by_seed.items()}
        checks.append(
            EffectCheck(
                f"{display_name(label)} deploy success >= {causal_fraction:.0%} of the expert's in every seed",
                ", ".join(f"seed {seed}: {fraction:.0%}" for seed, fraction in fractions.items()),
                all(fraction >= causal_fraction for fraction in fractions.values()),
            )
        )
    return checks


def effect_markdown(checks: Sequence[EffectCheck]) -> str:
    return _markdown(["Claim", "Measured", "Holds"], [[c.claim, c.measured, "yes" if c.passed else "**no**"] for c in checks])


@dataclass(frozen=True)
class NormalisedScores:
    """Each run's success rate divided by the expert's in its task and regime: the score
    rliable-style aggregates (IQM, performance profile) take across tasks.

    Attributes:
        regime: the evaluation regime the scores come from.
        scores: row label -> task (setting) -> one score per seed, seeds in ascending order.
        left_out: the tasks that could not be normalised, with why (no expert run, or an
            expert that never succeeded).
    """

    regime: str
    scores: Mapping[str, Mapping[Setting, Sequence[float]]]
    left_out: Mapping[Setting, str]

    def tasks(self, label: str) -> list[Sequence[float]]:
        """The scores of ``label`` grouped by task, as the stratified statistics take them."""
        return list(self.scores[label].values())


def normalised_scores(runs: Iterable[RunRecord], regime: str = "deploy") -> NormalisedScores:
    """Per row and task (setting), each seed's ``regime`` success rate over the expert's
    (pooled over the expert's runs of that setting, since the expert does not train); the
    expert row itself is not scored.

    Examples:
        >>> from pathlib import Path
        >>> def run(label, seed, successes, env="u"):
        ...     result = EvaluationResult("deploy", successes, [0.0] * len(successes), [1] * len(successes))
        ...     return RunRecord(Path(f"{env}/{label}/{seed}"), label, Setting(env, 400, 1.0, 2), seed, {"deploy": result})
        >>> runs = [run("expert", 0, [True, True, True, False]), run("c_sqil", 0, [True, True, False, False]),
        ...         run("c_sqil", 1, [True, True, True, False]), run("c_sqil", 0, [True], env="v")]
        >>> scores = normalised_scores(runs)
        >>> scores.tasks("c_sqil"), list(scores.left_out.values())
        ([[0.6666666666666666, 1.0]], ['no expert run'])
    """
    runs = list(runs)
    expert: dict[Setting, list[EvaluationResult]] = defaultdict(list)
    for run in runs:
        if run.label == "expert" and regime in run.evaluations:
            expert[run.setting].append(run.evaluations[regime])
    scored: dict[str, dict[Setting, list[float]]] = defaultdict(dict)
    left_out: dict[Setting, str] = {}
    for run in sorted(runs, key=lambda r: (r.label, r.setting, r.seed)):
        if run.label == "expert" or regime not in run.evaluations:
            continue
        if not expert.get(run.setting):
            left_out[run.setting] = "no expert run"
            continue
        reference = EvaluationResult.pool(expert[run.setting]).success_rate
        if not reference:
            left_out[run.setting] = "the expert never succeeded"
            continue
        scored[run.label].setdefault(run.setting, []).append(run.evaluations[regime].success_rate / reference)
    return NormalisedScores(regime, {label: scored[label] for label in ordered_labels(scored)}, left_out)


def aggregate_markdown(scores: NormalisedScores, digits: int = 2) -> str:
    """Per row: the tasks and runs scored, the mean and the IQM of the normalised score with
    the IQM's 95% stratified-bootstrap interval (runs resampled within each task;
    :func:`~torchrl_causal.evaluation.seed_statistics.stratified_bootstrap_interval`)."""
    header = ["Algorithm", "tasks", "runs", "mean", "IQM [95% stratified bootstrap CI]"]
    rows = []
    for label in scores.scores:
        tasks = scores.tasks(label)
        pooled = [x for task in tasks for x in task]
        low, high = stratified_bootstrap_interval(tasks)
        rows.append(
            [
                display_name(label),
                str(len(tasks)),
                str(len(pooled)),
                f"{math.fsum(pooled) / len(pooled):.{digits}f}",
                f"{interquartile_mean(pooled):.{digits}f} [{low:.{digits}f}, {high:.{digits}f}]",
            ]
        )
    return _markdown(header, rows)
