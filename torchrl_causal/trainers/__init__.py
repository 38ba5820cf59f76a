"""One training loop per paradigm, on TorchRL collectors, replay buffers and losses.

* :class:`OffPolicyILTrainer`: Causal SQIL / Causal IQ-Learn (Algorithms 2 and 3);
* :class:`BCTrainer`: (Causal) BC with early stopping;
* :class:`GAILTrainer`: (Causal) GAIL with PPO;
* :class:`ExpertRun`: the expert's evaluation (Table 1's first column).

All share :class:`Trainer`: run directory, TorchRL logger, atomic checkpoints and resume,
periodic train-regime evaluation with best-checkpoint selection, and the final
evaluation in both regimes. :func:`make_trainer` picks one from ``cfg.algo.trainer``.
"""

from omegaconf import DictConfig

from torchrl_causal.trainers.base import CheckpointError, Trainer, load_checkpoint, read_status
from torchrl_causal.trainers.bc import BCTrainer
from torchrl_causal.trainers.config import CONFIG_DIR, compose_config, run_label
from torchrl_causal.trainers.expert import ExpertRun
from torchrl_causal.trainers.gail import GAILTrainer
from torchrl_causal.trainers.off_policy import OffPolicyILTrainer

__all__ = [
    "BCTrainer",
    "CONFIG_DIR",
    "CheckpointError",
    "ExpertRun",
    "GAILTrainer",
    "OffPolicyILTrainer",
    "TRAINERS",
    "Trainer",
    "compose_config",
    "load_checkpoint",
    "make_trainer",
    "read_status",
    "run_label",
]

TRAINERS: dict[str, type[Trainer]] = {
    "off_policy": OffPolicyILTrainer,
    "bc": BCTrainer,
    "gail": GAILTrainer,
    "expert": ExpertRun,
}


def make_trainer(cfg: DictConfig) -> Trainer:
    """The trainer named by ``cfg.algo.trainer``.

    Raises:
        ValueError: for an unknown trainer, or an env without an expert (``env.expert: null``,
            e.g. HumanoidMaze): every algorithm needs one, for its demonstrations or its row.
    """
    if cfg.env.get("expert") is None:
        raise ValueError(
            f"env {cfg.env.name!r} has no expert (env.expert is null), and every algorithm needs one "
            "(demonstrations, or the expert row). HumanoidMaze's expert needs OGBench's humanoid locomotion "
            "skill (~40M env steps), which this library does not ship yet; pass your own with "
            "env.expert._target_=<module.Class taking the env>."
        )
    name = cfg.algo.trainer
    if name not in TRAINERS:
        raise ValueError(f"algo.trainer must be one of {sorted(TRAINERS)}, got {name!r}")
    return TRAINERS[name](cfg)
