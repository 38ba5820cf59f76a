"""The report's figures: training curves (Figure 2), success-rate curves with a band over
seeds, maze trajectories (Figure 3), the window / horizon / strength ablations (Figure 4,
Appendix F) and the expert-normalised aggregate across tasks (rliable's IQM and
performance profile), as PNG files."""

from __future__ import annotations

import math
from collections import defaultdict
from collections.abc import Mapping, Sequence
from pathlib import Path

import matplotlib

matplotlib.use("Agg")  # reports are written on headless machines
import matplotlib.pyplot as plt  # noqa: E402
from matplotlib.patches import Rectangle  # noqa: E402

from torchrl_causal.algorithms import TABLE1_FAMILIES, Row  # noqa: E402
from torchrl_causal.errors import InvalidValueError
from torchrl_causal.evaluation.figures import save_figure  # noqa: E402
from torchrl_causal.evaluation.metrics import EvaluationResult  # noqa: E402
from torchrl_causal.evaluation.runs import RunRecord, Setting, mean_curve, seed_band  # noqa: E402
from torchrl_causal.evaluation.seed_statistics import (  # noqa: E402
    interquartile_mean,
    performance_profile,
    stratified_bootstrap_interval,
)
from torchrl_causal.evaluation.tables import NormalisedScores, display_name, ordered_labels  # noqa: E402

__all__ = [
    "plot_training_curves",
    "plot_success_curves",
    "plot_trajectories",
    "plot_ablation",
    "plot_aggregate",
    "ABLATION_AXES",
    "BAND",
]

ABLATION_AXES = {"k": "window size k", "horizon": "horizon H", "strength": "confounding strength"}


#: What the success curves' band spans — every seed's curve lies inside it.
BAND = "min-max over seeds"


def _grid(n: int) -> tuple[int, int]:
    cols = min(n, 3 if n > 4 else n)
    return math.ceil(n / cols), cols


def plot_training_curves(runs: Sequence[RunRecord], path: str | Path) -> Path | None:
    """Train-regime evaluation return during training, causal vs non-causal per algorithm,
    with each variant's final deploy-regime return as a marker at the end of its curve.

    The paper's point (Figure 2): both variants look alike during training; the gap only
    appears at deployment. Returns ``None`` when no run logged a curve.
    """
    by_label: dict[str, list[RunRecord]] = defaultdict(list)
    for run in runs:
        by_label[run.label].append(run)
    pairs = {family: (Row(family, causal=True).name, family) for family in TABLE1_FAMILIES}  # (causal, non-causal) labels
    families = [f for f in TABLE1_FAMILIES if any(by_label.get(p) and any(r.curve for r in by_label[p]) for p in pairs[f])]
    if not families:
        return None
    fig, axes = plt.subplots(1, len(families), figsize=(4.2 * len(families), 3.4), squeeze=False)
    for ax, family in zip(axes[0], families):
        for label, colour in zip(pairs[family], ("tab:blue", "tab:red")):
            curve = mean_curve(r.curve for r in by_label.get(label, ()))
            if not curve:
                continue
            steps, values = zip(*curve)
            ax.plot(steps, values, color=colour, label=f"{display_name(label)} (train regime)")
            deploy = [r.evaluations["deploy"] for r in by_label[label] if "deploy" in r.evaluations]
            if deploy:
                value = EvaluationResult.pool(deploy).return_mean
                ax.scatter([steps[-1]], [value], color=colour, marker="X", s=80, zorder=3, label=f"{display_name(label)} (deploy, final)")
        ax.set_title(display_name(family))
        units = {r.unit for label in pairs[family] for r in by_label.get(label, ()) if r.unit}
        ax.set_xlabel(f"training progress ({' / '.join(sorted(units)) or 'steps'})")
        ax.set_ylabel("evaluation return E[Y]")
        ax.legend(fontsize=7)
    return save_figure(fig, path)


def _family(label: str) -> str:
    """The algorithm a row label runs (its panel in the success curves)."""
    row = Row.parse(label)
    return label if row is None else row.algorithm


