"""Writes the report of a folder of runs: Markdown tables, the results CSV and figures."""

from __future__ import annotations

import re
from collections import defaultdict
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace  # noqa: F401  (the docstring examples use it)
from pathlib import Path
from typing import Any

from torchrl_causal.errors import ExistingFileError, MissingFileError
from torchrl_causal.evaluation.plots import (
    ABLATION_AXES,
    BAND,
    plot_ablation,
    plot_aggregate,
    plot_success_curves,
    plot_training_curves,
    plot_trajectories,
)
from torchrl_causal.evaluation.runs import RunRecord, Setting, load_runs
from torchrl_causal.evaluation.tables import (
    CSV_COLUMNS,
    EffectTargets,
    aggregate,
    aggregate_markdown,
    csv_rows,
    display_name,
    effect_checks,
    effect_markdown,
    lengths_markdown,
    normalised_scores,
    raw_markdown,
    read_reported_rows,
    seed_effect_checks,
    seeds_markdown,
    table1_markdown,
    write_csv,
)

__all__ = ["Report", "write_report", "kept_command", "kept_notes", "notes_to_keep", "provenance_markdown", "NOTES_BEGIN", "NOTES_END"]

# Hand-written analysis between these markers survives regeneration of the Markdown file.
NOTES_BEGIN = "<!-- notes: kept when the report is regenerated -->"
NOTES_END = "<!-- /notes -->"


@dataclass
class Report:
    """What :func:`write_report` wrote."""

    markdown: Path
    csv: Path
    all_csv: Path
    figures: list[Path] = field(default_factory=list)
    main_setting: Setting | None = None


def _main_setting(runs: Sequence[RunRecord], carried: Mapping[Setting, Sequence[str]]) -> Setting:
    counts: dict[Setting, int] = defaultdict(int)
    for run in runs:
        counts[run.setting] += 1
    for setting, labels in carried.items():
        counts[setting] += len(labels)
    # Most runs (a carried row counts as one) first; ties go to the strongest confounding
    # and the longest horizon, which is the paper's default configuration.
    return max(counts, key=lambda s: (counts[s], s.strength, s.horizon, -s.k))


def _task_runs(runs: Sequence[RunRecord]) -> list[RunRecord]:
    """The runs of each env's main setting (the most runs): the tasks the expert-normalised
    aggregate pools, one per env, so that an ablation's other settings do not count as tasks."""
    by_env: dict[str, list[RunRecord]] = defaultdict(list)
    for run in runs:
        by_env[run.setting.env].append(run)
    mains = {_main_setting(env_runs, {}) for env_runs in by_env.values()}
    return [run for run in runs if run.setting in mains]


def _search(path: str | Path, pattern: str) -> re.Match[str] | None:
    """The first match of ``pattern`` (dot matches newlines, ``^`` each line) in a results file
    written earlier; ``None`` when the file does not exist."""
    path = Path(path)
    return re.search(pattern, path.read_text(), flags=re.S | re.M) if path.is_file() else None


def kept_notes(path: str | Path) -> str:
    """The hand-written notes block of a results file (``NOTES_BEGIN`` ... ``NOTES_END``,
    markers included) that its regeneration keeps; ``""`` when there is none.

    Examples:
        >>> import tempfile, pathlib
        >>> md = pathlib.Path(tempfile.mkdtemp()) / "r.md"
        >>> _ = md.write_text(f"# R\\n{NOTES_BEGIN}\\nWhy.\\n{NOTES_END}\\n| table |")
        >>> kept_notes(md).splitlines()[1]
        'Why.'
    """
    match = _search(path, re.escape(NOTES_BEGIN) + r".*?" + re.escape(NOTES_END))
    return match.group(0) if match else ""


