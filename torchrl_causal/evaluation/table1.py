"""Table 1 for the reader, generated from committed reports and set beside the paper's.

A spec (YAML; the repository's is ``results/table1.yaml``) says, for each table and each of
the paper's four tasks, which report CSV (the ``<name>.csv`` that
:func:`~torchrl_causal.evaluation.write_report` writes) holds each row, and which folders of
archived runs that report was made from. :func:`table1_markdown` prints each table in the
paper's layout (one column per row label, per task the deployment success rate ± its standard
error, the raw ``E[Y]`` ± its standard deviation over episodes, and the seeds and episodes),
every cell beside the paper's figure; a row no source holds is "—", never filled in. A cell
whose figure the named runs do not pool back to (its run records were lost, or the report
carried it from an earlier one) is marked with :data:`NO_RECORD`'s footnote.
:func:`table1_summary_markdown` is the README's one-table summary of the first table.
:func:`replace_block` writes either into a document between ``<!-- NAME: generated ... -->``
and ``<!-- /NAME -->``, so that a test can regenerate both and compare.

The spec::

    root: ..                       # the folder every path below is written from (relative to the spec)
    command: python -m torchrl_causal.report table1 spec=results/table1.yaml docs=docs/results.md
    tables:
      - title: "Table 1: ..."
        legend: "What the table's configurations are (Markdown)."
        rows: [expert, c_bc, c_gail, c_sqil, c_iq_learn, bc, gail, sqil, iq_learn]
        tasks:
          antmaze_medium:
            - csv: results/antmaze_medium.csv
              runs: [results/runs/antmaze/antmaze_medium/h1000-cs1.0-k10]
              rows: [expert, c_bc]
              notes: {c_bc: "a footnote of this cell"}

Examples:
    >>> import pathlib, tempfile
    >>> folder = pathlib.Path(tempfile.mkdtemp())
    >>> _ = (folder / "r.csv").write_text(
    ...     "algorithm,regime,success_rate,success_se,return_mean,return_std,ep_len_mean,ep_len_std,n_episodes,seeds\\n"
    ...     "c_bc,deploy,0.5,0.05,-200.0,100.0,400.0,50.0,100,1\\n")
    >>> _ = (folder / "t.yaml").write_text(
    ...     "root: .\\ncommand: make table\\ntables:\\n  - title: T\\n    rows: [c_bc, bc]\\n"
    ...     "    tasks: {antmaze_large: [{csv: r.csv, rows: [c_bc]}]}\\n")
    >>> print(table1_summary_markdown(load_table1_spec(folder / "t.yaml")).splitlines()[3])
    | AntMaze-Large | 50.0* (39.8) | — (0.0) |
"""

from __future__ import annotations

import csv
import math
import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path

from omegaconf import DictConfig, ListConfig, OmegaConf

from torchrl_causal.errors import InvalidValueError, MissingFileError
from torchrl_causal.evaluation.metrics import EvaluationResult
from torchrl_causal.evaluation.paper import PAPER_EPISODES, PAPER_SEEDS, PAPER_TASKS, paper_figure
from torchrl_causal.evaluation.runs import load_runs
from torchrl_causal.evaluation.tables import TABLE1_ALGORITHMS, ReportedResult, aggregate, display_name

__all__ = [
    "NO_RECORD",
    "Cell",
    "Source",
    "Table1Spec",
    "TableSpec",
    "load_table1_spec",
    "read_block",
    "replace_block",
    "table1_cells",
    "table1_markdown",
    "table1_summary_markdown",
]

#: The footnote of a cell whose figure no archived run record pools back to.
NO_RECORD = "\\* no archived run record (carried from earlier reports, or the run was lost with a machine)."
REGIME = "deploy"  # Table 1 is the deployment regime's


@dataclass(frozen=True)
class Source:
    """One report CSV and the rows of one task it is the record of.

    Attributes:
        csv: the report's ``<name>.csv``, as the spec writes it (from the spec's root).
        rows: the row labels it gives this task.
        runs: the folders of archived runs the report was made from; a cell whose runs there
            pool to another figure (or are missing) is marked :data:`NO_RECORD`.
        notes: row label -> a footnote of that cell (a budget or demonstration set that
            differs from the table's legend).
    """

    csv: str
    rows: tuple[str, ...]
    runs: tuple[str, ...] = ()
    notes: Mapping[str, str] = field(default_factory=dict)


@dataclass(frozen=True)
class TableSpec:
    """One table: its title, legend, columns (row labels) and each task's sources."""

    title: str
    rows: tuple[str, ...]
    tasks: Mapping[str, tuple[Source, ...]]
    legend: str = ""


