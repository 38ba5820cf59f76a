"""The algorithms and the table rows made of them, in one registry.

An :class:`Algorithm` is an option of the ``algo`` config group; a :class:`Row` is one
line of a results table and one run directory per seed: an algorithm, causal or not, on
the causal window or the window-matched one, perhaps with variables dropped. Everything
that names, orders or selects them reads this module: run directories
(:func:`~torchrl_causal.experiment.run_directory.run_label`), the ``row`` config group
and the sweeps' row lists (``${rows:table1}``, registered with the other resolvers), the
config schema (which schema types an algorithm's config) and the tables' order and
column headers (:mod:`torchrl_causal.evaluation.tables`).

Examples:
    >>> [row.label for row in TABLE1_ROWS]
    ['Expert', 'C-BC', 'C-GAIL', 'C-SQIL', 'C-IQ-Learn', 'BC', 'GAIL', 'SQIL', 'IQ-Learn']
    >>> Row.parse("sqil_wm"), Row.parse("sqil_wm").label
    (Row(algorithm='sqil', causal=False, window_matched=True, drop=()), 'SQIL (window-matched)')
    >>> Row.parse("c_bc_no-X").label, Row.parse("ppo") is None
    ('C-BC (no X)', True)
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass

from torchrl_causal.errors import UnknownKeyError

__all__ = ["ALGORITHMS", "Algorithm", "ROWS", "ROW_SETS", "Row", "TABLE1_FAMILIES", "TABLE1_ROWS", "algorithm", "row_names"]


@dataclass(frozen=True)
class Algorithm:
    """An option of the ``algo`` config group.

    Attributes:
        name: the option (``conf/algo/<name>.yaml``) and its ``algo.name``.
        label: its name in tables, without the causal prefix.
        schema: the config schema that types it (a key of
            :data:`~torchrl_causal.experiment.schema.ALGO_SCHEMAS`).
        off_policy: whether it learns from a replay buffer of its own rollouts (the paper's
            claim that the causal window recovers the expert is made of these).
    """

    name: str
    label: str
    schema: str
    off_policy: bool = False


#: Every algorithm, in the paper's order (the expert first).
ALGORITHMS: tuple[Algorithm, ...] = (
    Algorithm("expert", "Expert", schema="expert"),
    Algorithm("bc", "BC", schema="bc"),
    Algorithm("gail", "GAIL", schema="gail"),
    Algorithm("sqil", "SQIL", schema="sqil", off_policy=True),
    Algorithm("iq_learn", "IQ-Learn", schema="iq_learn", off_policy=True),
    Algorithm("iq_learn_garg", "IQ-Learn (Garg et al.)", schema="iq_learn", off_policy=True),
)
_BY_NAME = {entry.name: entry for entry in ALGORITHMS}


def algorithm(name: str) -> Algorithm:
    """The registered algorithm called ``name``.

    Raises:
        KeyError: no algorithm has that name (the message lists those that do).
    """
    try:
        return _BY_NAME[name]
    except KeyError:
        raise UnknownKeyError(f"no algorithm is called {name!r}; the registered ones are {sorted(_BY_NAME)}") from None


@dataclass(frozen=True)
class Row:
    """One line of a results table: an algorithm, causal or not, on which window.

    Attributes:
        algorithm: an :class:`Algorithm`'s name.
        causal: whether it conditions on the adjustment window (ignored for the expert).
        window_matched: a non-causal baseline that sees every observed variable over the
            causal window's lags (``window=matched``).
        drop: variables left out of the window at every lag (an ablation).
    """

    algorithm: str
    causal: bool = False
    window_matched: bool = False
    drop: tuple[str, ...] = ()

    @property
    def name(self) -> str:
        """The row's label in run directories, CSVs and ``row=<name>``: ``c_sqil``, ``sqil_wm``, ``c_bc_no-X``."""
        if self.algorithm == "expert":
            return "expert"
        name = f"c_{self.algorithm}" if self.causal else self.algorithm
        name += "_wm" if self.window_matched else ""
        return f"{name}_no-{'-'.join(sorted(self.drop))}" if self.drop else name

    @property
    def label(self) -> str:
        """The row's column header, such as ``C-SQIL``, ``SQIL (window-matched)``, ``C-BC (no X)``."""
        label = algorithm(self.algorithm).label
        if self.causal and self.algorithm != "expert":
            label = f"C-{label}"
        if self.window_matched:
            label += " (window-matched)"
        return f"{label} (no {', '.join(self.drop)})" if self.drop else label

    @property
    def window(self) -> str:
        """The ``window`` config group's option the row trains on."""
        return "matched" if self.window_matched else "default"

    @classmethod
    def parse(cls, name: str) -> Row | None:
        """The row called ``name`` (inverse of :attr:`name`), or ``None`` if no registered
        algorithm makes it."""
        name, _, dropped = name.partition("_no-")
        causal, name = name.startswith("c_"), name.removeprefix("c_")
        window_matched, name = name.endswith("_wm"), name.removesuffix("_wm")
        if name not in _BY_NAME or (causal and name == "expert"):
            return None
        return cls(name, causal, window_matched, tuple(dropped.split("-")) if dropped else ())


#: The algorithm families the paper's Table 1 trains, in its order; each has a causal and a
#: non-causal row (the tables' effect checks and the figures' panels go by them).
TABLE1_FAMILIES: tuple[str, ...] = ("bc", "gail", "sqil", "iq_learn")

#: The paper's Table 1, in its order — the expert, the causal algorithms, the same non-causal.
TABLE1_ROWS: tuple[Row, ...] = (
    Row("expert"),
    *(Row(name, causal=True) for name in TABLE1_FAMILIES),
    *(Row(name) for name in TABLE1_FAMILIES),
)

#: Every row of the ``row`` config group: Table 1's, C-IQ-Learn with Garg et al.'s
#: objective, and the window-matched non-causal SQIL (neither in the paper).
ROWS: tuple[Row, ...] = (*TABLE1_ROWS, Row("iq_learn_garg", causal=True), Row("sqil", window_matched=True))

#: The row lists a sweep names with ``${rows:<set>}``.
ROW_SETS: dict[str, tuple[Row, ...]] = {"table1": TABLE1_ROWS, "all": ROWS}


def row_names(rows: Iterable[Row]) -> str:
    """``rows``' names as a sweep lists them: comma-separated.

    Examples:
        >>> row_names(ROWS[:3])
        'expert,c_bc,c_gail'
    """
    return ",".join(row.name for row in rows)
