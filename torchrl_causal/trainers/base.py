"""What every training loop shares: the run directory, logging, checkpoints and resume,
periodic train-regime evaluation with best-checkpoint selection, and the final
evaluation of the selected policy in both regimes.

TorchRL's own :class:`~torchrl.trainers.Trainer` drives one loss from one collector
through hooks; the paper's protocol needs two replay buffers mixed half and half (SQIL,
IQ-Learn), an offline epoch loop with early stopping (BC), rounds that interleave a
discriminator and PPO (GAIL), and resumable state that includes the policy buffer and
the best checkpoint so far. So each paradigm gets a small explicit loop on TorchRL's
collectors, replay buffers, losses and loggers, and this base class holds the rest.
"""

from __future__ import annotations

import json
import math
import os
from abc import ABC, abstractmethod
from collections.abc import Mapping
from pathlib import Path
from typing import Any, ClassVar

import torch
from omegaconf import DictConfig, OmegaConf
from tensordict.nn import TensorDictModuleBase
from torchrl.envs import EnvBase
from torchrl.record.loggers import CSVLogger, Logger
from tqdm.auto import tqdm

from torchrl_causal.evaluation.metrics import EvaluationResult, evaluate_policy
from torchrl_causal.evaluation.runs import CONFIG_FILE, LOG_DIR, STATUS_FILE, WINDOW_FILE, TRAIN_CURVE, eval_path
from torchrl_causal.graphs.window import AdjustmentWindow
from torchrl_causal.trainers.builders import make_env, make_imitator_env, make_window, maze_geometry
from torchrl_causal.trainers.device import CPU, for_cpu_env, resolve_device

__all__ = ["Trainer", "CheckpointError", "atomic_save", "load_checkpoint", "read_status"]

CHECKPOINT_DIR = "checkpoints"
LAST_CHECKPOINT = "last.pt"
BEST_CHECKPOINT = "best.pt"
# Evaluation envs are seeded apart from the training env (and from each other), with the
# same seed at every periodic evaluation so checkpoints are compared on the same episodes.
_PERIODIC_EVAL_SEED, _FINAL_EVAL_SEED = 10_000, 20_000


class CheckpointError(RuntimeError):
    """A checkpoint that cannot be read or does not belong to this run."""


def atomic_save(obj: Any, path: Path) -> None:
    """``torch.save`` to a temporary file in the same folder, then rename over ``path``:
    an interrupted save leaves the previous checkpoint intact."""
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.tmp{os.getpid()}")
    torch.save(obj, tmp)
    os.replace(tmp, path)


def _atomic_write_text(path: Path, text: str) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.tmp{os.getpid()}")
    tmp.write_text(text)
    os.replace(tmp, path)


def load_checkpoint(path: Path, map_location: str | torch.device = CPU) -> dict[str, Any]:
    """``torch.load(..., weights_only=True)`` onto ``map_location``, with an error that
    names the file. A checkpoint written on a GPU loads on a machine without one."""
    try:
        state = torch.load(path, map_location=map_location, weights_only=True)
    except Exception as err:  # pickle, zip and unpickler errors all mean the same here
        raise CheckpointError(f"checkpoint {path} is corrupted or not a torchrl-causal checkpoint: {err}") from err
    if not isinstance(state, dict) or "progress" not in state:
        raise CheckpointError(f"checkpoint {path} lacks the 'progress' entry of a torchrl-causal checkpoint")
    return state


def read_status(run_dir: str | Path) -> dict[str, Any]:
    """The run's ``status.json`` (``{}`` before the first write)."""
    path = Path(run_dir) / STATUS_FILE
    return json.loads(path.read_text()) if path.is_file() else {}


def _truncate_scalar_logs(log_dir: Path, progress: int) -> None:
    """Drops CSV log rows written after ``progress`` by an interrupted attempt."""
    for path in (log_dir / "scalars").rglob("*.csv"):
        rows = [row for row in path.read_text().splitlines() if row and int(float(row.split(",")[0])) <= progress]
        _atomic_write_text(path, "".join(f"{row}\n" for row in rows))


