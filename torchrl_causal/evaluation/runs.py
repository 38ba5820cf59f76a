"""Reading finished runs back for reports.

A run directory's layout is :class:`~torchrl_causal.experiment.RunDirectory`'s (config,
window, status, checkpoints, scalar logs, ``eval/train.json`` and ``eval/deploy.json``,
the final evaluation of the selected policy in each regime). :func:`load_runs` finds
every run below a folder that has at least one final evaluation; records that
``python -m torchrl_causal.evaluate`` wrote under other names are not part of it.
"""

from __future__ import annotations

import csv
import json
import logging
import math
from collections.abc import Iterable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, NamedTuple

from omegaconf import OmegaConf

from torchrl_causal.envs.base import REGIMES
from torchrl_causal.errors import InvalidValueError, MissingFileError
from torchrl_causal.evaluation.metrics import EvaluationResult
from torchrl_causal.experiment.run_directory import (
    CONFIG_FILE,
    CheckpointError,
    RunDirectory,
    atomic_save,
    atomic_write_text,
    check_copy_targets,
    copy_folders,
    run_label,
)

log = logging.getLogger(__name__)

__all__ = [
    "Setting",
    "RunRecord",
    "eval_path",
    "read_scalar_csv",
    "load_run",
    "load_runs",
    "archive_runs",
    "copy_selected_policy",
    "POLICY_CHECKPOINT_KEYS",
    "mean_curve",
    "seed_band",
]


def eval_path(run_dir: str | Path, regime: str) -> Path:
    """Where the final evaluation of ``regime`` is stored."""
    return RunDirectory(run_dir).eval_path(regime)


class Setting(NamedTuple):
    """What a table compares algorithms under: task, horizon, strength, window size, and the
    deployment shift (``env.shift``: runs of the P(U) shift never pool with the rotation's).

    Examples:
        >>> Setting("antmaze_medium", 1000, 1.0, 10).describe()
        'antmaze_medium (H=1000, confounding strength=1, k=10)'
        >>> Setting("antmaze_medium", 1000, 1.0, 10, "prior").describe()
        'antmaze_medium (H=1000, confounding strength=1, k=10, shift=prior)'
    """

    env: str
    horizon: int
    strength: float
    k: int
    shift: str = "rotation"

    def describe(self) -> str:
        shift = "" if self.shift == "rotation" else f", shift={self.shift}"
        return f"{self.env} (H={self.horizon}, confounding strength={self.strength:g}, k={self.k}{shift})"


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
    #: the periodic evaluations' success rate per regime (``"train"``; ``"deploy"`` where recorded)
    success_curves: Mapping[str, Sequence[tuple[int, float]]] = field(default_factory=dict)
    maze: Mapping[str, Any] | None = field(default=None, compare=False)
    #: what each attempt trained under (``code.json``: code, packages, CPU, threads); empty
    #: for a run recorded before attempts were
    attempts: Sequence[Mapping[str, Any]] = field(default=(), compare=False)


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
    run = RunDirectory(run_dir)
    cfg = run.read_config()
    for key in ("env.name", "env.horizon", "env.confounding_strength", "window.k", "algo.name", "causal", "seed"):
        if OmegaConf.select(cfg, key) is None:
            raise InvalidValueError(f"{run.config_file} lacks the key {key!r}")
    evaluations: dict[str, EvaluationResult] = {}
    maze = None
    for path in (run.eval_path(regime) for regime in REGIMES):
        if not path.is_file():
            continue
        data = run.read_json(path)
        evaluations[data["regime"]] = EvaluationResult.from_dict(data)
        maze = data.get("maze", maze)
    curve_file = run.train_curve_file
    return RunRecord(
        path=run.path,
        label=run_label(
            cfg.algo.name,
            bool(cfg.causal),
            bool(OmegaConf.select(cfg, "window.window_matched")),
            OmegaConf.select(cfg, "window.drop", default=[]),
        ),
        setting=Setting(
            str(cfg.env.name),
            int(cfg.env.horizon),
            float(cfg.env.confounding_strength),
            int(cfg.window.k),
            str(OmegaConf.select(cfg, "env.shift") or "rotation"),  # runs made before the option: the rotation
        ),
        seed=int(cfg.seed),
        evaluations=evaluations,
        curve=read_scalar_csv(curve_file) if curve_file.is_file() else (),
        success_curves={
            regime: read_scalar_csv(run.success_curve_file(regime)) for regime in REGIMES if run.success_curve_file(regime).is_file()
        },
        unit=run.read_status().get("unit", ""),
        maze=maze,
        attempts=tuple(run.read_attempts()),
    )


