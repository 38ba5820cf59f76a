"""Report of a folder of runs:
``python -m torchrl_causal.report runs=<dir> [out=<dir>] [name=<str>] [command=<str>] [carried=<csv>]``.

Writes the paper's Table 1 layout, the raw and episode-length tables and the effect
checks as Markdown, the results CSV (one row per algorithm and regime) and PNG figures
(training curves, maze trajectories, ablations when the runs hold them). ``command=...``
records the command that regenerates the runs in the Markdown file (without it, the file's
earlier command is kept, as its notes are); ``carried=<name>_all.csv``
keeps an earlier report's rows for the algorithms whose runs are not below ``runs``.
"""

from __future__ import annotations

import sys
from collections.abc import Sequence

from omegaconf import OmegaConf

from torchrl_causal.evaluation.report import write_report


def main(argv: Sequence[str] | None = None) -> None:
    args = OmegaConf.from_cli(list(sys.argv[1:] if argv is None else argv))
    usage = "runs=<dir> [out=<dir>] [name=<str>] [command=<str>] [carried=<csv>]"
    unknown = set(args) - {"runs", "out", "name", "command", "carried"}
    if unknown:
        raise SystemExit(f"unknown argument(s) {sorted(unknown)}; expected {usage}")
    if "runs" not in args:
        raise SystemExit(f"usage: python -m torchrl_causal.report {usage}")
    report = write_report(args.runs, args.get("out"), name=args.get("name"), command=args.get("command"),
                          carried=args.get("carried"))
    print(report.markdown.read_text())
    print(f"wrote {report.markdown}, {report.csv}, {report.all_csv}" + "".join(f", {p}" for p in report.figures))


if __name__ == "__main__":
    main()
