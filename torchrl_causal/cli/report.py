"""Report of a folder of runs, or of several (``runs=[<dir>,<dir>]``, each run held by one):
``python -m torchrl_causal.report runs=<dir> [out=<dir>] [name=<str>] [command=<str>] [carried=<csv>]
[causal_fraction=<x>] [non_causal_fraction=<x>] [train_gap_points=<x>]``; or Table 1 for the
reader from committed reports: ``python -m torchrl_causal.report table1 spec=<yaml> [docs=<md>]
[readme=<md>]``.

Writes the paper's Table 1 layout, the raw and episode-length tables and the effect
checks as Markdown, the results CSV (one row per algorithm and regime) and PNG figures
(training curves, maze trajectories, ablations when the runs hold them). ``command=...``
records the command that regenerates the runs in the Markdown file (without it, the file's
earlier command is kept, as its notes are); ``carried=<name>_all.csv``
keeps an earlier report's rows for the algorithms whose runs are not below ``runs``; the
last three set the effect checks' thresholds (:class:`~torchrl_causal.evaluation.EffectTargets`,
whose defaults are 0.8, 0.2 and 10).

``table1`` reads a spec (:mod:`torchrl_causal.evaluation.table1`; the repository's is
``results/table1.yaml``) and prints Table 1 in the paper's layout and its one-table summary;
``docs=`` / ``readme=`` write them instead into those documents' generated blocks
(``<!-- table1: generated ... -->`` ... ``<!-- /table1 -->``, ``table1-summary`` for the
summary), leaving the rest of each document as it is. Every document is checked for its block
before any is written.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

from torchrl_causal.cli.arguments import Option, argv_or_sys, one_line_errors, parse_arguments
from torchrl_causal.errors import TorchRLCausalError
from torchrl_causal.evaluation.reporting import write_report
from torchrl_causal.evaluation.table1 import load_table1_spec, replace_block, table1_cells, table1_markdown, table1_summary_markdown
from torchrl_causal.evaluation.tables import EffectTargets
from torchrl_causal.experiment.run_directory import atomic_write_text

__all__ = ["OPTIONS", "TABLE1_OPTIONS", "main", "table1_main"]

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


TABLE1_OPTIONS: dict[str, Option] = {
    "spec": Option(str, placeholder="results/table1.yaml"),
    "docs": Option(str, None, placeholder="docs/results.md"),
    "readme": Option(str, None, placeholder="README.md"),
}
#: The generated block of each document ``table1`` writes: Table 1 in full, its summary.
TABLE1_BLOCKS = {"docs": "table1", "readme": "table1-summary"}


def table1_main(argv: Sequence[str]) -> None:
    """``report table1``: Table 1 and its summary from a spec, printed or written into documents."""
    args = parse_arguments("report table1", argv, TABLE1_OPTIONS)
    with one_line_errors(TorchRLCausalError):
        spec = load_table1_spec(args["spec"])
        cells = table1_cells(spec)
        blocks = {"docs": table1_markdown(spec, cells), "readme": table1_summary_markdown(spec, cells)}
        documents = {key: Path(args[key]) for key in TABLE1_BLOCKS if args[key] is not None}
        # Every document is read and checked before any is written: a missing block leaves all as they were.
        texts = {key: replace_block(path.read_text(), TABLE1_BLOCKS[key], blocks[key], str(path)) for key, path in documents.items()}
        for key, path in documents.items():
            atomic_write_text(path, texts[key])
    if not documents:
        print(blocks["docs"] + "\n\n" + blocks["readme"])
    else:
        print("wrote " + ", ".join(f"{path} ({TABLE1_BLOCKS[key]})" for key, path in documents.items()))


def main(argv: Sequence[str] | None = None) -> None:
    arguments = argv_or_sys(argv)
    if arguments[:1] == ["table1"]:
        table1_main(arguments[1:])
        return
    args = parse_arguments("report", arguments, OPTIONS, about=__doc__, example=EXAMPLE)
    targets = EffectTargets(**{key: args.pop(key) for key in TARGET_KEYS})
    with one_line_errors():
        report = write_report(
            args["runs"], args["out"], name=args["name"], command=args["command"], carried=args["carried"], targets=targets
        )
    print(report.markdown.read_text())
    print(f"wrote {report.markdown}, {report.csv}, {report.all_csv}" + "".join(f", {p}" for p in report.figures))


if __name__ == "__main__":
    main()