def load_runs(roots: str | Path | Iterable[str | Path]) -> list[RunRecord]:
    """Every complete run below ``roots`` (one folder or several) with at least one final
    evaluation, in path order.

    A run directory whose final evaluations are there but whose status is not
    ``"complete"`` is left out, with a warning naming it: its budget was raised and it is
    training again (or that attempt stopped), so its evaluations belong to the earlier
    budget and would be reported as the new one's.

    Two runs of the same label, setting and seed are refused with a ``ValueError`` naming
    both: a report would pool them as two seeds. They come from a folder above two run
    roots (``runs/`` holding a Table-1 root and an ablation's, say) or from two roots that
    both hold the run; point the report at the roots that hold each run once.
    """
    folders = [Path(roots)] if isinstance(roots, (str, Path)) else [Path(root) for root in roots]
    if not folders:
        raise InvalidValueError("load_runs needs at least one runs folder")
    records: list[RunRecord] = []
    first_path: dict[tuple[Setting, str, int], Path] = {}
    for folder in folders:
        if not folder.exists():
            raise MissingFileError(f"runs folder {folder} does not exist")
        for run in _complete_runs(folder):
            record = load_run(run.path)
            key = (record.setting, record.label, record.seed)
            if key in first_path:
                raise InvalidValueError(
                    f"{first_path[key]} and {record.path} are both {record.label} seed {record.seed} "
                    f"on {record.setting.describe()}: a report would pool them as two seeds; "
                    "point runs= at the run roots that hold each run once"
                )
            first_path[key] = record.path
            records.append(record)
    return records


def _complete_runs(root: Path) -> Iterator[RunDirectory]:
    """The runs below ``root`` with a final evaluation whose status is ``"complete"``;
    every other evaluated run is named in a warning."""
    for config_file in sorted(root.rglob(CONFIG_FILE)):
        run = RunDirectory(config_file.parent)
        if not any(run.eval_path(regime).is_file() for regime in REGIMES):
            continue
        status = run.read_status()
        if status.get("status") != "complete":
            log.warning(
                "left out %s: it is %s (%s of %s %s), so its evaluations are from an earlier budget",
                run.path,
                status.get("status", "without a status"),
                status.get("progress", "?"),
                status.get("total", "?"),
                status.get("unit", "steps"),
            )
            continue
        yield run


#: What a selected-policy checkpoint (``checkpoints/best.pt``) holds: the actor's weights and
#: where they were selected; no critic, optimiser or replay state. ``train_success`` joined
#: with best-checkpoint selection by success: checkpoints written before it lack it;
#: ``val_loss`` is BC's when it selects by validation loss (``algo.select_by_val_loss``).
POLICY_CHECKPOINT_KEYS = frozenset({"progress", "train_return", "policy"})
POLICY_CHECKPOINT_OPTIONAL_KEYS = frozenset({"train_success", "val_loss"})


def copy_selected_policy(run: RunDirectory, target: RunDirectory) -> list[Path]:
    """Copies ``run``'s selected policy (``checkpoints/best.pt``) to ``target``, checking that it
    holds the actor's weights only, with its identity (``checkpoints/best.json``: the digests of
    its weights, config and window; the run's own, else computed from the run as it is), and
    returns the two copies' paths.

    Raises:
        CheckpointError: the run has no selected policy, its checkpoint holds more, or its
            files differ from the digests it recorded.
    """
    state = run.load_checkpoint(best=True)
    if state is None:
        raise CheckpointError(f"run {run.path} has no checkpoints/best.pt to ship")
    if not POLICY_CHECKPOINT_KEYS <= set(state) <= POLICY_CHECKPOINT_KEYS | POLICY_CHECKPOINT_OPTIONAL_KEYS:
        raise CheckpointError(
            f"{run.best_checkpoint} holds {sorted(state)}, not the selected policy alone ({sorted(POLICY_CHECKPOINT_KEYS)})"
        )
    run.check_policy_identity(state["policy"])
    identity = run.read_json(run.policy_identity_file) if run.policy_identity_file.is_file() else run.policy_identity(state["policy"])
    target.best_checkpoint.parent.mkdir(parents=True, exist_ok=True)
    atomic_save(state, target.best_checkpoint)
    target.write_json(target.policy_identity_file, identity)
    return [target.best_checkpoint, target.policy_identity_file]


def _is_evaluation_record(path: Path) -> bool:
    """Whether ``path`` is an evaluation record (a JSON object with a ``regime``), not a file
    of another kind that someone put in ``eval/``."""
    try:
        record = json.loads(path.read_text())
    except (OSError, ValueError):
        return False
    return isinstance(record, dict) and "regime" in record


