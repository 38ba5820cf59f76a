"""The results tables of the README and ``docs/results.md`` against the results files they quote.

Every results table in those documents is preceded by ``<!-- figures: results/<file> -->``:

* a ``.csv`` (the report's layout): the table has a ``regime`` column and one column per
  algorithm (its display name); each ``train`` / ``deploy`` cell must equal the file's
  success rate in percent, to one decimal. Other rows (the paper's numbers) are not checked.
* a ``.md`` (the strength ablation's file): each README row must equal, cell for cell
  (the leading number, without its ``± SE``), the row of the same algorithm in the file's
  table with the same column headers.

Table 1 (the top of ``docs/results.md``) and its summary in the README are generated blocks:
regenerating them from ``results/table1.yaml`` and the reports it names must give the committed
text, cell for cell (``python -m torchrl_causal.report table1 ...`` rewrites them).

A figure that changes in ``results/`` without the documents following fails here; so does a
link of the README to a file that is not there.
"""

from __future__ import annotations

import csv
import re
from pathlib import Path

import pytest

from torchrl_causal.evaluation.table1 import load_table1_spec, read_block, table1_cells, table1_markdown, table1_summary_markdown
from torchrl_causal.evaluation.tables import REGIMES, display_name

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / "README.md"
#: The documents whose results tables quote ``results/``: the README's one table, the rest in docs.
DOCUMENTS = (README, ROOT / "docs" / "results.md")
#: Which reports Table 1 reads, and the command that regenerates its blocks.
TABLE1_SPEC = ROOT / "results" / "table1.yaml"
MARKER = re.compile(r"<!--\s*figures:\s*(\S+)\s*-->")

Table = list[list[str]]


def _cells(line: str) -> list[str]:
    return [cell.strip() for cell in line.strip().strip("|").split("|")]


def _is_separator(line: str) -> bool:
    return set(line.replace("|", "").strip()) <= {"-", ":", " "}


def markdown_tables(lines: list[str]) -> list[tuple[int, Table]]:
    """Each markdown table of ``lines`` as (index of its header line, header and body rows)."""
    tables, start = [], None
    for index, line in enumerate(lines + [""]):
        if line.lstrip().startswith("|"):
            start = index if start is None else start
            continue
        if start is not None:
            rows = [_cells(row) for row in lines[start:index] if not _is_separator(row)]
            tables.append((start, rows))
            start = None
    return tables


def marked_tables(text: str) -> list[tuple[str, Table]]:
    """(quoted file, table) for every table that directly follows a figures marker."""
    lines = text.splitlines()
    tables = dict(markdown_tables(lines))
    marked = []
    for index, line in enumerate(lines):
        match = MARKER.search(line)
        if match:
            following = next((i for i in range(index + 1, len(lines)) if lines[i].strip()), None)
            assert following in tables, f"line {index + 1}: the figures marker is not followed by a table"
            marked.append((match.group(1), tables[following]))
    return marked


def _leading_number(cell: str) -> str:
    match = re.match(r"\**\s*(-?\d+(?:\.\d+)?)", cell)
    assert match, f"not a figure: {cell!r}"
    return match.group(1)


def check_against_csv(table: Table, path: Path) -> int:
    """Asserts the table's regime rows equal the CSV's success rates; returns the cells checked."""
    with path.open() as handle:
        rates = {(row["algorithm"], row["regime"]): float(row["success_rate"]) for row in csv.DictReader(handle)}
    labels = {display_name(algorithm): algorithm for algorithm, _ in rates}
    header, checked = table[0], 0
    assert header[0] == "regime", f"{path.name}: a CSV-backed table starts with a 'regime' column, not {header[0]!r}"
    unknown = [name for name in header[1:] if name not in labels]
    assert not unknown, f"README columns {unknown} have no rows in {path.name}"
    for row in table[1:]:
        if row[0] not in REGIMES:
            continue
        for name, cell in zip(header[1:], row[1:]):
            expected = f"{100 * rates[(labels[name], row[0])]:.1f}"
            assert _leading_number(cell) == expected, f"README {name} / {row[0]}: {cell}, {path.name}: {expected}"
            checked += 1
    return checked


