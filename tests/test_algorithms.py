"""The registry of algorithms and table rows: names and headers round-trip, and the
tables, run labels and sweeps read it."""

from __future__ import annotations

import itertools

import pytest

from torchrl_causal.algorithms import ALGORITHMS, ROWS, TABLE1_ROWS, Row, algorithm
from torchrl_causal.evaluation.tables import TABLE1_ALGORITHMS, display_name, ordered_labels
from torchrl_causal.experiment.run_directory import run_label

ROW_VARIANTS = [
    Row(entry.name, causal, window_matched, drop)
    for entry, causal, window_matched, drop in itertools.product(ALGORITHMS, (False, True), (False, True), ((), ("X",), ("W", "X")))
    if entry.name != "expert" and not (causal and window_matched)
]


@pytest.mark.parametrize("row", ROW_VARIANTS, ids=lambda row: row.name)
def test_a_row_is_parsed_back_from_its_name_and_run_label_agrees(row: Row) -> None:
    assert Row.parse(row.name) == row
    assert run_label(row.algorithm, row.causal, row.window_matched, row.drop) == row.name
    assert display_name(row.name) == row.label


def test_headers_are_the_papers() -> None:
    # Table 1's headers as the paper prints them, and the two rows it lacks.
    assert [display_name(name) for name in TABLE1_ALGORITHMS] == [
        "Expert",
        "C-BC",
        "C-GAIL",
        "C-SQIL",
        "C-IQ-Learn",
        "BC",
        "GAIL",
        "SQIL",
        "IQ-Learn",
    ]
    assert [row.label for row in ROWS[len(TABLE1_ROWS) :]] == ["C-IQ-Learn (Garg et al.)", "SQIL (window-matched)"]
    assert display_name("c_bc_no-W-X") == "C-BC (no W, X)" and display_name("ppo") == "ppo"


def test_tables_order_the_registrys_rows_first() -> None:
    assert ordered_labels(["sqil_wm", "bc", "expert", "zz", "c_sqil"]) == ["expert", "c_sqil", "bc", "sqil_wm", "zz"]


def test_an_unknown_algorithm_is_refused_by_name() -> None:
    with pytest.raises(KeyError, match="'ppo'.*bc"):
        algorithm("ppo")
    assert Row.parse("c_expert") is None and len({row.name for row in ROWS}) == len(ROWS)