def notes_to_keep(path: str | Path) -> str:
    """The notes block a regenerated results file carries: the one ``path`` holds, or an
    empty one (the place for notes) when ``path`` does not exist yet.

    Raises:
        FileExistsError: ``path`` exists without the notes markers: regenerating it would
            delete whatever was written in it by hand.

    Examples:
        >>> import tempfile, pathlib
        >>> md = pathlib.Path(tempfile.mkdtemp()) / "r.md"
        >>> notes_to_keep(md) == f"{NOTES_BEGIN}\\n{NOTES_END}"
        True
        >>> _ = md.write_text("# R\\nA reading written by hand.\\n")
        >>> notes_to_keep(md)  # doctest: +ELLIPSIS
        Traceback (most recent call last):
        ...
        torchrl_causal.errors.ExistingFileError: .../r.md has no notes markers ...
    """
    path = Path(path)
    if not path.exists():
        return f"{NOTES_BEGIN}\n{NOTES_END}"
    notes = kept_notes(path)
    if not notes:
        raise ExistingFileError(
            f"{path} has no notes markers ({NOTES_BEGIN} ... {NOTES_END}), so regenerating it would delete any text "
            "written in it by hand: move that text between the two markers (or delete the file, or write elsewhere "
            "with out= / name=), then rerun"
        )
    return notes


def _describe_machine(attempt: Mapping[str, Any]) -> str:
    packages = attempt.get("packages") or {}
    listed = ", ".join(f"{name} {version or 'absent'}" for name, version in packages.items())
    threads = attempt.get("threads")
    cores = attempt.get("cores")
    return (
        f"{listed}; Python {attempt.get('python', '?')}; CPU {attempt.get('cpu', '?')}, "
        f"{threads} thread{'s' if threads != 1 else ''}"
        + (f" of {cores} cores" if cores else "")
        + f"; device {attempt.get('device', '?')}"
        + ("; compiled" if attempt.get("compile") else "")
    )


def provenance_markdown(runs: Sequence[RunRecord]) -> str:
    """What made ``runs``: each distinct combination of package versions, CPU and threads
    their attempts recorded (``code.json``), with the runs trained under it; runs recorded
    before versions were name themselves as unknown.

    Examples:
        >>> from torchrl_causal.evaluation.runs import RunRecord, Setting
        >>> attempt = {"packages": {"torch": "2.13.0", "numpy": "2.3.4"}, "python": "3.12.3", "cpu": "Xeon",
        ...            "threads": 1, "cores": 2, "device": "cpu", "compile": False}
        >>> record = RunRecord(Path("r/c_sqil/seed0"), "c_sqil", Setting("u", 400, 1.0, 2), 0, {}, attempts=(attempt,))
        >>> older = replace(record, path=Path("r/bc/seed0"), label="bc", attempts=())
        >>> print(provenance_markdown([record, older]))
        - torch 2.13.0, numpy 2.3.4; Python 3.12.3; CPU Xeon, 1 thread of 2 cores; device cpu: 1 run (C-SQIL seed 0)
        - not recorded (trained before package versions were recorded, or the expert row): 1 run (BC seed 0)
    """
    groups: dict[str, list[str]] = defaultdict(list)
    for run in runs:
        name = f"{display_name(run.label)} seed {run.seed}"
        recorded = [attempt for attempt in run.attempts if attempt.get("packages")]
        if not recorded:
            groups["not recorded (trained before package versions were recorded, or the expert row)"].append(name)
        for machine in dict.fromkeys(_describe_machine(attempt) for attempt in recorded):
            groups[machine].append(name)
    return "\n".join(
        f"- {machine}: {len(names)} run{'s' if len(names) != 1 else ''} ({', '.join(names)})" for machine, names in groups.items()
    )


def kept_command(path: str | Path) -> str | None:
    """The command in the "Regenerate with" block of a results file written by
    :func:`write_report`; ``None`` when the file or the block is absent.

    Examples:
        >>> import tempfile, pathlib
        >>> md = pathlib.Path(tempfile.mkdtemp()) / "r.md"
        >>> _ = md.write_text("# R\\n\\nRegenerate with:\\n\\n```bash\\nmake demo\\n```\\n")
        >>> kept_command(md)
        'make demo'
    """
    match = _search(path, r"^Regenerate with:\n\n```bash\n(.*?)\n```")
    return match.group(1) if match else None


