"""The confounding-strength ablation of trained runs (the paper's Appendix F):
``python -m torchrl_causal.strength_ablation runs=<dir> [strengths=[0.15,0.5,0.85,1.0]]
[episodes=1000] [seed=30000] [out=<dir>] [name=<str>] [threads=1]``.

The strength only sets how far the deployment regime shifts the confounded sensor
(the compass is rotated by ``strength * pi``); training never sees it. So the ablation is
an evaluation, not new training: every run below ``runs`` (its selected policy,
``checkpoints/best.pt``) is evaluated in the deploy regime at each strength with
:func:`~torchrl_causal.lifecycle.evaluate_run`, which keeps each record in
``<run_dir>/eval/deploy-n<episodes>-seed<seed>-envs<n>-cs<strength>.json``. A record that
already exists with the same settings is read back instead of evaluated again, so an
interrupted ablation resumes and a finished one rewrites its report in seconds, and an
archive (``python -m torchrl_causal.archive``) gives back every record it holds. A run that
lacks a record and whose selected policy is gone (an archived run) is left out at every
strength, with a warning naming it, so that each row pools the same seeds in every column;
the table names the seeds of each row.

Writes ``<out>/<name>.md`` (deploy success % ± SE per algorithm and strength, pooled over
seeds, with the regenerating command; a notes block written by hand between the report's
markers is kept, as :func:`~torchrl_causal.evaluation.write_report` keeps it) and
``<out>/<name>.png`` (success against strength, causal methods solid, non-causal dashed).
"""

from __future__ import annotations

import logging
from collections.abc import Sequence
from dataclasses import replace
from pathlib import Path

import torch

from torchrl_causal.cli.arguments import Option, argv_or_sys, one_line_errors, parse_arguments
from torchrl_causal.errors import InvalidValueError, MissingFileError
from torchrl_causal.evaluation.plots import plot_ablation
from torchrl_causal.evaluation.reporting import notes_to_keep, provenance_markdown
from torchrl_causal.evaluation.runs import RunRecord, load_runs
from torchrl_causal.evaluation.tables import aggregate, display_name, ordered_labels
from torchrl_causal.experiment import CheckpointError
from torchrl_causal.lifecycle import DEFAULT_THREADS, evaluate_run

__all__ = ["OPTIONS", "PAPER_STRENGTHS", "strength_ablation", "strength_markdown", "main"]

PAPER_STRENGTHS: tuple[float, ...] = (0.15, 0.5, 0.85, 1.0)  # Appendix F's strength ablation
OPTIONS: dict[str, Option] = {
    "runs": Option(str, placeholder="<dir>", help="the folder of one setting's trained runs"),
    "strengths": Option(
        list,
        list(PAPER_STRENGTHS),
        ge=0.0,
        le=1.0,
        item=float,
        placeholder="[" + ",".join(map(str, PAPER_STRENGTHS)) + "]",
        help="the deployment shifts to evaluate at",
    ),
    "episodes": Option(int, 1000, ge=1, help="episodes per run and strength"),
    "seed": Option(int, 30_000, ge=0, help="the evaluation seed"),
    "out": Option(str, None, placeholder="<runs>/report", help="where the table and figure go"),
    "name": Option(str, "strength_ablation", help="their file name"),
    "threads": Option(int, DEFAULT_THREADS, ge=1, help="torch threads"),
}
EXAMPLE = "python -m torchrl_causal.strength_ablation runs=runs/rovermaze_medium/h1000-cs1.0-k10 episodes=200"
log = logging.getLogger(__name__)


