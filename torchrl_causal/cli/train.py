"""Hydra entry point: ``python -m torchrl_causal.train env=<name> algo=<bc|gail|sqil|iq_learn|expert>
causal=<bool> window.k=<int> seed=<int> [env.horizon=...] [env.confounding_strength=...]``.

The config tree is ``configs/`` next to the package (see ``configs/config.yaml``), typed
by :mod:`torchrl_causal.trainers.schema`: a bad value stops the command before a run
directory exists. ``scale=paper`` selects Appendix E's networks and budgets,
``scale=cpu`` (default) a 2-core budget. Sweeps:
``python -m torchrl_causal.train -m experiment=paper_table``.

A run directory belongs to one config (a changed config is refused, naming the changed
keys) and to one process at a time (a second one is refused, naming the first);
rerunning the same command resumes an unfinished run from its last checkpoint and
returns a finished run's stored evaluations. Ctrl-C (SIGINT) or SIGTERM finishes
the training step in flight, checkpoints, marks the run interrupted and prints the
command that resumes it.
"""

from __future__ import annotations

import logging
import shutil
import sys
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import hydra
import torch
from hydra.core.hydra_config import HydraConfig
from hydra.utils import get_class
from omegaconf import DictConfig

from torchrl_causal.evaluation.evaluator import Evaluator
from torchrl_causal.evaluation.metrics import EvaluationResult
from torchrl_causal.trainers import (
    ConfigMismatchError,
    ConfigValueError,
    RunDirectory,
    RunInterrupted,
    RunInUseError,
    Trainer,
    validate_config,
)
from torchrl_causal.trainers.builders import make_window
from torchrl_causal.trainers.config import CONFIG_DIR, CONFIG_NAME, register_resolvers
from torchrl_causal.trainers.interrupts import signals_raise

__all__ = ["main", "run"]

log = logging.getLogger("torchrl_causal")

register_resolvers()

REGIMES = ("train", "deploy")


@contextmanager
def _run_log(run: RunDirectory) -> Iterator[None]:
    """Copies the package's log records (INFO and up) to ``<run_dir>/train.log``."""
    handler = logging.FileHandler(run.train_log)
    handler.setFormatter(logging.Formatter("[%(asctime)s][%(name)s][%(levelname)s] %(message)s"))
    level = log.level
    log.addHandler(handler)
    if log.getEffectiveLevel() > logging.INFO:
        log.setLevel(logging.INFO)
    try:
        yield
    finally:
        log.removeHandler(handler)
        log.setLevel(level)
        handler.close()


def _first_missing(path: Path) -> Path | None:
    """The outermost folder of ``path`` that does not exist yet (``None``: it exists)."""
    missing = None
    for folder in (path, *path.parents):
        if folder.exists():
            break
        missing = folder
    return missing


def _stored_results(run: RunDirectory) -> dict[str, EvaluationResult]:
    return {regime: EvaluationResult.from_dict(run.read_json(run.eval_path(regime)))
            for regime in REGIMES if run.eval_path(regime).is_file()}


def run(cfg: DictConfig) -> dict[str, EvaluationResult]:
    """Trains, selects and evaluates one run of ``cfg``; returns the final evaluation of
    the selected policy in each regime (written to ``eval/<regime>.json``).

    Raises:
        ConfigValueError: a value out of range (nothing is written).
        ConfigMismatchError: ``cfg.run_dir`` holds a run of another config (nothing is written).
        RunInUseError: another process is running ``cfg.run_dir`` (nothing is written).
        RunInterrupted: on SIGINT/SIGTERM, after checkpointing and marking the run interrupted.
    """
    validate_config(cfg)
    trainer_class: type[Trainer] | None = get_class(cfg.algo.trainer) if cfg.algo.trainer else None
    total = trainer_class.budget(cfg) if trainer_class else 0
    run_dir = RunDirectory(cfg.run_dir)
    created = _first_missing(run_dir.path)  # what a failure before any checkpoint removes
    killed = run_dir.read_status().get("status") == "killed"
    with run_dir.lock():
        if killed and cfg.resume:
            log.warning("%s: its last attempt was killed before it could record its stop; resuming from its last "
                        "checkpoint", run_dir.path)
        if not cfg.resume:
            run_dir.discard()
            created = created or run_dir.path
        return _claim_and_run(cfg, run_dir, trainer_class, total, created)


def _claim_and_run(cfg: DictConfig, run_dir: RunDirectory, trainer_class: type[Trainer] | None, total: int,
                   created: Path | None) -> dict[str, EvaluationResult]:
    extendable = trainer_class is not None and trainer_class.extendable_budget(cfg)
    run_dir.claim(cfg, ignored=(trainer_class.budget_key,) if extendable else ())
    status = run_dir.read_status()
    if status.get("status") == "complete" and status.get("total") == total:
        log.info("%s is complete: its stored evaluations are returned", run_dir.path)
        return _stored_results(run_dir)
    with _run_log(run_dir), signals_raise():
        try:
            return _train_and_evaluate(cfg, run_dir, trainer_class, total)
        except RunInterrupted:
            if run_dir.read_status().get("status") != "interrupted":  # stopped outside the training loop
                run_dir.update_status("interrupted")
            raise
        except Exception as error:
            if created is not None and not run_dir.last_checkpoint.is_file():
                shutil.rmtree(created, ignore_errors=True)  # leave no half-made run directory behind
            else:
                run_dir.update_status("failed", error=f"{type(error).__name__}: {error}")
            raise


def _train_and_evaluate(cfg: DictConfig, run_dir: RunDirectory, trainer_class: type[Trainer] | None,
                        total: int) -> dict[str, EvaluationResult]:
    torch.manual_seed(cfg.seed)
    torch.set_num_threads(cfg.threads)
    window = make_window(cfg) if trainer_class else None
    evaluator = Evaluator(cfg, window, progress=cfg.progress_bar)
    policy = None  # the env's expert
    if trainer_class is not None:
        run_dir.write_json(run_dir.window_file, window.to_dict())
        trainer = trainer_class(cfg, run_dir, window, evaluator.periodic)
        trainer.fit()
        policy = trainer.best_policy()
    results = evaluator.final(policy)
    for regime, result in results.items():
        run_dir.write_json(run_dir.eval_path(regime), evaluator.record(result))
        log.info("%s [%s] success %.1f%% ± %.1f, E[Y] %.1f ± %.1f, episodes %d", cfg.run_dir, regime,
                 100 * result.success_rate, 100 * result.success_se, result.return_mean, result.return_std,
                 result.n_episodes)
    run_dir.update_status("complete", total=total, progress=total if trainer_class is None else trainer.progress)
    if trainer_class is not None:
        trainer.finish()
    return results


@hydra.main(config_path=str(CONFIG_DIR), config_name=CONFIG_NAME, version_base="1.3")
def main(cfg: DictConfig) -> float:
    """Runs one job; returns its deploy-regime success rate (what a sweeper would optimise)."""
    try:
        results = run(cfg)
    except (ConfigValueError, ConfigMismatchError, RunInUseError) as error:
        raise SystemExit(f"error: {error}") from None
    except RunInterrupted as stop:
        command = " ".join(["python -m torchrl_causal.train", *HydraConfig.get().overrides.task])
        print(f"{stop}. Resume with: {command}", file=sys.stderr)
        raise SystemExit(stop.exit_code) from None
    return results["deploy"].success_rate


if __name__ == "__main__":
    main()