def plot_success_curves(runs: Sequence[RunRecord], path: str | Path) -> Path | None:
    """Success rate of the periodic evaluations over training, one panel per algorithm and
    one line per row (causal and not): the mean over seeds with a band spanning the seeds
    (:data:`BAND`), solid for the train regime, dashed for the deploy regime where the
    runs recorded it. Each row's final deploy success (its selected policy's evaluation) is
    an ``X`` at the end of its curve with bars over the same seeds; the expert's final
    deploy success is a dotted line.

    Returns ``None`` when no run logged a success curve.
    """
    by_label: dict[str, list[RunRecord]] = defaultdict(list)
    for run in runs:
        by_label[run.label].append(run)
    labels = [label for label in ordered_labels(by_label) if any(r.success_curves for r in by_label[label])]
    if not labels:
        return None
    families = list(dict.fromkeys(_family(label) for label in labels))
    expert = [r.evaluations["deploy"] for r in by_label.get("expert", ()) if "deploy" in r.evaluations]
    n_rows, n_cols = _grid(len(families))
    fig, axes = plt.subplots(n_rows, n_cols, figsize=(4.6 * n_cols, 3.8 * n_rows), squeeze=False)
    for ax in axes.flat[len(families) :]:
        ax.axis("off")
    colours = ("tab:blue", "tab:red", "tab:orange", "tab:purple", "tab:brown")
    for ax, family in zip(axes.flat, families):
        rows = [label for label in labels if _family(label) == family]
        for label, colour in zip(rows, colours):
            seeds = by_label[label]
            last = 0
            for regime, style in (("train", "-"), ("deploy", "--")):
                band = seed_band([r.success_curves.get(regime, ()) for r in seeds])
                if not band:
                    continue
                steps, mean, low, high = (list(column) for column in zip(*band))
                ax.plot(steps, [100 * v for v in mean], style, color=colour, label=f"{display_name(label)} ({regime})")
                ax.fill_between(steps, [100 * v for v in low], [100 * v for v in high], color=colour, alpha=0.18, linewidth=0)
                last = max(last, steps[-1])
            final = [100 * r.evaluations["deploy"].success_rate for r in seeds if "deploy" in r.evaluations]
            if final:
                final_mean = math.fsum(final) / len(final)
                ax.errorbar(
                    [last],
                    [final_mean],
                    yerr=[[final_mean - min(final)], [max(final) - final_mean]],
                    color=colour,
                    marker="X",
                    markersize=9,
                    capsize=3,
                    linestyle="none",
                    zorder=3,
                    label=f"{display_name(label)} (deploy, final)",
                )
        if expert:
            ax.axhline(100 * EvaluationResult.pool(expert).success_rate, color="0.4", linestyle=":", label="Expert (deploy)")
        n_seeds = sorted({len(by_label[label]) for label in rows})
        ax.set_title(f"{display_name(family)}: {'/'.join(map(str, n_seeds))} seed{'' if n_seeds == [1] else 's'} per row", fontsize=10)
        units = {r.unit for label in rows for r in by_label[label] if r.unit}
        ax.set_xlabel(f"training progress ({' / '.join(sorted(units)) or 'steps'})")
        ax.set_ylabel("success rate (%)")
        ax.set_ylim(-3, 103)
        ax.legend(fontsize=6, loc="best")
    fig.suptitle(f"Success rate of the periodic evaluations: mean over seeds, band {BAND}", fontsize=10)
    return save_figure(fig, path)


def plot_aggregate(scores: Sequence[NormalisedScores], path: str | Path, thresholds: Sequence[float] | None = None) -> Path | None:
    """rliable's two summaries of expert-normalised scores across tasks, one row of panels
    per regime: the interquartile mean over all runs (seeds x tasks) with its 95%
    stratified-bootstrap interval (runs resampled within each task), and the performance
    profile, the fraction of runs whose score exceeds each threshold tau (each task
    weighing the same; ``thresholds`` defaults to 0 to 1.25 in steps of 0.01).

    Returns ``None`` when no regime has a scored row.
    """
    scores = [s for s in scores if s.scores]
    if not scores:
        return None
    taus = list(thresholds) if thresholds is not None else [i / 100 for i in range(126)]
    n_rows = max(len(s.scores) for s in scores)
    fig, axes = plt.subplots(len(scores), 2, figsize=(10, (0.4 * n_rows + 1.8) * len(scores)), squeeze=False)
    # one colour per algorithm; the causal row solid, the others dashed and hatched
    families = list(dict.fromkeys(_family(label) for s in scores for label in s.scores))
    colour_of = {family: f"C{i % 10}" for i, family in enumerate(families)}
    right = max(taus[-1], 1.05)
    for (bars, profile), regime_scores in zip(axes, scores):
        labels = list(regime_scores.scores)
        for y, label in enumerate(labels):
            colour, causal = colour_of[_family(label)], label.startswith("c_")
            tasks = regime_scores.tasks(label)
            iqm = interquartile_mean([x for task in tasks for x in task])
            low, high = stratified_bootstrap_interval(tasks)
            right = max(right, high + 0.05)
            # a zero-width interval (one run per task) still shows as a thin bar
            bars.barh(
                y, max(high - low, 0.006), left=low, height=0.6, color=colour, alpha=0.45 if causal else 0.2, hatch=None if causal else "//"
            )
            bars.plot([iqm, iqm], [y - 0.3, y + 0.3], color=colour, linewidth=2.5)
            profile.plot(
                taus,
                performance_profile(tasks, taus),
                "-" if causal else "--",
                color=colour,
                label=display_name(label),
                drawstyle="steps-post",
            )
        n_tasks = len({task for by_task in regime_scores.scores.values() for task in by_task})
        bars.set_yticks(range(len(labels)), [display_name(label) for label in labels])
        bars.set_xlim(-0.02, right)
        bars.invert_yaxis()
        bars.axvline(1.0, color="0.5", linestyle=":", linewidth=1)
        bars.set_xlabel("IQM of success / expert's success (bar: 95% stratified bootstrap CI)")
        bars.set_title(f"{regime_scores.regime} regime, {n_tasks} task{'' if n_tasks == 1 else 's'}", fontsize=10)
        profile.set_xlabel(f"normalised {regime_scores.regime} score tau")
        profile.set_ylabel("fraction of runs with score > tau")
        profile.set_ylim(-0.03, 1.03)
        profile.set_title("performance profile", fontsize=10)
        profile.legend(fontsize=7)
    return save_figure(fig, path)


