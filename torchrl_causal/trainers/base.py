"""What every training loop shares: the loop itself, logging, checkpoints and resume,
clean interrupts, and periodic train-regime evaluation with best-checkpoint selection.

TorchRL's own :class:`~torchrl.trainers.Trainer` drives one loss from one collector
through hooks; the paper's protocol needs two replay buffers mixed half and half (SQIL,
IQ-Learn), an offline epoch loop with early stopping (BC), rounds that interleave a
discriminator and PPO (GAIL), and resumable state that includes the env's episodes in
flight and the best checkpoint so far. So each paradigm gets a small explicit loop on
TorchRL's collectors, replay buffers, losses and loggers, and this base class holds the
rest. Where the files go is :class:`~torchrl_causal.experiment.run_directory.RunDirectory`'s business;
how a policy is scored is the ``evaluate`` callable the trainer is given.

Networks, losses and optimisers live on ``cfg.device`` (:attr:`Trainer.device`); envs
step on the CPU. A step may return its scalars as 0-dim tensors on the device: the loop
reads them back only when it logs them.
"""

from __future__ import annotations

import logging
import math
import signal
import time
from abc import ABC, abstractmethod
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any, ClassVar, Protocol

import torch
from omegaconf import DictConfig, OmegaConf
from tensordict import TensorDict
from tensordict.nn import TensorDictModuleBase
from torchrl.record.loggers import Logger

from torchrl_causal.data.sources import source_checksum
from torchrl_causal.errors import InvalidStateError
from torchrl_causal.experiment.builders import expert_transitions, load_or_collect_demonstrations
from torchrl_causal.experiment.device import resolve_device, resolve_precision
from torchrl_causal.experiment.interrupts import RunInterrupted, deferred_signals
from torchrl_causal.experiment.provenance import attempt_identity, identity_changes
from torchrl_causal.experiment.run_directory import TRAIN_CURVE, VIDEO_INDEX, ConfigMismatchError, RunDirectory, atomic_write_text
from torchrl_causal.experiment.timing import timed
from torchrl_causal.graphs.window import AdjustmentWindow
from torchrl_causal.progress import progress
from torchrl_causal.trainers.telemetry import SpeedMeter, log_config, open_run_logger

__all__ = ["Score", "Trainer", "selection_key"]

log = logging.getLogger(__name__)


class Score(Protocol):
    """What a periodic evaluation reports (an ``EvaluationResult`` is one)."""

    @property
    def return_mean(self) -> float: ...

    @property
    def success_rate(self) -> float: ...


def selection_key(success_rate: float, return_mean: float, by_success: bool) -> tuple[float, ...]:
    """What best-checkpoint selection maximises over the periodic train-regime evaluations.

    By the mean return alone, or with ``by_success`` (``eval.select_by_success``) by the
    success rate with the return breaking ties. A goal task's mean return can be dominated by
    costs the policy does not control (RoverMaze's gust penalty): selecting on it then picks
    a checkpoint by luck. A strictly greater key replaces the kept one, so among equal keys
    the earliest evaluation stays selected.

    Examples:
        >>> selection_key(0.9, -50.0, by_success=True) > selection_key(0.8, -5.0, by_success=True)
        True
        >>> selection_key(0.9, -50.0, by_success=False) > selection_key(0.8, -5.0, by_success=False)
        False
    """
    return (success_rate, return_mean) if by_success else (return_mean,)


def _truncate_scalar_logs(log_dir: Path, progress: int) -> None:
    """Drops CSV log rows written after ``progress`` by an interrupted attempt (the scalars
    and the CSV logger's record of the periodic evaluations' videos: each row's first field
    is its step)."""
    for path in [*(log_dir / "scalars").rglob("*.csv"), log_dir / VIDEO_INDEX]:
        if not path.is_file():
            continue
        rows = [row for row in path.read_text().splitlines() if row and int(float(row.split(",")[0])) <= progress]
        atomic_write_text(path, "".join(f"{row}\n" for row in rows))