def strength_ablation(
    runs_root: str | Path, strengths: Sequence[float] = PAPER_STRENGTHS, episodes: int = 1000, seed: int = 30_000
) -> list[RunRecord]:
    """One record per run and strength, its setting's ``strength`` set to the evaluated one
    and its only evaluation the deploy regime there (ready for
    :func:`~torchrl_causal.evaluation.tables.aggregate`).

    Raises:
        FileNotFoundError: no evaluated run below ``runs_root``, or none that holds a record
            or its selected policy for every strength.
        ValueError: a strength outside [0, 1], or runs of more than one task / horizon / window.
    """
    runs = load_runs(runs_root)
    if not runs:
        raise MissingFileError(f"no evaluated runs below {runs_root} (expected */config.yaml with eval/*.json)")
    settings = {run.setting._replace(strength=0.0) for run in runs}
    if len(settings) > 1:
        raise InvalidValueError(
            f"runs below {runs_root} differ in more than the strength: {sorted(settings)}; point runs= at one setting's folder"
        )
    bad = [s for s in strengths if not 0.0 <= float(s) <= 1.0]
    if bad:
        raise InvalidValueError(f"strengths must lie in [0, 1], got {bad}")
    records = []
    for run in runs:
        try:
            evaluations = {
                float(strength): evaluate_run(
                    run.path, "deploy", int(episodes), seed=int(seed), confounding_strength=float(strength), reuse=True
                )
                for strength in strengths
            }
        except CheckpointError as error:
            log.warning("left out: %s, and it holds no record of every strength asked for", error)
            continue
        records += [
            replace(run, setting=run.setting._replace(strength=strength), evaluations={"deploy": result})
            for strength, result in evaluations.items()
        ]
    if not records:
        raise MissingFileError(
            f"no run below {runs_root} could be evaluated at strengths {list(strengths)}: "
            "their selected policies are gone and they hold no such records"
        )
    return records


def strength_markdown(records: Sequence[RunRecord]) -> str:
    """Deploy success % ± SE, one row per algorithm (with the training seeds it pools), one
    column per strength."""
    aggregated = aggregate(records)
    settings = sorted(aggregated, key=lambda s: s.strength)
    labels = ordered_labels({label for table in aggregated.values() for label in table})
    seeds = {label: sorted({r.seed for r in records if r.label == label}) for label in labels}
    lines = ["| Algorithm | Seeds | " + " | ".join(f"{s.strength:g}" for s in settings) + " |", "|---|---|" + "---|" * len(settings)]
    for label in labels:
        cells = [", ".join(map(str, seeds[label]))]
        for setting in settings:
            result = aggregated[setting].get(label, {}).get("deploy")
            cells.append("—" if result is None else f"{100 * result.success_rate:.1f} ± {100 * result.success_se:.1f}")
        lines.append(f"| {display_name(label)} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def main(argv: Sequence[str] | None = None) -> Path:
    cli = argv_or_sys(argv)
    args = parse_arguments("strength_ablation", cli, OPTIONS, about=__doc__, example=EXAMPLE)
    torch.set_num_threads(args["threads"])  # see torchrl_causal.lifecycle
    out = Path(args["out"] or Path(args["runs"]) / "report")
    path = out / f"{args['name']}.md"
    with one_line_errors():
        notes = notes_to_keep(path)  # before anything is evaluated or written
        records = strength_ablation(args["runs"], args["strengths"], args["episodes"], args["seed"])
        out.mkdir(parents=True, exist_ok=True)
        figure = plot_ablation(aggregate(records), "strength", out / f"{args['name']}.png")
    command = " ".join(["python -m torchrl_causal.strength_ablation", *cli])
    setting = records[0].setting
    trained = list({record.path: record for record in records}.values())
    text = "\n".join(
        [
            f"# Confounding-strength ablation: {setting.env} (H={setting.horizon}, k={setting.k})",
            "",
            "Regenerate with:",
            "",
            "```bash",
            command,
            "```",
            "",
            notes,
            "",
            f"Deploy-regime success rate (%) ± SE of each run's selected policy, {args['episodes']} episodes per strength "
            f"(evaluation seed {args['seed']}), pooled over the training seeds of each row. "
            "Strength s rotates the compass by s·π at deployment; training is unchanged.",
            "",
            strength_markdown(records),
            "",
            "What made these runs (package versions, CPU and threads of their training attempts):",
            "",
            provenance_markdown(trained),
            "",
            *([f"![strength ablation]({figure.name})", ""] if figure is not None else []),
        ]
    )
    path.write_text(text)
    print(text)
    return path


if __name__ == "__main__":
    main()