def _draw_maze(ax, maze: Mapping | None) -> None:
    if not maze:
        return
    for x0, y0, x1, y1 in maze.get("walls", ()):
        ax.add_patch(Rectangle((x0, y0), x1 - x0, y1 - y0, color="0.3"))
    if maze.get("goal") is not None:
        ax.scatter(*maze["goal"][:2], marker="*", s=180, color="gold", edgecolor="k", zorder=4)
    if maze.get("start") is not None:
        ax.scatter(*maze["start"][:2], marker="o", s=60, color="tab:green", edgecolor="k", zorder=4)


def plot_trajectories(table_runs: Mapping[str, Sequence[RunRecord]], path: str | Path, regime: str = "deploy") -> Path | None:
    """Recorded ``regime`` trajectories of each algorithm drawn on the maze (Figure 3 style).

    Green paths reached the goal, red ones did not. Returns ``None`` when no run recorded a
    trajectory (e.g. Route Choice, which has no positions).
    """
    labels = [
        label
        for label in ordered_labels(table_runs)
        if any(r.evaluations.get(regime) and r.evaluations[regime].trajectories for r in table_runs[label])
    ]
    if not labels:
        return None
    rows, cols = _grid(len(labels))
    fig, axes = plt.subplots(rows, cols, figsize=(3.6 * cols, 3.6 * rows), squeeze=False)
    for ax in axes.flat[len(labels) :]:
        ax.axis("off")
    for ax, label in zip(axes.flat, labels):
        runs = [r for r in table_runs[label] if regime in r.evaluations]
        _draw_maze(ax, next((r.maze for r in runs if r.maze), None))
        result = EvaluationResult.pool([r.evaluations[regime] for r in runs])
        for trajectory, success in zip(result.trajectories, result.successes):
            xs, ys = zip(*trajectory)
            ax.plot(xs, ys, color="tab:green" if success else "tab:red", alpha=0.7, linewidth=1.2)
        ax.set_title(f"{display_name(label)}: {100 * result.success_rate:.0f}% success")
        ax.set_aspect("equal")
        ax.set_xticks([])
        ax.set_yticks([])
    fig.suptitle(f"{regime}-regime trajectories")
    return save_figure(fig, path)


def plot_ablation(
    aggregated: Mapping[Setting, Mapping[str, Mapping[str, EvaluationResult]]],
    axis: str,
    path: str | Path,
    regime: str = "deploy",
) -> Path | None:
    """Deploy success rate (± SE) of every algorithm against one setting ``axis``
    (``"k"``, ``"horizon"`` or ``"strength"``), the other setting fields held fixed.

    Uses the largest group of settings that differ only in ``axis``; returns ``None`` when
    no two settings differ in ``axis`` alone.
    """
    if axis not in ABLATION_AXES:
        raise InvalidValueError(f"unknown ablation axis {axis!r}; expected one of {sorted(ABLATION_AXES)}")
    groups: dict[tuple, list[Setting]] = defaultdict(list)
    for setting in aggregated:
        groups[tuple(v for f, v in setting._asdict().items() if f != axis)].append(setting)
    settings = max(groups.values(), key=len, default=[])
    if len(settings) < 2:
        return None
    settings = sorted(settings, key=lambda s: getattr(s, axis))
    fig, ax = plt.subplots(figsize=(6, 4))
    labels = ordered_labels({label for s in settings for label in aggregated[s]})
    for label in labels:
        points = [(getattr(s, axis), aggregated[s][label][regime]) for s in settings if regime in aggregated[s].get(label, {})]
        if not points:
            continue
        xs = [x for x, _ in points]
        ax.errorbar(
            xs,
            [100 * r.success_rate for _, r in points],
            yerr=[100 * r.success_se for _, r in points],
            marker="o",
            capsize=3,
            label=display_name(label),
            linestyle="-" if label.startswith("c_") or label == "expert" else "--",
        )
    ax.set_xlabel(ABLATION_AXES[axis])
    ax.set_ylabel(f"{regime} success rate (%)")
    ax.set_title(f"{settings[0].env}: {ABLATION_AXES[axis]} ablation")
    if axis == "k" and max(getattr(s, axis) for s in settings) >= 50:
        ax.set_xscale("symlog")
    ax.legend(fontsize=7)
    return save_figure(fig, path)
