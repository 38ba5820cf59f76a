"""The run-directory layout and reading finished runs back for reports.

A run directory (``cfg.run_dir``) holds::

    config.yaml              the full resolved config of the run
    window.json              the adjustment window the policy was trained on
    status.json              {"status": "running" | "complete", counters, best evaluation}
    checkpoints/last.pt      full training state for resume (atomic: temp file + rename)
    checkpoints/best.pt      the policy with the best train-regime evaluation return
    logs/scalars/...csv      TorchRL CSVLogger scalars (``eval/train_return`` = training curve)
    eval/train.json          final evaluation of the best policy in each regime
    eval/deploy.json         (:class:`~torchrl_causal.evaluation.EvaluationResult` records)

:func:`load_runs` finds every run below a folder that has at least one final evaluation.
"""

from __future__ import annotations

import csv
import json
import math
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, NamedTuple

from omegaconf import OmegaConf

from torchrl_causal.evaluation.metrics import EvaluationResult

__all__ = [
    "CONFIG_FILE",
    "WINDOW_FILE",
    "STATUS_FILE",
    "EVAL_DIR",
    "LOG_DIR",
    "TRAIN_CURVE",
    "Setting",
    "RunRecord",
    "eval_path",
    "read_scalar_csv",
    "load_run",
    "load_runs",
    "mean_curve",
]

CONFIG_FILE = "config.yaml"
WINDOW_FILE = "window.json"
STATUS_FILE = "status.json"
EVAL_DIR = "eval"
LOG_DIR = "logs"
TRAIN_CURVE = "eval/train_return"  # scalar logged at every periodic train-regime evaluation


def eval_path(run_dir: str | Path, regime: str) -> Path:
    """Where the final evaluation of ``regime`` is stored."""
    return Path(run_dir) / EVAL_DIR / f"{regime}.json"


class Setting(NamedTuple):
    """What a table compares algorithms under: task, horizon, strength, window size."""

    env: str
    horizon: int
    strength: float
    k: int

    def describe(self) -> str:
        return f"{self.env} (H={self.horizon}, confounding strength={self.strength:g}, k={self.k})"


@dataclass(frozen=True)
class RunRecord:
    """One finished (or partly finished) run as the report sees it."""

    path: Path
    label: str
    setting: Setting
    seed: int
    evaluations: Mapping[str, EvaluationResult]
    curve: Sequence[tuple[int, float]] = ()
    unit: str = ""  # what the curve's steps count (env steps, epochs, rounds)
    maze: Mapping[str, Any] | None = field(default=None, compare=False)


def read_scalar_csv(path: str | Path) -> list[tuple[int, float]]:
    """``(step, value)`` rows of a CSVLogger scalar file, last write per step, step order.

    A resumed run may log a step again; the later value wins.

    Examples:
        >>> import tempfile, pathlib
        >>> p = pathlib.Path(tempfile.mkdtemp()) / "s.csv"
        >>> _ = p.write_text("0,1.0\\n10,2.0\\n10,3.0\\n")
        >>> read_scalar_csv(p)
        [(0, 1.0), (10, 3.0)]
    """
    by_step: dict[int, float] = {}
    with open(path, newline="") as handle:
        for row in csv.reader(handle):
            if len(row) >= 2:
                by_step[int(float(row[0]))] = float(row[1])
    return sorted(by_step.items())


def load_run(run_dir: str | Path) -> RunRecord:
    """Reads one run directory (its config, final evaluations and training curve)."""
    from torchrl_causal.trainers.config import run_label

    run_dir = Path(run_dir)
    config_file = run_dir / CONFIG_FILE
    if not config_file.is_file():
        raise FileNotFoundError(f"{run_dir} is not a run directory: {CONFIG_FILE} is missing")
    cfg = OmegaConf.load(config_file)
    for key in ("env.name", "env.horizon", "env.confounding_strength", "window.k", "algo.name", "causal", "seed"):
        if OmegaConf.select(cfg, key) is None:
            raise ValueError(f"{config_file} lacks the key {key!r}")
    evaluations: dict[str, EvaluationResult] = {}
    maze = None
    for path in (eval_path(run_dir, regime) for regime in ("train", "deploy")):
        if not path.is_file():
            continue
        data = json.loads(path.read_text())
        evaluations[data["regime"]] = EvaluationResult.from_dict(data)
        maze = data.get("maze", maze)
    curve_file = run_dir / LOG_DIR / "scalars" / f"{TRAIN_CURVE}.csv"
    status_file = run_dir / STATUS_FILE
    return RunRecord(
        path=run_dir,
        label=run_label(cfg.algo.name, bool(cfg.causal), bool(OmegaConf.select(cfg, "window.window_matched"))),
        setting=Setting(
            str(cfg.env.name), int(cfg.env.horizon), float(cfg.env.confounding_strength), int(cfg.window.k)
        ),
        seed=int(cfg.seed),
        evaluations=evaluations,
        curve=read_scalar_csv(curve_file) if curve_file.is_file() else (),
        unit=json.loads(status_file.read_text()).get("unit", "") if status_file.is_file() else "",
        maze=maze,
    )


def load_runs(root: str | Path) -> list[RunRecord]:
    """Every run below ``root`` with at least one final evaluation, in path order."""
    root = Path(root)
    if not root.exists():
        raise FileNotFoundError(f"runs folder {root} does not exist")
    runs = []
    for config_file in sorted(root.rglob(CONFIG_FILE)):
        if (config_file.parent / EVAL_DIR).is_dir():
            record = load_run(config_file.parent)
            if record.evaluations:
                runs.append(record)
    return runs


def mean_curve(curves: Iterable[Sequence[tuple[int, float]]]) -> list[tuple[int, float]]:
    """Pointwise mean over the steps every curve logged (seeds of one algorithm).

    Examples:
        >>> mean_curve([[(0, 1.0), (5, 3.0)], [(0, 3.0), (5, 5.0), (9, 0.0)]])
        [(0, 2.0), (5, 4.0)]
    """
    curves = [dict(c) for c in curves if c]
    if not curves:
        return []
    steps = sorted(set.intersection(*(set(c) for c in curves)))
    return [(s, math.fsum(c[s] for c in curves) / len(curves)) for s in steps]