def _carry(aggregated: dict[Setting, dict], carried: str | Path) -> dict[Setting, list[str]]:
    """Adds to ``aggregated`` the rows of ``carried`` (an earlier ``_all.csv``) of the
    labels no run holds in their setting; returns the labels added, per setting."""
    added: dict[Setting, list[str]] = {}
    for setting, rows in read_reported_rows(carried).items():
        table = aggregated.setdefault(setting, {})
        added[setting] = [label for label in rows if label not in table]
        table.update({label: rows[label] for label in added[setting]})
    return {setting: labels for setting, labels in added.items() if labels}


def write_report(
    runs_root: str | Path | Sequence[str | Path],
    out_dir: str | Path | None = None,
    *,
    name: str | None = None,
    command: str | None = None,
    carried: str | Path | None = None,
    targets: EffectTargets = EffectTargets(),
) -> Report:
    """Reads every run below ``runs_root`` (a folder, or several: see
    :func:`~torchrl_causal.evaluation.runs.load_runs`) and writes ``<out_dir>/<name>.{md,csv}``,
    ``<name>_all.csv`` (every setting, with setting columns) and the PNG figures.

    ``<name>.csv`` holds the main setting (the most runs, a carried row counting as one) with
    exactly the columns :data:`~torchrl_causal.evaluation.tables.CSV_COLUMNS`.

    ``carried`` names an earlier report's ``_all.csv`` whose rows stand in for runs whose
    records are gone (a lost machine; see ``python -m torchrl_causal.archive`` for keeping
    them): a row is carried into the tables and CSVs unchanged where no run below
    ``runs_root`` has its setting and label, and the Markdown names every carried row.
    The training curves, trajectories and across-seeds table come from the runs alone; the
    ablation plots, drawn from the tables, show carried rows too.

    ``targets`` sets the thresholds of the effect checks (the task's issue may ask more than
    the defaults: AntMaze's asks 90% / 10%).

    Without ``command`` the Markdown keeps the command its earlier version recorded (see
    :func:`kept_command`), as it keeps the hand-written notes (:func:`kept_notes`).
    """
    roots = [Path(runs_root)] if isinstance(runs_root, (str, Path)) else [Path(root) for root in runs_root]
    runs = load_runs(roots)
    if not runs:
        raise MissingFileError(f"no evaluated runs below {', '.join(map(str, roots))} (expected */config.yaml with eval/*.json)")
    out_dir = Path(out_dir) if out_dir is not None else roots[0] / "report"
    envs = sorted({run.setting.env for run in runs})
    name = name or (envs[0] if len(envs) == 1 else "report")
    notes = notes_to_keep(out_dir / f"{name}.md")  # before anything is written
    out_dir.mkdir(parents=True, exist_ok=True)
    aggregated = aggregate(runs)
    carried_labels = _carry(aggregated, carried) if carried is not None else {}
    main = _main_setting(runs, carried_labels)

    report = Report(out_dir / f"{name}.md", out_dir / f"{name}.csv", out_dir / f"{name}_all.csv", main_setting=main)
    write_csv(csv_rows(aggregated[main]), report.csv)
    all_rows = [
        {"env": s.env, "horizon": s.horizon, "strength": s.strength, "k": s.k, **row}
        for s in sorted(aggregated)
        for row in csv_rows(aggregated[s])
    ]
    write_csv(all_rows, report.all_csv, columns=("env", "horizon", "strength", "k", *CSV_COLUMNS))

    main_runs = [r for r in runs if r.setting == main]
    by_label: dict[str, list[RunRecord]] = defaultdict(list)
    for run in main_runs:
        by_label[run.label].append(run)
    task_runs = _task_runs(runs)
    scores = [normalised_scores(task_runs, regime) for regime in ("deploy", "train")]
    figures = {
        "training curves": plot_training_curves(main_runs, out_dir / f"{name}_training_curves.png"),
        f"success rate over training (band: {BAND})": plot_success_curves(main_runs, out_dir / f"{name}_success_curves.png"),
        "deploy-regime trajectories": plot_trajectories(by_label, out_dir / f"{name}_trajectories.png"),
        "IQM and performance profile of the expert-normalised success": plot_aggregate(scores, out_dir / f"{name}_aggregate.png"),
    }
    for axis in ABLATION_AXES:
        figures[f"{ABLATION_AXES[axis]} ablation"] = plot_ablation(aggregated, axis, out_dir / f"{name}_ablation_{axis}.png")
    report.figures = [p for p in figures.values() if p is not None]

    lines = [f"# Results: {name}", ""]
    command = command or kept_command(report.markdown)
    if command:
        lines += ["Regenerate with:", "", "```bash", command.strip(), "```", ""]
    lines += [notes, ""]
    ordered = [main] + sorted(s for s in aggregated if s != main)
    for setting in ordered:
        table = aggregated[setting]
        seeds = sorted({r.seed for r in runs if r.setting == setting})
        lines += [
            f"## {setting.describe()}",
            "",
            f"Seeds: {', '.join(map(str, seeds))}. Normalised E[Y] shifts the worst algorithm of the row to 0 "
            "(the reward is purely negative); ± is the return's standard deviation and the success "
            "rate's standard error over the pooled episodes (as the paper's Table 1).",
            "",
        ]
        if carried is not None and setting in carried_labels:
            lines += [
                f"Carried from `{Path(carried).name}` (an earlier report; their runs' records are not below "
                "the runs folder, so the training curves and trajectories do not show them): "
                + ", ".join(display_name(label) for label in carried_labels[setting])
                + ".",
                "",
            ]
        for regime in ("deploy", "train"):
            if any(regime in regimes for regimes in table.values()):
                lines += [f"### {regime.capitalize()} regime (Table 1 layout)", "", table1_markdown(table, regime), ""]
        lines += [
            "### Raw E[Y] and success rate",
            "",
            raw_markdown(table),
            "",
            "### Mean length of successful episodes",
            "",
            lengths_markdown(table),
            "",
        ]
        if len(seeds) > 1:
            setting_runs = [r for r in runs if r.setting == setting]
            lines += ["### Across seeds", "", seeds_markdown(setting_runs), ""]
            seed_checks = seed_effect_checks(setting_runs, targets)
            if seed_checks:
                lines += [effect_markdown(seed_checks), ""]
        checks = effect_checks(table, targets)
        if checks:
            lines += ["### The paper's effect, checked", "", effect_markdown(checks), ""]
    if any(regime_scores.scores for regime_scores in scores):
        lines += [
            "## Across tasks: expert-normalised success",
            "",
            "Each run's success rate over the expert's in its task and regime (the expert pooled over its runs), "
            "pooled over "
            + ", ".join(sorted({run.setting.describe() for run in task_runs}))
            + " (each env's setting with the most runs; the table's own rows, not carried ones). "
            "IQM: the mean of the middle half of the runs; its interval is the 95% percentile bootstrap that "
            "resamples the seeds within each task (rliable's stratified bootstrap, exact where the resamples are "
            f"few enough). Figures: `{name}_aggregate.png` (IQM and performance profile, the fraction of runs "
            f"above each score), `{name}_success_curves.png` (mean over seeds, band {BAND}).",
            "",
        ]
        for regime_scores in scores:
            if regime_scores.scores:
                lines += [f"### {regime_scores.regime.capitalize()} regime", "", aggregate_markdown(regime_scores), ""]
                if regime_scores.left_out:
                    lines += [
                        "Not normalised: "
                        + "; ".join(f"{setting.describe()} ({why})" for setting, why in sorted(regime_scores.left_out.items()))
                        + ".",
                        "",
                    ]
    lines += [
        "## What made these runs",
        "",
        "Package versions, CPU and threads of every training attempt (the runs' `code.json`); another "
        "CPU, thread count or package version changes floating-point summation order, and the figures with it.",
        "",
        provenance_markdown(runs),
        "",
    ]
    if report.figures:
        lines += ["## Figures", ""]
        lines += [f"![{title}]({path.name})" for title, path in figures.items() if path is not None]
        lines.append("")
    report.markdown.write_text("\n".join(lines))
    return report
