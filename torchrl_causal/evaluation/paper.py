"""The paper's published figures: Table 1 and Appendix F at deployment, for its four tasks.

Tagor, Li & Bareinboim report, per task and row, the raw ``E[Y]`` (± its standard deviation
over episodes), the success rate (± its standard error) and the mean length of the successful
episodes (± std); Table 1 prints ``E[Y]`` shifted so that the task's worst row sits at 0
(:func:`paper_normalised_returns`). They trained 3 seeds per row and evaluated 1000 episodes
per task (100 on HumanoidMaze-Large). Where the paper's two tables disagree in the last digit,
the figures here are Appendix F's (C-IQ-Learn's AntMaze-Medium success SE: 1.15, Table 1 1.2).
One pair disagrees by more: HumanoidMaze-Large's C-BC, raw ``E[Y]`` -858.6 in Appendix F but
125.1 normalised in Table 1 (that is -851.9); its normalised value here is Appendix F's, 118.4.

Examples:
    >>> PAPER_TASKS["antmaze_medium"], PAPER_RESULTS["antmaze_medium"]["c_sqil"].success
    ('AntMaze-Medium', 90.7)
    >>> paper_normalised_returns("antmaze_large")["c_iq_learn"]  # Table 1: 225.6
    225.6
    >>> PAPER_RESULTS["humanoidmaze_large"]["gail"].length_mean is None  # no successful episode
    True
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

from torchrl_causal.errors import UnknownKeyError

__all__ = ["PAPER_EPISODES", "PAPER_RESULTS", "PAPER_SEEDS", "PAPER_TASKS", "PaperFigure", "paper_figure", "paper_normalised_returns"]

#: The paper's tasks, by the name of their env config, with their names in its tables.
PAPER_TASKS: Mapping[str, str] = {
    "antmaze_medium": "AntMaze-Medium",
    "antmaze_large": "AntMaze-Large",
    "humanoidmaze_medium": "HumanoidMaze-Medium",
    "humanoidmaze_large": "HumanoidMaze-Large",
}
#: Training seeds per row (Appendix E, "All tasks used 3 seeds").
PAPER_SEEDS = 3
#: Evaluation episodes per task (Appendix E, HumanoidMaze-Large 100, "the other tasks' 1000").
PAPER_EPISODES: Mapping[str, int] = {"antmaze_medium": 1000, "antmaze_large": 1000, "humanoidmaze_medium": 1000, "humanoidmaze_large": 100}


@dataclass(frozen=True)
class PaperFigure:
    """One row of one task at deployment, as published.

    Attributes:
        return_mean, return_std: raw ``E[Y]`` and its standard deviation over episodes.
        success, success_se: success rate and its standard error, in percent.
        length_mean, length_std: steps of the successful episodes; ``None`` where none succeeded.
    """

    return_mean: float
    return_std: float
    success: float
    success_se: float
    length_mean: float | None = None
    length_std: float | None = None


def _rows(*figures: tuple[float, float, float, float, float | None, float | None]) -> dict[str, PaperFigure]:
    # Table 1's row order: Expert, C-BC, C-GAIL, C-SQIL, C-IQ-Learn, BC, GAIL, SQIL, IQ-Learn.
    labels = ("expert", "c_bc", "c_gail", "c_sqil", "c_iq_learn", "bc", "gail", "sqil", "iq_learn")
    return {label: PaperFigure(*figure) for label, figure in zip(labels, figures, strict=True)}


#: The published figures by task, then by row label (Appendix F's tables ``tab:raw-results``
#: and ``tab:episode-lengths``).
PAPER_RESULTS: Mapping[str, Mapping[str, PaperFigure]] = {
    "antmaze_medium": _rows(
        (-104.0, 87.5, 87.6, 1.0, 301, 57),
        (-125.2, 100.9, 77.9, 1.3, 318, 79),
        (-135.8, 113.6, 74.1, 1.4, 309, 75),
        (-99.6, 85.7, 90.7, 0.9, 299, 62),
        (-118.2, 101.3, 84.3, 1.15, 321, 90),
        (-375.3, 119.2, 0.0, 0.0, None, None),
        (-364.9, 112.2, 0.0, 0.0, None, None),
        (-370.7, 119.1, 0.0, 0.0, None, None),
        (-372.5, 120.8, 0.0, 0.0, None, None),
    ),
    "antmaze_large": _rows(
        (-255.2, 122.8, 55.9, 1.6, 648, 99),
        (-284.9, 121.6, 39.8, 1.5, 683, 116),
        (-328.5, 122.6, 7.3, 0.8, 709, 134),
        (-279.9, 125.9, 45.0, 1.6, 695, 119),
        (-258.6, 127.9, 58.9, 1.6, 636, 108),
        (-470.2, 150.2, 0.0, 0.0, None, None),
        (-398.4, 132.9, 0.0, 0.0, None, None),
        (-484.2, 151.5, 0.0, 0.0, None, None),
        (-468.1, 153.5, 0.0, 0.0, None, None),
    ),
    "humanoidmaze_medium": _rows(
        (-522.9, 218.4, 33.8, 1.5, 976, 410),
        (-655.7, 172.7, 10.4, 1.0, 1356, 344),
        (-747.2, 161.9, 0.0, 0.0, None, None),
        (-555.5, 217.2, 24.7, 1.4, 912, 425),
        (-588.8, 203.8, 19.1, 1.2, 1024, 443),
        (-678.4, 169.1, 5.4, 0.7, 1364, 320),
        (-747.7, 162.5, 0.0, 0.0, None, None),
        (-706.2, 157.0, 0.1, 0.1, 1800, 0),
        (-697.6, 169.7, 2.4, 0.5, 1085, 396),
    ),
    "humanoidmaze_large": _rows(
        (-840.6, 212.9, 7.0, 0.8, 1463, 366),
        (-858.6, 227.9, 8.0, 2.7, 1477, 421),
        (-976.3, 210.2, 0.0, 0.0, None, None),
        (-837.7, 226.0, 8.0, 2.7, 1251, 316),
        (-887.1, 220.5, 3.0, 1.7, 1848, 84),
        (-884.1, 204.6, 5.0, 2.2, 1663, 237),
        (-977.0, 208.9, 0.0, 0.0, None, None),
        (-896.3, 194.9, 0.0, 0.0, None, None),
        (-906.2, 193.3, 0.0, 0.0, None, None),
    ),
}


def _task_rows(task: str) -> Mapping[str, PaperFigure]:
    if task not in PAPER_RESULTS:
        raise UnknownKeyError(f"the paper has no task {task!r}; its tasks: {', '.join(PAPER_RESULTS)}")
    return PAPER_RESULTS[task]


def paper_figure(task: str, label: str) -> PaperFigure:
    """The paper's figures of row ``label`` on ``task``.

    Raises:
        UnknownKeyError: the paper has no such task or row, named with the ones it has.
    """
    if label not in _task_rows(task):
        raise UnknownKeyError(f"the paper has no row {label!r} on {task}; its rows: {', '.join(PAPER_RESULTS[task])}")
    return PAPER_RESULTS[task][label]


def paper_normalised_returns(task: str) -> dict[str, float]:
    """Table 1's normalised ``E[Y]`` of ``task``: each raw ``E[Y]`` minus the task's worst
    (the paper shifts before it rounds, so a last digit may differ from its table by 0.1).

    Raises:
        UnknownKeyError: the paper has no such task.
    """
    rows = _task_rows(task)
    worst = min(figure.return_mean for figure in rows.values())
    return {label: round(figure.return_mean - worst, 1) for label, figure in rows.items()}