@dataclass(frozen=True)
class Table1Spec:
    """A whole spec: the folder its paths start from, its regenerating command, its tables."""

    root: Path
    command: str
    tables: tuple[TableSpec, ...]


@dataclass(frozen=True)
class Cell:
    """One task and row's figures at deployment, where they were read, and whether a record backs them."""

    result: ReportedResult
    source: Source
    recorded: bool


def _strings(value: object, where: str) -> tuple[str, ...]:
    items = list(value) if isinstance(value, (list, tuple, ListConfig)) else [value]
    strings = tuple(item for item in items if isinstance(item, str) and item)
    if not items or len(strings) != len(items):
        raise InvalidValueError(f"{where} must be a non-empty string or list of strings, got {value!r}")
    return strings


def _source(raw: object, where: str, columns: Sequence[str]) -> Source:
    if not isinstance(raw, DictConfig):
        raise InvalidValueError(f"{where} must be a mapping with csv, rows (and runs, notes), got {raw!r}")
    unknown = sorted(set(raw) - {"csv", "rows", "runs", "notes"})
    if unknown or "csv" not in raw or "rows" not in raw:
        raise InvalidValueError(f"{where} needs csv and rows (runs and notes optional); unknown keys: {unknown}")
    rows = _strings(raw.rows, f"{where}.rows")
    outside = [row for row in rows if row not in columns]
    if outside:
        raise InvalidValueError(f"{where}.rows names {outside}, which are not the table's rows {list(columns)}")
    notes = {str(key): str(value) for key, value in (raw.get("notes") or {}).items()}
    stray = sorted(set(notes) - set(rows))
    if stray:
        raise InvalidValueError(f"{where}.notes names {stray}, which this source does not give")
    runs = _strings(raw.runs, f"{where}.runs") if raw.get("runs") else ()
    return Source(csv=_strings(raw.csv, f"{where}.csv")[0], rows=rows, runs=runs, notes=notes)


def _table(raw: object, where: str) -> TableSpec:
    if not isinstance(raw, DictConfig) or "title" not in raw or "rows" not in raw or "tasks" not in raw:
        raise InvalidValueError(f"{where} must be a mapping with title, rows and tasks (legend optional)")
    unknown = sorted(set(raw) - {"title", "legend", "rows", "tasks"})
    if unknown:
        raise InvalidValueError(f"{where} has unknown key(s) {unknown}; a table has title, legend, rows and tasks")
    columns = _strings(raw.rows, f"{where}.rows")
    outside = [row for row in columns if row not in TABLE1_ALGORITHMS]
    if outside:
        raise InvalidValueError(f"{where}.rows names {outside}, which the paper has no figures for; its rows: {list(TABLE1_ALGORITHMS)}")
    tasks: dict[str, tuple[Source, ...]] = {}
    for task, sources in raw.tasks.items():
        if task not in PAPER_TASKS:
            raise InvalidValueError(f"{where}.tasks.{task}: not one of the paper's tasks ({', '.join(PAPER_TASKS)})")
        if not isinstance(sources, ListConfig):
            raise InvalidValueError(f"{where}.tasks.{task} must be a list of sources")
        parsed = tuple(_source(source, f"{where}.tasks.{task}[{index}]", columns) for index, source in enumerate(sources))
        given = [row for source in parsed for row in source.rows]
        twice = sorted({row for row in given if given.count(row) > 1})
        if twice:
            raise InvalidValueError(f"{where}.tasks.{task}: {twice} given by two sources; each cell has one record")
        tasks[str(task)] = parsed
    return TableSpec(title=str(raw.title), rows=columns, tasks=tasks, legend=str(raw.get("legend") or "").strip())


def load_table1_spec(path: str | Path) -> Table1Spec:
    """Reads and checks a spec; nothing is read but the spec itself.

    Raises:
        MissingFileError: ``path`` does not exist.
        InvalidValueError: a key is missing or unknown, a task or row is not the paper's, or
            a cell is given by two sources (each message names where).
    """
    path = Path(path)
    if not path.is_file():
        raise MissingFileError(f"table spec {path} does not exist")
    raw = OmegaConf.load(path)
    if not isinstance(raw, DictConfig) or not isinstance(raw.get("tables"), ListConfig) or not raw.tables:
        raise InvalidValueError(f"{path} must hold a non-empty list under tables:")
    unknown = sorted(set(raw) - {"root", "command", "tables"})
    if unknown:
        raise InvalidValueError(f"{path}: unknown key(s) {unknown}; a spec has root, command and tables")
    tables = tuple(_table(table, f"{path.name}: tables[{index}]") for index, table in enumerate(raw.tables))
    return Table1Spec(root=(path.parent / str(raw.get("root") or ".")).resolve(), command=str(raw.get("command") or ""), tables=tables)