def check_against_markdown(table: Table, path: Path) -> int:
    """Asserts each row equals the same algorithm's row in the file's table with this header."""
    candidates = [rows for _, rows in markdown_tables(path.read_text().splitlines()) if rows[0][1:] == table[0][1:]]
    assert candidates, f"{path.name} has no table with the columns {table[0][1:]}"
    source = {row[0]: row[1:] for row in candidates[0][1:]}
    checked = 0
    for row in table[1:]:
        assert row[0] in source, f"README row {row[0]!r} is not in {path.name}"
        assert [_leading_number(c) for c in row[1:]] == [_leading_number(c) for c in source[row[0]]], (
            f"README row {row}, {path.name}: {source[row[0]]}"
        )
        checked += len(row) - 1
    return checked


def _figure_tables(document: Path) -> tuple[list[Table], list[Table]]:
    """The results tables of ``document`` (first column ``regime`` or ``strength``): all, and those without a marker."""
    lines = document.read_text().splitlines()
    marked_headers = {index for index, _ in markdown_tables(lines) if any(MARKER.search(line) for line in lines[max(0, index - 2) : index])}
    figures = [(index, rows) for index, rows in markdown_tables(lines) if rows[0][0] in ("regime", "strength")]
    return [rows for _, rows in figures], [rows for index, rows in figures if index not in marked_headers]


def test_every_results_table_is_marked() -> None:
    tables = {document.name: _figure_tables(document) for document in DOCUMENTS}
    assert len(tables["README.md"][0]) == 1, "the README shows one results table (the demo's); the rest are in docs"
    assert len(tables["results.md"][0]) >= 6, f"docs/results.md has {len(tables['results.md'][0])} results tables"
    unmarked = {name: [rows[0] for rows in tables[name][1]] for name in tables if tables[name][1]}
    assert not unmarked, f"results tables without a figures marker: {unmarked}"


def test_table1_is_regenerated_from_the_results() -> None:
    spec = load_table1_spec(TABLE1_SPEC)
    cells = table1_cells(spec)
    command = f"rerun `{spec.command}`"
    assert read_block(DOCUMENTS[1].read_text(), "table1") == table1_markdown(spec, cells), command
    assert read_block(README.read_text(), "table1-summary") == table1_summary_markdown(spec, cells), command
    assert DOCUMENTS[1].read_text().index("<!-- table1: generated") < DOCUMENTS[1].read_text().index("## Lab notebook"), (
        "docs/results.md opens with Table 1"
    )


def test_readme_links_resolve() -> None:
    targets = re.findall(r"\]\(([^)#]+)\)", README.read_text())
    assert "docs/results.md" in targets
    assert not [target for target in targets if "://" not in target and not (ROOT / target).exists()]


MARKED = [(document.name, quoted, table) for document in DOCUMENTS for quoted, table in marked_tables(document.read_text())]


@pytest.mark.parametrize("document, quoted, table", MARKED, ids=lambda x: str(x)[:40])
def test_readme_table_matches_its_results_file(document: str, quoted: str, table: Table) -> None:
    path = ROOT / quoted
    assert path.is_file(), f"{document} quotes {quoted}, which does not exist"
    check = check_against_csv if path.suffix == ".csv" else check_against_markdown
    assert check(table, path) > 0


def test_checks_catch_a_changed_figure(tmp_path: Path) -> None:
    results = tmp_path / "t.csv"
    results.write_text("algorithm,regime,success_rate\nc_sqil,train,0.4\nc_sqil,deploy,0.428\n")
    table = [["regime", "C-SQIL"], ["train", "40.0"], ["deploy", "42.8"], ["paper, deploy", "90.7"]]
    assert check_against_csv(table, results) == 2
    with pytest.raises(AssertionError, match="C-SQIL / deploy"):
        check_against_csv([table[0], ["deploy", "42.9"]], results)
    with pytest.raises(AssertionError, match="no rows"):
        check_against_csv([["regime", "SQIL"], ["train", "1.0"]], results)
    strength = tmp_path / "s.md"
    strength.write_text("| Algorithm | 0.15 | 0.5 |\n|---|---|---|\n| BC | 80.9 ± 1.2 | 0.0 ± 0.0 |\n")
    assert check_against_markdown([["strength", "0.15", "0.5"], ["BC", "80.9", "0.0"]], strength) == 2
    with pytest.raises(AssertionError, match="README row"):
        check_against_markdown([["strength", "0.15", "0.5"], ["BC", "80.0", "0.0"]], strength)