class Trainer(ABC):
    """One run of one algorithm: ``Trainer(cfg).fit()`` trains, selects and evaluates.

    Subclasses set :attr:`unit` and implement :meth:`setup` (build envs, networks, losses,
    buffers), :meth:`train_step` (advance :attr:`progress` by one iteration),
    :meth:`training_state` / :meth:`load_training_state` (everything resume needs) and
    :meth:`build_policy` (the network that acts, rebuilt from the config for evaluation).

    Progress is counted in :attr:`unit` (env steps, epochs or rounds) up to :attr:`total`;
    every ``cfg.algo.eval_every`` units the policy is evaluated in the train regime on
    ``cfg.eval.episodes`` episodes, the best one by mean return is kept in
    ``checkpoints/best.pt`` and the full state in ``checkpoints/last.pt``. At the end the
    best policy is evaluated in both regimes on ``cfg.eval.final_episodes`` episodes.
    """

    unit: ClassVar[str] = "steps"
    uses_window: ClassVar[bool] = True

    def __init__(self, cfg: DictConfig) -> None:
        self.cfg = cfg
        # Before anything is built or written: device=cuda on a machine without one fails here.
        self.device = resolve_device(str(OmegaConf.select(cfg, "device", default="cpu")))
        self.run_dir = Path(cfg.run_dir)
        self.progress = 0
        self.best_return = -math.inf
        self.best_progress: int | None = None
        self.last_evaluated: int | None = None
        self.stopped = False  # set by a subclass that ends early (BC's early stopping)
        self.window: AdjustmentWindow | None = None
        self.logger: Logger | None = None
        self.progress_bar = bool(OmegaConf.select(cfg, "progress_bar", default=True))

    # ------------------------------------------------------------------ to implement

    @property
    @abstractmethod
    def total(self) -> int:
        """Training length in :attr:`unit`."""

    @abstractmethod
    def setup(self) -> None:
        """Builds everything training needs (called once, after seeding)."""

    @abstractmethod
    def train_step(self) -> Mapping[str, float | torch.Tensor]:
        """One iteration; advances :attr:`progress`; returns scalars to log (floats or
        0-dim tensors, which are read back from their device only when logged)."""

    @abstractmethod
    def training_state(self) -> dict[str, Any]:
        """Everything resume needs beyond the counters (weights_only-loadable)."""

    @abstractmethod
    def load_training_state(self, state: Mapping[str, Any]) -> None:
        """Inverse of :meth:`training_state`."""

    @classmethod
    @abstractmethod
    def build_policy(cls, cfg: DictConfig, env: EnvBase) -> TensorDictModuleBase:
        """A freshly initialised acting network for ``env`` (the imitator's view)."""

    @property
    @abstractmethod
    def policy(self) -> TensorDictModuleBase:
        """The network being trained that acts."""

    def close(self) -> None:
        """Releases envs and collectors at the end of :meth:`fit`."""

    def checkpoint_due(self, before: int) -> bool:
        """Whether to write ``last.pt`` after an iteration (at evaluations by default)."""
        return False

    # ------------------------------------------------------------------ shared machinery

    @property
    def checkpoint_dir(self) -> Path:
        return self.run_dir / CHECKPOINT_DIR

    def make_eval_env(self, regime: str, batch_size: int, seed: int) -> EnvBase:
        """The env a policy is evaluated in (the imitator's view by default)."""
        return make_imitator_env(self.cfg, self.window, regime, batch_size, seed)

    def load_best_policy(self) -> TensorDictModuleBase:
        """The acting network rebuilt from the config with ``checkpoints/best.pt`` loaded
        (for evaluating a finished run without its training state)."""
        env = self.make_eval_env("train", 1, 0)
        policy = self.build_policy(self.cfg, env).to(self.device)
        env.close()
        path = self.checkpoint_dir / BEST_CHECKPOINT
        if not path.is_file():
            raise CheckpointError(f"run {self.run_dir} has no {CHECKPOINT_DIR}/{BEST_CHECKPOINT} to evaluate")
        policy.load_state_dict(load_checkpoint(path, self.device)["policy"])
        return policy

    def evaluate(self, regime: str, episodes: int, seed: int, *, trajectories: int = 0, progress: bool = False,
                 policy: TensorDictModuleBase | None = None) -> EvaluationResult:
        """Runs ``policy`` (default: the one being trained) in eval mode (no dropout) for
        ``episodes`` episodes in batches of ``cfg.eval.num_envs``."""
        env = self.make_eval_env(regime, min(int(self.cfg.eval.num_envs), episodes), seed)
        policy = self.policy if policy is None else policy
        was_training = getattr(policy, "training", None)  # scripted experts are plain callables
        if was_training is not None:
            policy.eval()
        acting = for_cpu_env(policy)
        try:
            return evaluate_policy(
                env, acting, episodes=episodes, max_steps=int(self.cfg.env.horizon), regime=regime,
                seeds=[int(self.cfg.seed)], position_key=OmegaConf.select(self.cfg, "env.position_key"),
                trajectories=trajectories, progress=progress,
            )
        finally:
            if was_training is not None:
                policy.train(was_training)
            env.close()

    def _seed(self) -> None:
        torch.manual_seed(int(self.cfg.seed))
        torch.set_num_threads(int(self.cfg.threads))

    def _write_run_files(self) -> None:
        self.run_dir.mkdir(parents=True, exist_ok=True)
        _atomic_write_text(self.run_dir / CONFIG_FILE, OmegaConf.to_yaml(self.cfg, resolve=True))
        if self.window is not None:
            _atomic_write_text(self.run_dir / WINDOW_FILE, json.dumps(self.window.to_dict(), indent=2))

    def _make_logger(self) -> Logger:
        backend = str(OmegaConf.select(self.cfg, "logger.backend", default="csv"))
        if backend == "csv":
            return CSVLogger(exp_name=LOG_DIR, log_dir=str(self.run_dir))
        if backend == "tensorboard":
            from torchrl.record.loggers import TensorboardLogger

            return TensorboardLogger(exp_name=LOG_DIR, log_dir=str(self.run_dir))
        raise ValueError(f"logger.backend must be 'csv' or 'tensorboard', got {backend!r}")

    def _log(self, scalars: Mapping[str, float | torch.Tensor], step: int) -> None:
        for name, value in scalars.items():
            self.logger.log_scalar(name, float(value), step=step)

    def _write_status(self, status: str) -> None:
        _atomic_write_text(self.run_dir / STATUS_FILE, json.dumps({
            "status": status, "progress": self.progress, "total": self.total, "unit": self.unit,
            "best_progress": self.best_progress,
            "best_train_return": None if math.isinf(self.best_return) else self.best_return,
        }, indent=2))

    def state_dict(self) -> dict[str, Any]:
        return {
            "progress": self.progress,
            "best_return": self.best_return,
            "best_progress": -1 if self.best_progress is None else self.best_progress,
            "last_evaluated": -1 if self.last_evaluated is None else self.last_evaluated,
            "stopped": self.stopped,
            "torch_rng": torch.get_rng_state(),
            "training": self.training_state(),
        }

    def load_state_dict(self, state: Mapping[str, Any]) -> None:
        self.progress = int(state["progress"])
        self.best_return = float(state["best_return"])
        self.best_progress = None if state["best_progress"] < 0 else int(state["best_progress"])
        self.last_evaluated = None if state["last_evaluated"] < 0 else int(state["last_evaluated"])
        self.stopped = bool(state["stopped"])
        torch.set_rng_state(state["torch_rng"].cpu())  # map_location may have put it on the device
        self.load_training_state(state["training"])

    def save_checkpoint(self) -> None:
        atomic_save(self.state_dict(), self.checkpoint_dir / LAST_CHECKPOINT)
        self._write_status("running")

    def _resume(self) -> bool:
        path = self.checkpoint_dir / LAST_CHECKPOINT
        if not (bool(self.cfg.resume) and path.is_file()):
            return False
        self.load_state_dict(load_checkpoint(path, self.device))
        _truncate_scalar_logs(self.run_dir / LOG_DIR, self.progress)
        return True

    def periodic_evaluation(self) -> EvaluationResult:
        """Train-regime evaluation; keeps the best policy; checkpoints the run."""
        result = self.evaluate("train", int(self.cfg.eval.episodes), _PERIODIC_EVAL_SEED + int(self.cfg.seed))
        self._log({TRAIN_CURVE: result.return_mean, "eval/train_success": result.success_rate}, self.progress)
        self.last_evaluated = self.progress
        if result.return_mean > self.best_return:
            self.best_return, self.best_progress = result.return_mean, self.progress
            atomic_save({"progress": self.progress, "train_return": result.return_mean,
                         "policy": self.policy.state_dict()}, self.checkpoint_dir / BEST_CHECKPOINT)
        self.save_checkpoint()
        return result

    def final_evaluation(self) -> dict[str, EvaluationResult]:
        """Evaluates the best checkpoint in both regimes and writes ``eval/<regime>.json``."""
        best = self.checkpoint_dir / BEST_CHECKPOINT
        if best.is_file():
            self.policy.load_state_dict(load_checkpoint(best, self.device)["policy"])
        results = {}
        for offset, regime in enumerate(("train", "deploy")):
            result = self.evaluate(regime, int(self.cfg.eval.final_episodes),
                                   _FINAL_EVAL_SEED + 1000 * offset + int(self.cfg.seed),
                                   trajectories=int(self.cfg.eval.trajectories), progress=self.progress_bar)
            record = result.to_dict()
            record["maze"] = maze_geometry(make_env(self.cfg, regime, 1, 0))
            _atomic_write_text(eval_path(self.run_dir, regime), json.dumps(record))
            results[regime] = result
        return results

    def fit(self) -> dict[str, EvaluationResult]:
        """Trains (or resumes) to :attr:`total`, then evaluates the best policy.

        A run whose ``status.json`` says complete at this :attr:`total` is not trained
        again (with ``resume=true``): its stored evaluations are returned. Raising the
        budget of a finished run continues it from its last checkpoint.
        """
        status = read_status(self.run_dir)
        if bool(self.cfg.resume) and status.get("status") == "complete" and status.get("total") == self.total:
            return {regime: EvaluationResult.from_dict(json.loads(eval_path(self.run_dir, regime).read_text()))
                    for regime in ("train", "deploy") if eval_path(self.run_dir, regime).is_file()}
        self._seed()
        if self.uses_window:
            self.window = make_window(self.cfg, make_env(self.cfg, "train", 1, int(self.cfg.seed)))
        self._write_run_files()
        self.setup()
        resumed = self._resume()
        self.logger = self._make_logger()
        label = f"{self.cfg.algo.name}{' (causal)' if self.cfg.causal else ''} seed {self.cfg.seed}"
        with tqdm(total=self.total, initial=self.progress, desc=label, unit=self.unit,
                  disable=not self.progress_bar, dynamic_ncols=True) as bar:
            if resumed:
                bar.write(f"resumed {self.run_dir} at {self.progress} {self.unit}")
            while self.progress < self.total and not self.stopped:
                before = self.progress
                scalars = self.train_step()
                bar.update(self.progress - before)
                if scalars:
                    scalars = {name: float(value) for name, value in scalars.items()}  # the one device read per log
                    self._log(scalars, self.progress)
                    bar.set_postfix({k.split("/")[-1]: f"{v:.3g}" for k, v in scalars.items()}, refresh=False)
                every = int(self.cfg.algo.eval_every)
                if before // every != self.progress // every:
                    result = self.periodic_evaluation()
                    bar.write(f"[{self.progress} {self.unit}] train-regime return {result.return_mean:.1f}, "
                              f"success {100 * result.success_rate:.0f}%")
                elif self.checkpoint_due(before):
                    self.save_checkpoint()
        if self.total > 0 and self.last_evaluated != self.progress:
            self.periodic_evaluation()
        self.close()
        results = self.final_evaluation()
        self._write_status("complete")
        return results
