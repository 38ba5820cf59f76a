"""One training loop per paradigm, on TorchRL collectors, replay buffers and losses.

* :class:`OffPolicyILTrainer`: Causal SQIL / Causal IQ-Learn (Algorithms 2 and 3);
* :class:`BCTrainer`: (Causal) BC with early stopping;
* :class:`GAILTrainer`: (Causal) GAIL with PPO.

All share :class:`Trainer`: the loop, TorchRL logger, checkpoints and exact resume,
clean SIGINT/SIGTERM handling, periodic evaluation with best-checkpoint selection. A
:class:`RunDirectory` holds a run's files; :mod:`~torchrl_causal.trainers.schema` types
the Hydra config tree that ``cfg.algo.trainer`` names a trainer class in.
"""

from torchrl_causal.trainers.base import Score, Trainer
from torchrl_causal.trainers.bc import BCTrainer
from torchrl_causal.trainers.collection import ResumableCollector
from torchrl_causal.trainers.config import CONFIG_DIR, compose_config
from torchrl_causal.trainers.gail import GAILTrainer
from torchrl_causal.trainers.interrupts import RunInterrupted
from torchrl_causal.trainers.off_policy import OffPolicyILTrainer
from torchrl_causal.trainers.run_directory import (
    CheckpointError,
    ConfigMismatchError,
    RunDirectory,
    RunInUseError,
    load_checkpoint,
    run_label,
)
from torchrl_causal.trainers.schema import ConfigValueError, validate_config

__all__ = [
    "BCTrainer",
    "CONFIG_DIR",
    "CheckpointError",
    "ConfigMismatchError",
    "ConfigValueError",
    "GAILTrainer",
    "OffPolicyILTrainer",
    "ResumableCollector",
    "RunDirectory",
    "RunInUseError",
    "RunInterrupted",
    "Score",
    "Trainer",
    "compose_config",
    "load_checkpoint",
    "run_label",
    "validate_config",
]
