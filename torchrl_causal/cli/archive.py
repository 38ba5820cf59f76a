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
"""

from __future__ import annotations

import sys
from collections.abc import Sequence
from pathlib import Path

from omegaconf import OmegaConf

from torchrl_causal.evaluation.runs import archive_runs

__all__ = ["main"]

_USAGE = "usage: python -m torchrl_causal.archive runs=<dir> out=<dir> [policies=true]"


def main(argv: Sequence[str] | None = None) -> list[Path]:
    args = OmegaConf.from_cli(list(sys.argv[1:] if argv is None else argv))
    unknown = set(args) - {"runs", "out", "policies"}
    if unknown or not {"runs", "out"} <= set(args):
        raise SystemExit(_USAGE + (f"; unknown argument(s) {sorted(unknown)}" if unknown else ""))
    archived = archive_runs(args.runs, args.out, policies=bool(args.get("policies", False)))
    size = sum(path.stat().st_size for run in archived for path in run.rglob("*") if path.is_file())
    for run in archived:
        print(run)
    print(f"archived {len(archived)} run(s) below {args.out} ({size / 1e6:.1f} MB)")
    return archived


if __name__ == "__main__":
    main()
