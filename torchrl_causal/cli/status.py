"""Where the runs below a folder stand: ``python -m torchrl_causal.status runs=<dir>``.

One row per run directory (a folder holding ``config.yaml``, below ``runs``): its status
(``running`` while a process holds its lock; ``killed`` when its file says running but no
process does, i.e. the process died without recording its stop; ``interrupted``;
``failed``, with the error; ``complete``), its progress against its budget, the best
train-regime evaluation return so far, its attempts (its start and each resume, from
``code.json``) with the fields of code, data and runtime that changed between them, what
each attempt cost (wall time / process CPU time, ``—`` for an attempt that did not record it:
killed outright, or older than the record), and its final success rates once it has them. A
``killed`` or ``interrupted`` run continues from its last checkpoint when its command is
run again. Final success rates are shown for complete runs only: a run training again
after its budget was raised still holds the evaluations of the earlier budget.

Examples:
    >>> import tempfile
    >>> from torchrl_causal.experiment import RunDirectory
    >>> root = tempfile.mkdtemp()
    >>> run = RunDirectory(f"{root}/rovermaze_u/c_sqil/seed0")
    >>> run.path.mkdir(parents=True)
    >>> _ = run.config_file.write_text("seed: 0")
    >>> run.write_status("running", progress=50000, total=150000, unit="env steps", best_train_return=-91.5)
    >>> _ = run.record_attempt({"source": "a", "compile": True}, progress=0)
    >>> _ = run.record_attempt_cost(0, {"wall_s": 5400.0, "cpu_s": 1500.0})
    >>> _ = run.record_attempt({"source": "b", "compile": True}, progress=40000)
    >>> print(status_markdown(run_statuses(root)))
    | run | status | progress | attempts | cost (wall / CPU) | best train return | train success % | deploy success % |
    |---|---|---|---|---|---|---|---|
    | rovermaze_u/c_sqil/seed0 | killed | 50000 / 150000 env steps (33%) | 2 (source changed) | 1.50 h / 25.0 min + — | -91.5 | — | — |
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

from torchrl_causal.cli.arguments import Option, argv_or_sys, one_line_errors, parse_arguments
from torchrl_causal.envs.base import REGIMES
from torchrl_causal.errors import InvalidValueError, MissingFileError
from torchrl_causal.evaluation.metrics import EvaluationResult
from torchrl_causal.experiment.provenance import COST_FIELDS, RUNTIME_FIELDS, identity_changes
from torchrl_causal.experiment.run_directory import CONFIG_FILE, RunDirectory

__all__ = ["OPTIONS", "run_statuses", "status_markdown", "main"]

OPTIONS: dict[str, Option] = {"runs": Option(str, placeholder="<dir>", help="the folder whose run directories are listed")}
EXAMPLE = "python -m torchrl_causal.status runs=runs"

COLUMNS = ("run", "status", "progress", "attempts", "cost (wall / CPU)", "best train return", "train success %", "deploy success %")


def _progress(status: dict[str, Any]) -> str:
    progress, total, unit = status.get("progress"), status.get("total"), status.get("unit")
    if progress is None:
        return "—"
    if total == 0:
        return "no training"  # the expert: evaluated, not trained
    counted = f"{progress} / {total}" if total else f"{progress}"
    return counted + (f" {unit}" if unit else "") + (f" ({100 * progress / total:.0f}%)" if total else "")


def _attempts(attempts: Sequence[dict[str, Any]]) -> str:
    if not attempts:
        return "—"  # trained before attempts were recorded, or not started
    changed = set().union(*(identity_changes(previous, current) for previous, current in zip(attempts, attempts[1:])))
    named = [field for field in RUNTIME_FIELDS if field in changed]
    return f"{len(attempts)}" + (f" ({', '.join(named)} changed)" if named else "")


def _duration(seconds: float | None) -> str:
    """``42 s``, ``12.5 min`` or ``2.10 h``; ``—`` when not recorded.

    Examples:
        >>> [_duration(s) for s in (42.4, 750.0, 7560.0, None)]
        ['42 s', '12.5 min', '2.10 h', '—']
    """
    if seconds is None:
        return "—"
    if seconds < 60:
        return f"{seconds:.0f} s"
    if seconds < 3600:
        return f"{seconds / 60:.1f} min"
    return f"{seconds / 3600:.2f} h"


def _costs(attempts: Sequence[dict[str, Any]]) -> str:
    """Each attempt's ``wall / CPU``, joined by `` + ``; ``—`` for an attempt that
    recorded no cost (killed outright, or recorded before attempts had a cost); ``—``
    alone when none did."""
    if not any(field in attempt for attempt in attempts for field in COST_FIELDS):
        return "—"
    parts = []
    for attempt in attempts:
        wall, cpu = attempt.get("wall_s"), attempt.get("cpu_s")
        parts.append("—" if wall is None and cpu is None else f"{_duration(wall)} / {_duration(cpu)}")
    return " + ".join(parts)


def _success(run: RunDirectory, regime: str) -> str:
    path = run.eval_path(regime)
    if not path.is_file():
        return "—"
    return f"{100 * EvaluationResult.from_dict(run.read_json(path)).success_rate:.1f}"


def run_statuses(root: str | Path) -> list[dict[str, str]]:
    """A row of :data:`COLUMNS` for every run directory below ``root``, in path order.

    Raises:
        FileNotFoundError: if ``root`` does not exist.
        InvalidValueError: if ``root`` is a file (a ``ValueError``).
        ~torchrl_causal.experiment.run_directory.RunFileError: a run's ``status.json`` or evaluation that does not parse, named.
    """
    root = Path(root)
    if not root.exists():
        raise MissingFileError(f"runs folder {root} does not exist")
    if not root.is_dir():
        raise InvalidValueError(f"runs={root} is a file, not a folder of runs")
    rows = []
    for config_file in sorted(root.rglob(CONFIG_FILE)):
        if any(part.startswith(".") for part in config_file.relative_to(root).parts[:-1]):
            continue  # Hydra's own .hydra/config.yaml in a multirun job's folder
        run = RunDirectory(config_file.parent)
        status = run.read_status()
        state = status.get("status", "not started")
        if state == "failed" and status.get("error"):
            state = f"failed: {status['error']}"
        best = status.get("best_train_return")
        attempts = run.read_attempts()
        # a run training again after its budget was raised still holds the earlier budget's evaluations
        final = [_success(run, regime) if state == "complete" else "—" for regime in REGIMES]
        rows.append(
            dict(
                zip(
                    COLUMNS,
                    (
                        str(run.path.relative_to(root)) or ".",
                        state,
                        _progress(status),
                        _attempts(attempts),
                        _costs(attempts),
                        "—" if best is None else f"{best:.1f}",
                        *final,
                    ),
                )
            )
        )
    return rows


def status_markdown(rows: Sequence[dict[str, str]]) -> str:
    """The rows as a Markdown table."""
    lines = ["| " + " | ".join(COLUMNS) + " |", "|" + "---|" * len(COLUMNS)]
    lines += ["| " + " | ".join(row[c] for c in COLUMNS) + " |" for row in rows]
    return "\n".join(lines)


def main(argv: Sequence[str] | None = None) -> None:
    args = parse_arguments("status", argv_or_sys(argv), OPTIONS, about=__doc__, example=EXAMPLE)
    with one_line_errors():
        rows = run_statuses(args["runs"])
    print(status_markdown(rows) if rows else f"no run directories below {args['runs']}")


if __name__ == "__main__":
    main()