class Trainer(ABC):
    """One run of one algorithm: ``Trainer(cfg, run, window, evaluate).fit()`` trains to
    the budget and leaves the selected policy in ``checkpoints/best.pt``.

    Subclasses set :attr:`~torchrl_causal.trainers.base.Trainer.unit` and :attr:`budget_key` and implement :meth:`setup` (build
    envs, networks, losses, buffers), :meth:`train_step` (advance :attr:`~torchrl_causal.trainers.base.Trainer.progress` by one
    iteration), :meth:`training_state` / :meth:`load_training_state` (everything resume
    needs) and :attr:`policy`.

    Progress is counted in :attr:`~torchrl_causal.trainers.base.Trainer.unit` (env steps, epochs or rounds) up to the budget
    ``cfg.<budget_key>``; every ``cfg.algo.eval_every`` units ``evaluate(policy)`` scores
    the policy (in the train regime), the best one by mean return (by success rate, the
    return breaking ties, with ``cfg.eval.select_by_success``) is kept in
    ``checkpoints/best.pt``. The full state goes to ``checkpoints/last.pt`` at every
    evaluation, every ``cfg.checkpoint_every_s`` seconds and on SIGINT/SIGTERM, after
    which :meth:`~torchrl_causal.trainers.base.Trainer.fit` raises :class:`~torchrl_causal.experiment.interrupts.RunInterrupted`.
    Resume restores the networks, optimisers, schedulers, RNG states, counters and the
    episodes in flight: the run continues as if it had not stopped.

    Args:
        cfg: the run's composed config.
        run: its directory.
        window: the adjustment window the policy conditions on.
        evaluate: scores a policy for best-checkpoint selection (``evaluate(policy)``); with
            ``eval.video_periodic`` it is called ``evaluate(policy, video_dir=, logger=, step=)``
            to record videos of the evaluation, as
            :meth:`~torchrl_causal.evaluation.evaluator.Evaluator.periodic` does.
        device: where networks, losses and replay batches live: the run's ``cfg.device``
            as its caller resolved it (:func:`~torchrl_causal.experiment.device.resolve_device`),
            resolved here when not given.
    """

    #: what :attr:`progress` counts: ``"env steps"``, ``"epochs"`` or ``"rounds"``.
    unit: ClassVar[str] = "steps"
    #: the config key holding the training budget, counted in :attr:`~torchrl_causal.trainers.base.Trainer.unit`.
    budget_key: ClassVar[str]

    def __init__(
        self,
        cfg: DictConfig,
        run: RunDirectory,
        window: AdjustmentWindow,
        evaluate: Callable[..., Score],
        *,
        device: torch.device | None = None,
    ) -> None:
        self.cfg = cfg
        self.run = run
        self.window = window
        self.evaluate = evaluate
        #: where networks, losses and optimisers live (``cfg.device`` resolved).
        self.device = resolve_device(cfg.device) if device is None else device
        #: units of training done so far (see :attr:`unit`).
        self.progress = 0
        self.best_return = -math.inf
        self.best_success = -math.inf
        self.best_progress: int | None = None
        self.last_evaluated: int | None = None
        self.stopped = False  # set by a subclass that ends early (BC's early stopping)
        self.logger: Logger | None = None
        # What the speed scalars count: subclasses add the env steps and gradient updates
        # each train_step makes (counts of this process only; nothing resumes from them).
        self.env_steps_done = 0
        self.updates_done = 0
        self.speed: SpeedMeter | None = None
        self._last_checkpoint = time.monotonic()

    @classmethod
    def budget(cls, cfg: DictConfig) -> int:
        """The training length in :attr:`~torchrl_causal.trainers.base.Trainer.unit` that ``cfg`` asks for."""
        return int(OmegaConf.select(cfg, cls.budget_key))

    @classmethod
    def extendable_budget(cls, cfg: DictConfig) -> bool:
        """Whether raising the budget of a finished run may continue it (nothing else in
        the config depends on the budget). True unless a subclass says otherwise."""
        return True

    @property
    def total(self) -> int:
        return self.budget(self.cfg)

    @property
    def precision(self) -> str:
        """The updates' precision, ``algo.precision`` (``"fp32"``, or ``"bf16"`` where the
        trainer supports it: soft-Q and BC)."""
        return resolve_precision(self.cfg.algo.get("precision"))

    # ------------------------------------------------------------------ to implement

    @abstractmethod
    def setup(self) -> None:
        """Builds everything training needs (called once, after seeding, before resume)."""

    @abstractmethod
    def train_step(self) -> Mapping[str, float | torch.Tensor]:
        """One iteration; advances :attr:`~torchrl_causal.trainers.base.Trainer.progress`; returns scalars to log (floats or
        0-dim tensors, which are read back from their device only when logged)."""

    @abstractmethod
    def training_state(self) -> dict[str, Any]:
        """Everything resume needs beyond the counters (weights_only-loadable); state too
        large for a checkpoint may be written to the run directory here instead."""

    @abstractmethod
    def load_training_state(self, state: Mapping[str, Any]) -> None:
        """Inverse of :meth:`training_state`."""

    @property
    @abstractmethod
    def policy(self) -> TensorDictModuleBase:
        """The network being trained that acts."""

    def close(self) -> None:
        """Releases envs and collectors at the end of :meth:`~torchrl_causal.trainers.base.Trainer.fit`."""

    def finish(self) -> None:
        """Called once the run is complete: drops what only a continuation would need."""

    # ------------------------------------------------------------------ shared by the loops

    def demonstration_transitions(self) -> TensorDict:
        """The run's demonstrations (loaded, or collected once) as transitions on the run's
        adjustment window: what the imitators that learn from expert transitions read."""
        return expert_transitions(self.window, load_or_collect_demonstrations(self.cfg))

    # ------------------------------------------------------------------ checkpoints

    def state_dict(self) -> dict[str, Any]:
        return {
            "progress": self.progress,
            "best_return": self.best_return,
            "best_success": self.best_success,
            "best_progress": -1 if self.best_progress is None else self.best_progress,
            "last_evaluated": -1 if self.last_evaluated is None else self.last_evaluated,
            "stopped": self.stopped,
            "training": self.training_state(),
            "torch_rng": torch.get_rng_state(),
        }

    def load_state_dict(self, state: Mapping[str, Any]) -> None:
        self.progress = int(state["progress"])
        self.best_return = float(state["best_return"])
        # Checkpoints written before selection by success existed hold no best_success.
        self.best_success = float(state.get("best_success", -math.inf))
        self.best_progress = None if state["best_progress"] < 0 else int(state["best_progress"])
        self.last_evaluated = None if state["last_evaluated"] < 0 else int(state["last_evaluated"])
        self.stopped = bool(state["stopped"])
        self.load_training_state(state["training"])
        # Last: building and restoring the training state may draw random numbers. The
        # checkpoint was loaded onto the device; the CPU generator's state lives on the CPU.
        torch.set_rng_state(state["torch_rng"].cpu())

    def write_status(self, status: str) -> None:
        speed = {} if self.speed is None else {"wall_time_s": round(self.speed.wall_time_s, 3)}
        self.run.write_status(
            status,
            progress=self.progress,
            total=self.total,
            unit=self.unit,
            best_progress=self.best_progress,
            best_train_return=self.best_return,
            **speed,
        )

    def save_checkpoint(self) -> None:
        with timed("checkpoints"):
            self.run.save_checkpoint(self.state_dict())
            self._last_checkpoint = time.monotonic()
            self.write_status("running")

    def checkpoint_due(self) -> bool:
        """Whether ``cfg.checkpoint_every_s`` seconds have passed since the last checkpoint."""
        return time.monotonic() - self._last_checkpoint >= self.cfg.checkpoint_every_s

    def _resume(self) -> bool:
        state = self.run.load_checkpoint(map_location=self.device) if self.cfg.resume else None
        if state is None:
            return False
        if state["progress"] > self.total:
            raise ConfigMismatchError(
                f"{self.run.path} has trained {state['progress']} {self.unit}, more than "
                f"{self.budget_key}={self.total}: raise the budget or start another run"
            )
        self.load_state_dict(state)
        _truncate_scalar_logs(self.run.log_dir, self.progress)
        return True

    def best_policy(self) -> TensorDictModuleBase:
        """:attr:`policy` with the weights of ``checkpoints/best.pt`` (the selected policy)."""
        best = self.run.load_checkpoint(best=True, map_location=self.device)
        if best is not None:
            self.policy.load_state_dict(best["policy"])
        return self.policy

    # ------------------------------------------------------------------ the loop

    def _log(self, scalars: Mapping[str, float], step: int) -> None:
        if self.logger is None:
            raise InvalidStateError(f"{type(self).__name__}: the logger starts in fit(); train with fit() before logging")
        for name, value in scalars.items():
            self.logger.log_scalar(name, float(value), step=step)

    def periodic_evaluation(self) -> Score:
        """Scores the policy; keeps the best one; checkpoints the run."""
        with timed("evaluation"):
            result = self.evaluate(self.policy, **self._periodic_videos())
        speed = {} if self.speed is None else self.speed.read()
        self._log({TRAIN_CURVE: result.return_mean, "eval/train_success": result.success_rate, **speed}, self.progress)
        self.last_evaluated = self.progress
        by_success = bool(self.cfg.eval.get("select_by_success", False))
        best_so_far = selection_key(self.best_success, self.best_return, by_success)
        if self.selects_on_evaluation and selection_key(result.success_rate, result.return_mean, by_success) > best_so_far:
            self.best_return, self.best_success = result.return_mean, result.success_rate
            self.keep_selected(train_return=result.return_mean, train_success=result.success_rate)
        self.save_checkpoint()
        log.info(
            "[%d %s] train-regime return %.1f, success %.0f%%", self.progress, self.unit, result.return_mean, 100 * result.success_rate
        )
        return result

    def _periodic_videos(self) -> dict[str, Any]:
        """What :meth:`periodic_evaluation` passes ``evaluate`` beside the policy: with
        ``eval.video_periodic``, the folder of this evaluation's videos, the logger they also
        go to and the step (see :meth:`~torchrl_causal.evaluation.evaluator.Evaluator.periodic`);
        else nothing, so any one-argument ``evaluate`` serves."""
        if not OmegaConf.select(self.cfg, "eval.video_periodic", default=False):
            return {}
        return {"video_dir": self.run.periodic_video_dir(self.progress), "logger": self.logger, "step": self.progress}

    @property
    def selects_on_evaluation(self) -> bool:
        """Whether the periodic evaluations select the kept policy (:func:`selection_key`).
        A trainer that selects by another rule (BC's validation loss) returns ``False`` and
        calls :meth:`keep_selected` itself; its evaluations then only draw the curves."""
        return True

    def keep_selected(self, **scores: float) -> None:
        """Writes the policy as it is now to ``checkpoints/best.pt``, the selected policy,
        with the ``scores`` it was selected on (``train_return`` and ``train_success``: NaN
        where the rule did not evaluate it), and records :attr:`progress` as where."""
        self.best_progress = self.progress
        with timed("checkpoints"):
            self.run.save_checkpoint(
                {"progress": self.progress, **scores, "policy": self.policy.state_dict()},
                best=True,
                ignored=(self.budget_key,),  # a longer budget keeps the policy it already selected
            )

    def _interrupted(self, signal_number: int) -> RunInterrupted:
        self.save_checkpoint()
        self.write_status("interrupted")
        name = signal.Signals(signal_number).name
        return RunInterrupted(
            signal_number, f"{self.run.path}: interrupted by {name} at {self.progress}/{self.total} {self.unit}, checkpoint saved"
        )

    def fit(self) -> None:
        """Trains (or resumes) to the budget; the selected policy ends in ``best.pt``.

        Raises:
            RunInterrupted: after checkpointing, on SIGINT or SIGTERM.
        """
        with timed("setup"):
            self.setup()
            resumed = self._resume()
        # The wall time of the attempts before this one: status.json holds it as of the checkpoint resumed from.
        self.speed = SpeedMeter(float(self.run.read_status().get("wall_time_s") or 0.0) if resumed else 0.0)
        self.logger = open_run_logger(self.cfg, self.run)
        if resumed:
            log.info("resumed %s at %d %s", self.run.path, self.progress, self.unit)
        else:
            log_config(self.logger, self.cfg)  # once per run: a resumed W&B run keeps its config
        identity = attempt_identity(
            source_checksum(self.cfg.demos.source, self.cfg.demos.path), self.cfg.compile, self.device, precision=self.precision
        )
        previous = self.run.record_attempt(identity, self.progress)
        changes = identity_changes(previous, identity) if resumed and previous is not None else {}
        if changes:
            listed = "; ".join(f"{key}: {old!r} -> {new!r}" for key, (old, new) in changes.items())
            log.warning(
                "%s resumes under other code, data or runtime than its last attempt (%s): its results mix both, "
                "and a rerun from scratch will not repeat them",
                self.run.path,
                listed,
            )
        self.write_status("running")
        label = f"{self.cfg.algo.name}{' (causal)' if self.cfg.causal else ''} seed {self.cfg.seed}"
        try:
            self._loop(label)
        finally:
            self.close()
            self.logger.close()  # flushes; W&B finishes its run (a resume continues it), TensorBoard closes its file

    def _count_speed(self, seconds: float, counted_before: tuple[int, int]) -> None:
        if self.speed is not None:
            env_steps, updates = self.env_steps_done - counted_before[0], self.updates_done - counted_before[1]
            self.speed.add(seconds, env_steps, updates)

    def _loop(self, label: str) -> None:
        every = self.cfg.algo.eval_every
        with (
            progress(self.total, label, self.unit, enabled=self.cfg.progress_bar, initial=self.progress) as bar,
            deferred_signals() as signals,
        ):
            while self.progress < self.total and not self.stopped:
                before, counted = self.progress, (self.env_steps_done, self.updates_done)
                started = time.monotonic()
                scalars = self.train_step()
                self._count_speed(time.monotonic() - started, counted)
                bar.update(self.progress - before)
                if scalars:
                    read = {name: float(value) for name, value in scalars.items()}  # the one device read per log
                    self._log(read, self.progress)
                    bar.set_postfix({k.split("/")[-1]: f"{v:.3g}" for k, v in read.items()}, refresh=False)
                if before // every != self.progress // every:
                    self.periodic_evaluation()
                elif self.checkpoint_due():
                    self.save_checkpoint()
                if signals.received is not None:
                    raise self._interrupted(signals.received)
            if self.total > 0 and self.last_evaluated != self.progress:
                self.periodic_evaluation()
            if signals.received is not None:
                raise self._interrupted(signals.received)
