"""Deployment evaluation, the paper's tables and the report's figures.

* :func:`evaluate_policy` runs batched episodes and returns an :class:`EvaluationResult`
  (success rate ± SE, raw E[Y] ± std, lengths of successful episodes);
* :func:`load_runs` reads run directories back; :func:`write_report` turns them into
  Table 1 (normalised E[Y]), the raw and episode-length tables, the results CSV and
  PNG figures;
* :mod:`~torchrl_causal.evaluation.paper` keeps the paper's published figures, and
  :mod:`~torchrl_causal.evaluation.table1` sets committed reports beside them as Table 1
  (``python -m torchrl_causal.report table1``).
"""

from torchrl_causal.evaluation.metrics import EvaluationResult, evaluate_policy
from torchrl_causal.evaluation.reporting import Report, write_report
from torchrl_causal.evaluation.runs import RunRecord, Setting, eval_path, load_run, load_runs
from torchrl_causal.evaluation.tables import (
    CSV_COLUMNS,
    TABLE1_ALGORITHMS,
    EffectTargets,
    aggregate,
    effect_checks,
    normalised_returns,
)

__all__ = [
    "CSV_COLUMNS",
    "EffectTargets",
    "EvaluationResult",
    "Report",
    "RunRecord",
    "Setting",
    "TABLE1_ALGORITHMS",
    "aggregate",
    "effect_checks",
    "eval_path",
    "evaluate_policy",
    "load_run",
    "load_runs",
    "normalised_returns",
    "write_report",
]
