"""Report of a folder of runs, or of several (``runs=[<dir>,<dir>]``, each run held by one):
``python -m torchrl_causal.report runs=<dir> [out=<dir>] [name=<str>] [command=<str>] [carried=<csv>]
[causal_fraction=<x>] [non_causal_fraction=<x>] [train_gap_points=<x>]``.

Writes the paper's Table 1 layout, the raw and episode-length tables and the effect
checks as Markdown, the results CSV (one row per algorithm and regime) and PNG figures
(training curves, maze trajectories, ablations when the runs hold them). ``command=...``
records the command that regenerates the runs in the Markdown file (without it, the file's
earlier command is kept, as its notes are); ``carried=<name>_all.csv``
keeps an earlier report's rows for the algorithms whose runs are not below ``runs``; the
last three set the effect checks' thresholds (:class:`~torchrl_causal.evaluation.EffectTargets`,
whose defaults are 0.8, 0.2 and 10).
"""

from __future__ import annotations

import sys
from collections.abc import Sequence

from omegaconf import OmegaConf

from torchrl_causal.evaluation.reporting import write_report
from torchrl_causal.evaluation.tables import EffectTargets


def main(argv: Sequence[str] | None = None) -> None:
    args = OmegaConf.from_cli(list(sys.argv[1:] if argv is None else argv))
    target_keys = ("causal_fraction", "non_causal_fraction", "train_gap_points")
    usage = "runs=<dir>|[<dir>,...] [out=<dir>] [name=<str>] [command=<str>] [carried=<csv>] " + " ".join(
        f"[{key}=<x>]" for key in target_keys)
    unknown = set(args) - {"runs", "out", "name", "command", "carried", *target_keys}
    if unknown:
        raise SystemExit(f"unknown argument(s) {sorted(unknown)}; expected {usage}")
    if "runs" not in args:
        raise SystemExit(f"usage: python -m torchrl_causal.report {usage}")
    try:
        targets = EffectTargets(**{key: args[key] for key in target_keys if key in args})
    except ValueError as error:
        raise SystemExit(str(error)) from error
    runs = list(args.runs) if OmegaConf.is_list(args.runs) else args.runs
    report = write_report(runs, args.get("out"), name=args.get("name"), command=args.get("command"),
                          carried=args.get("carried"), targets=targets)
    print(report.markdown.read_text())
    print(f"wrote {report.markdown}, {report.csv}, {report.all_csv}" + "".join(f", {p}" for p in report.figures))


if __name__ == "__main__":
    main()