def _deploy_rows(path: Path) -> dict[str, ReportedResult]:
    with path.open(newline="") as handle:
        return {row["algorithm"]: ReportedResult.from_row(row) for row in csv.DictReader(handle) if row["regime"] == REGIME}


def _pools_to(result: EvaluationResult, reported: ReportedResult) -> bool:
    return (
        result.n_episodes == reported.n_episodes
        and len(set(result.seeds)) == reported.seed_count
        and math.isclose(result.success_rate, reported.success_rate, rel_tol=0.0, abs_tol=1e-12)
        and math.isclose(result.return_mean, reported.return_mean, rel_tol=1e-9, abs_tol=1e-9)
    )


def table1_cells(spec: Table1Spec) -> list[dict[str, dict[str, Cell]]]:
    """For each table of ``spec``: task -> row label -> its :class:`Cell`, for the cells its
    sources give (each runs folder is read once, however many sources name it).

    Raises:
        MissingFileError: a source's CSV or runs folder does not exist.
        InvalidValueError: a source's CSV has no deployment row for a row it is said to give.
    """
    pooled: dict[tuple[str, ...], dict] = {}
    tables: list[dict[str, dict[str, Cell]]] = []
    for table in spec.tables:
        cells: dict[str, dict[str, Cell]] = {}
        for task, sources in table.tasks.items():
            cells[task] = {}
            for source in sources:
                path = spec.root / source.csv
                if not path.is_file():
                    raise MissingFileError(f"{source.csv} (a source of {task} in the table spec) does not exist")
                reported = _deploy_rows(path)
                lacking = [row for row in source.rows if row not in reported]
                if lacking:
                    raise InvalidValueError(
                        f"{source.csv} has no {REGIME} row for {lacking}, which the table spec reads from it for {task}"
                    )
                if source.runs not in pooled:
                    pooled[source.runs] = aggregate(load_runs([spec.root / runs for runs in source.runs])) if source.runs else {}
                for row in source.rows:
                    records = [
                        labels[row][REGIME]
                        for setting, labels in pooled[source.runs].items()
                        if setting.env == task and REGIME in labels.get(row, {})
                    ]
                    recorded = any(_pools_to(result, reported[row]) for result in records)
                    cells[task][row] = Cell(result=reported[row], source=source, recorded=recorded)
        tables.append(cells)
    return tables


def _number(value: float, digits: int = 1) -> str:
    return f"{value:.{digits}f}"


class _Notes:
    """Footnote letters in order of first use, one per distinct text."""

    def __init__(self) -> None:
        self.texts: list[str] = []

    def mark(self, text: str | None) -> str:
        if text is None:
            return ""
        if text not in self.texts:
            self.texts.append(text)
        return f"<sup>{chr(ord('a') + self.texts.index(text))}</sup>"

    def lines(self) -> list[str]:
        return [f"<sup>{chr(ord('a') + index)}</sup> {text}" for index, text in enumerate(self.texts)]


def _markdown_table(header: Sequence[str], rows: Sequence[Sequence[str]]) -> list[str]:
    return ["| " + " | ".join(header) + " |", "|" + "|".join("---" for _ in header) + "|"] + ["| " + " | ".join(row) + " |" for row in rows]


def _seeds_and_episodes(result: ReportedResult) -> str:
    seeds, episodes = result.seed_count, result.n_episodes
    return f"{seeds} × {episodes // seeds}" if seeds and episodes % seeds == 0 else f"{seeds} seeds, {episodes} episodes"


def _sources_line(table: TableSpec, task: str) -> str:
    read = "; ".join(f"`{source.csv}` ({', '.join(display_name(row) for row in source.rows)})" for source in table.tasks.get(task, ()))
    return f"- {PAPER_TASKS[task]}: {read or 'no report yet'}."


