"""What a run stands on, below the training loops and the evaluation that use it.

* :mod:`~torchrl_causal.experiment.schema` types the Hydra config tree,
  :mod:`~torchrl_causal.experiment.config` composes it from ``torchrl_causal/conf/``;
* :class:`RunDirectory` holds a run's files (config, checkpoints, status, evaluations);
* :mod:`~torchrl_causal.experiment.device` resolves where tensors live,
  :mod:`~torchrl_causal.experiment.provenance` what produced a run,
  :mod:`~torchrl_causal.experiment.interrupts` how SIGINT/SIGTERM stop one cleanly,
  :mod:`~torchrl_causal.experiment.timing` what each part of one costs;
* :mod:`~torchrl_causal.experiment.builders` turns a resolved config into envs, the
  adjustment window, policies and demonstrations.

The lifecycle over these pieces (train, reopen, evaluate a run) is
:mod:`torchrl_causal.lifecycle`.
"""

from torchrl_causal.experiment.config import CONFIG_DIR, compose_config
from torchrl_causal.experiment.interrupts import RunInterrupted
from torchrl_causal.experiment.run_directory import (
    CheckpointError,
    CheckpointWriteError,
    ConfigMismatchError,
    ForeignFilesError,
    RunDirectory,
    RunInUseError,
    load_checkpoint,
    run_label,
)
from torchrl_causal.experiment.schema import ConfigValueError, validate_config

__all__ = [
    "CONFIG_DIR",
    "CheckpointError",
    "CheckpointWriteError",
    "ConfigMismatchError",
    "ConfigValueError",
    "ForeignFilesError",
    "RunDirectory",
    "RunInUseError",
    "RunInterrupted",
    "compose_config",
    "load_checkpoint",
    "run_label",
    "validate_config",
]