def archive_runs(root: str | Path, out: str | Path, *, policies: bool = False) -> list[Path]:
    """Copies the record of every complete run below ``root`` to the same relative path
    below ``out`` and returns the archived run directories.

    A record (:meth:`~torchrl_causal.experiment.RunDirectory.record_files`: config, window,
    status, evaluation records, the periodic evaluations' curves) is what :func:`load_runs`, the report and
    the strength ablation's stored evaluations read back; at well under a megabyte per
    run it can be committed, so that a report is regenerated where the runs themselves
    (checkpoints, replay data) are gone. Archiving several machines' runs into one
    ``out`` builds one table: an archived run's record is replaced as a whole by its newer
    one (a file the newer run lacks, such as an evaluation at a setting it was not
    evaluated at, belonged to an earlier run and is removed), every other run already in
    ``out`` is kept. Evaluating at settings no record holds
    needs the original run directory (its ``checkpoints/best.pt``), or an archive made with
    ``policies=True``: it also copies each run's selected policy (the actor's weights only,
    under a megabyte at ``scale=cpu_ant``), so that
    ``python -m torchrl_causal.evaluate run_dir=<archived run>`` evaluates it as it is.

    Raises:
        FileNotFoundError: ``root`` does not exist.
        ValueError: one of ``root`` and ``out`` lies inside the other.

    Examples:
        >>> import tempfile, pathlib
        >>> from torchrl_causal.experiment import RunDirectory
        >>> root, out = (pathlib.Path(tempfile.mkdtemp()) for _ in range(2))
        >>> run = RunDirectory(root / "rovermaze_medium/h1000-cs1.0-k10/c_sqil/seed0")
        >>> run.path.mkdir(parents=True)
        >>> _ = run.config_file.write_text("seed: 0")
        >>> run.write_status("complete", progress=150000, total=150000, unit="env steps")
        >>> run.write_json(run.eval_path("deploy"), {"regime": "deploy"})
        >>> [str(p.relative_to(out)) for p in archive_runs(root, out)]
        ['rovermaze_medium/h1000-cs1.0-k10/c_sqil/seed0']
        >>> sorted(str(p.relative_to(out)) for p in out.rglob("*") if p.is_file())
        ['rovermaze_medium/h1000-cs1.0-k10/c_sqil/seed0/config.yaml',
         'rovermaze_medium/h1000-cs1.0-k10/c_sqil/seed0/eval/deploy.json',
         'rovermaze_medium/h1000-cs1.0-k10/c_sqil/seed0/status.json']
    """
    root, out = copy_folders(root, out)
    runs = list(_complete_runs(root))
    check_copy_targets([out / run.path.relative_to(root) for run in runs])  # before the first file is written
    archived = []
    for run in runs:
        target = RunDirectory(out / run.path.relative_to(root))
        record = {path.relative_to(run.path) for path in run.record_files()}
        for relative in sorted(record):
            destination = target.path / relative
            destination.parent.mkdir(parents=True, exist_ok=True)
            atomic_write_text(destination, (run.path / relative).read_text())
        if policies:
            record |= {path.relative_to(target.path) for path in copy_selected_policy(run, target)}
        # What only an earlier run of this directory recorded (its other evaluations): only the
        # files an archive writes are candidates; anything else found there is left alone.
        written = [*target.record_files(), target.best_checkpoint, target.policy_identity_file]
        for stale in [path for path in written if path.is_file() and path.relative_to(target.path) not in record]:
            if stale.parent.name != "eval" or _is_evaluation_record(stale):
                stale.unlink()
        archived.append(target.path)
    return archived


def mean_curve(curves: Iterable[Sequence[tuple[int, float]]]) -> list[tuple[int, float]]:
    """Pointwise mean over the steps every curve logged (seeds of one algorithm).

    Examples:
        >>> mean_curve([[(0, 1.0), (5, 3.0)], [(0, 3.0), (5, 5.0), (9, 0.0)]])
        [(0, 2.0), (5, 4.0)]
    """
    return [(step, mean) for step, mean, _, _ in seed_band(curves)]


def seed_band(curves: Iterable[Sequence[tuple[int, float]]]) -> list[tuple[int, float, float, float]]:
    """``(step, mean, min, max)`` over the seeds' curves at the steps every curve logged: the
    mean and the min-max band a seed-band figure draws.

    Examples:
        >>> seed_band([[(0, 0.2), (5, 0.6)], [(0, 0.4), (5, 1.0), (9, 1.0)]])
        [(0, 0.30000000000000004, 0.2, 0.4), (5, 0.8, 0.6, 1.0)]
    """
    by_step = [dict(c) for c in curves if c]
    if not by_step:
        return []
    steps = sorted(set.intersection(*(set(c) for c in by_step)))
    return [(s, math.fsum(c[s] for c in by_step) / len(by_step), min(c[s] for c in by_step), max(c[s] for c in by_step)) for s in steps]
