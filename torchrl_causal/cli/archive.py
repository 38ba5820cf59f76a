"""Copies the records of finished runs where they can be committed:
``python -m torchrl_causal.archive runs=<dir> out=<dir>``.

Run directories hold checkpoints and replay data (gigabytes, ignored by git) beside the
few files a report reads. This command copies those files of every complete run below
``runs`` to the same relative path below ``out`` (see
:func:`~torchrl_causal.evaluation.runs.archive_runs`), so that
``python -m torchrl_causal.report runs=<out>/...`` and the strength ablation's stored
evaluations regenerate the results on a machine where the runs are gone. The shipped
records live in ``results/runs/``: ``run_root=runs/table3`` archives with
``out=results/runs/table3``. With ``policies=true`` each run's selected policy (the actor's
weights, ``checkpoints/best.pt``) is copied too: the shipped policies in ``results/policies/``
are such archives, which ``python -m torchrl_causal.evaluate run_dir=<archived run>`` evaluates.

With ``carry=true`` it copies instead every run that has a checkpoint, finished or not, whole
but for its replay buffer (:func:`~torchrl_causal.experiment.run_directory.carry_runs`): what continues
the run on another machine, where the same ``train`` command resumes it after the runs are
copied back below its ``run_root``.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

from torchrl_causal.cli.arguments import Option, argv_or_sys, one_line_errors, parse_arguments
from torchrl_causal.errors import InvalidValueError
from torchrl_causal.evaluation.runs import archive_runs
from torchrl_causal.experiment.run_directory import carry_runs

__all__ = ["OPTIONS", "main"]

OPTIONS: dict[str, Option] = {
    "runs": Option(str, placeholder="<dir>", help="the folder of runs to archive"),
    "out": Option(str, placeholder="<dir>", help="where the archive goes (the same relative paths)"),
    "policies": Option(bool, False, help="copy each run's selected policy too"),
    "carry": Option(bool, False, help="copy every run with a checkpoint, whole but for its replay buffer"),
}
EXAMPLE = "python -m torchrl_causal.archive runs=runs/table3 out=results/runs/table3"


def main(argv: Sequence[str] | None = None) -> list[Path]:
    args = parse_arguments("archive", argv_or_sys(argv), OPTIONS, about=__doc__, example=EXAMPLE)
    with one_line_errors():
        if args["carry"] and args["policies"]:
            raise InvalidValueError("carry=true copies every checkpoint already; leave out policies=true")
        archived = (
            carry_runs(args["runs"], args["out"]) if args["carry"] else archive_runs(args["runs"], args["out"], policies=args["policies"])
        )
    size = sum(path.stat().st_size for run in archived for path in run.rglob("*") if path.is_file())
    for run in archived:
        print(run)
    print(f"{'carried' if args['carry'] else 'archived'} {len(archived)} run(s) below {args['out']} ({size / 1e6:.1f} MB)")
    return archived


if __name__ == "__main__":
    main()
