"""The report's figures: training curves (Figure 2), maze trajectories (Figure 3) and the
window / horizon / strength ablations (Figure 4, Appendix F), as PNG files."""

from __future__ import annotations

import math
from collections import defaultdict
from collections.abc import Mapping, Sequence
from pathlib import Path

import matplotlib

matplotlib.use("Agg")  # reports are written on headless machines
import matplotlib.pyplot as plt  # noqa: E402
from matplotlib.patches import Rectangle  # noqa: E402

from torchrl_causal.errors import InvalidValueError
from torchrl_causal.evaluation.metrics import EvaluationResult  # noqa: E402
from torchrl_causal.evaluation.runs import RunRecord, Setting, mean_curve  # noqa: E402
from torchrl_causal.evaluation.tables import display_name, ordered_labels  # noqa: E402

__all__ = ["plot_training_curves", "plot_trajectories", "plot_ablation", "ABLATION_AXES"]

_FAMILIES = ("bc", "gail", "sqil", "iq_learn")
ABLATION_AXES = {"k": "window size k", "horizon": "horizon H", "strength": "confounding strength"}


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
    families = [f for f in _FAMILIES if any(by_label.get(p) and any(r.curve for r in by_label[p]) for p in (f, f"c_{f}"))]
    if not families:
        return None
    fig, axes = plt.subplots(1, len(families), figsize=(4.2 * len(families), 3.4), squeeze=False)
    for ax, family in zip(axes[0], families):
        for label, colour in ((f"c_{family}", "tab:blue"), (family, "tab:red")):
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
        units = {r.unit for label in (family, f"c_{family}") for r in by_label.get(label, ()) if r.unit}
        ax.set_xlabel(f"training progress ({' / '.join(sorted(units)) or 'steps'})")
        ax.set_ylabel("evaluation return E[Y]")
        ax.legend(fontsize=7)
    fig.tight_layout()
    path = Path(path)
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path


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
    fig.tight_layout()
    path = Path(path)
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path


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
    fig.tight_layout()
    path = Path(path)
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path
