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

from collections.abc import Sequence

from torchrl_causal.cli.arguments import Option, argv_or_sys, one_line_errors, parse_arguments
from torchrl_causal.evaluation.reporting import write_report
from torchrl_causal.evaluation.tables import EffectTargets

__all__ = ["OPTIONS", "main"]

TARGET_KEYS = ("causal_fraction", "non_causal_fraction", "train_gap_points")
OPTIONS: dict[str, Option] = {
    "runs": Option(list, placeholder="<dir>|[<dir>,...]", help="the folder(s) of runs to report"),
    "out": Option(str, None, placeholder="<runs>/report", help="where the report is written"),
    "name": Option(str, None, placeholder="<env name>", help="the report's file name"),
    "command": Option(str, None, placeholder="<the file's earlier command>", help="the command recorded as regenerating the runs"),
    "carried": Option(str, None, placeholder="<name>_all.csv", help="an earlier report's rows kept for algorithms not below runs"),
    "causal_fraction": Option(float, EffectTargets.causal_fraction, ge=0.0, le=1.0, help="effect check threshold"),
    "non_causal_fraction": Option(float, EffectTargets.non_causal_fraction, ge=0.0, le=1.0, help="effect check threshold"),
    "train_gap_points": Option(float, EffectTargets.train_gap_points, ge=0.0, help="effect check threshold"),
}
EXAMPLE = "python -m torchrl_causal.report runs=runs/rovermaze_u out=runs/rovermaze_u/report"


def main(argv: Sequence[str] | None = None) -> None:
    args = parse_arguments("report", argv_or_sys(argv), OPTIONS, about=__doc__, example=EXAMPLE)
    targets = EffectTargets(**{key: args.pop(key) for key in TARGET_KEYS})
    with one_line_errors():
        report = write_report(
            args["runs"], args["out"], name=args["name"], command=args["command"], carried=args["carried"], targets=targets
        )
    print(report.markdown.read_text())
    print(f"wrote {report.markdown}, {report.csv}, {report.all_csv}" + "".join(f", {p}" for p in report.figures))


if __name__ == "__main__":
    main()