def table1_markdown(spec: Table1Spec, cells: Sequence[Mapping[str, Mapping[str, Cell]]] | None = None, heading: str = "###") -> str:
    """Every table of ``spec`` in the paper's layout, each with its legend, footnotes and the
    CSVs its cells were read from, ours beside the paper's figure in parentheses, then the
    spec's command; ``cells``: :func:`table1_cells` of ``spec``, read when not given."""
    cells_of = table1_cells(spec) if cells is None else cells
    blocks = []
    for table, table_cells in zip(spec.tables, cells_of, strict=True):
        notes, unrecorded = _Notes(), False
        body: list[list[str]] = []
        for task in PAPER_TASKS:
            success, returns, seeds = (
                [PAPER_TASKS[task], "success %"],
                ["", "raw E[Y]"],
                ["", f"seeds × episodes (paper: {PAPER_SEEDS} × {PAPER_EPISODES[task]})"],
            )
            for row in table.rows:
                paper = paper_figure(task, row)
                cell = table_cells.get(task, {}).get(row)
                if cell is None:
                    success.append(f"— ({_number(paper.success)})")
                    returns.append(f"— ({_number(paper.return_mean)})")
                    seeds.append("—")
                    continue
                unrecorded |= not cell.recorded
                mark = ("" if cell.recorded else "*") + notes.mark(cell.source.notes.get(row))
                r = cell.result
                success.append(f"{_number(100 * r.success_rate)} ± {_number(100 * r.success_se)}{mark} ({_number(paper.success)})")
                returns.append(f"{_number(r.return_mean)} ± {_number(r.return_std)}{mark} ({_number(paper.return_mean)})")
                seeds.append(_seeds_and_episodes(r))
            body += [success, returns, seeds]
        lines = [f"{heading} {table.title}", ""]
        lines += [table.legend, ""] if table.legend else []
        lines += _markdown_table(["task", ""] + [display_name(row) for row in table.rows], body)
        footnotes = ([NO_RECORD] if unrecorded else []) + notes.lines()
        for text in footnotes:
            lines += ["", text]
        lines += ["", "Read from:", ""] + [_sources_line(table, task) for task in PAPER_TASKS]
        blocks.append("\n".join(lines))
    command = f"\n\n```bash\n{spec.command}\n```" if spec.command else ""
    return "\n\n".join(blocks) + command


def table1_summary_markdown(spec: Table1Spec, cells: Sequence[Mapping[str, Mapping[str, Cell]]] | None = None) -> str:
    """The first table's deployment success rates, ours (paper's), one row per task, then the
    spec's command: the README's summary. A cell without a record keeps its ``*``; "—" is a
    row not run yet. ``cells``: :func:`table1_cells` of ``spec``, read when not given."""
    table = spec.tables[0]
    first = (table1_cells(spec) if cells is None else cells)[0]
    unrecorded = any(not cell.recorded for task_cells in first.values() for cell in task_cells.values())
    body = []
    for task in PAPER_TASKS:
        row_cells = [PAPER_TASKS[task]]
        for row in table.rows:
            paper, cell = paper_figure(task, row), first.get(task, {}).get(row)
            ours = "—" if cell is None else _number(100 * cell.result.success_rate) + ("" if cell.recorded else "*")
            row_cells.append(f"{ours} ({_number(paper.success)})")
        body.append(row_cells)
    lines = _markdown_table(["deploy success %, ours (paper)"] + [display_name(row) for row in table.rows], body)
    lines += ["", NO_RECORD] if unrecorded else []
    lines += ["", "```bash", spec.command, "```"] if spec.command else []
    return "\n".join(lines)


def _block_pattern(name: str) -> re.Pattern[str]:
    # The block is every line between its two marker lines (none when it is empty).
    return re.compile(rf"^<!-- {re.escape(name)}: generated[^\n]*-->\n(.*?)^<!-- /{re.escape(name)} -->$", flags=re.S | re.M)


def read_block(text: str, name: str) -> str | None:
    """The generated block ``name`` of a document's text (between its markers); ``None`` without one.

    Examples:
        >>> read_block("a\\n<!-- t: generated, do not edit -->\\n| x |\\n<!-- /t -->\\nb", "t")
        '| x |'
    """
    match = _block_pattern(name).search(text)
    return None if match is None else match.group(1).removesuffix("\n")


def replace_block(text: str, name: str, content: str, document: str = "the document") -> str:
    """``text`` with its generated block ``name`` replaced by ``content``.

    Raises:
        InvalidValueError: ``text`` has no such block (or two), named with the markers to add.

    Examples:
        >>> replace_block("<!-- t: generated -->\\n<!-- /t -->", "t", "new")
        '<!-- t: generated -->\\nnew\\n<!-- /t -->'
    """
    matches = list(_block_pattern(name).finditer(text))
    if len(matches) != 1:
        raise InvalidValueError(
            f"{document} has {len(matches)} blocks '{name}'; it needs exactly one, between "
            f"'<!-- {name}: generated ... -->' and '<!-- /{name} -->' on lines of their own"
        )
    match = matches[0]
    return text[: match.start(1)] + content + "\n" + text[match.end(1) :]
