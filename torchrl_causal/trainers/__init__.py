"""One training loop per paradigm, on TorchRL collectors, replay buffers and losses.

* :class:`OffPolicyILTrainer`: Causal SQIL / Causal IQ-Learn (Algorithms 2 and 3);
* :class:`BCTrainer`: (Causal) BC with early stopping;
* :class:`GAILTrainer`: (Causal) GAIL with PPO.

All share :class:`Trainer`: the loop, TorchRL logger, checkpoints and exact resume,
clean SIGINT/SIGTERM handling, periodic evaluation with best-checkpoint selection. What a
run stands on (its typed config, run directory, device, builders) is
:mod:`torchrl_causal.experiment`; ``cfg.algo.trainer`` names a trainer class here by its
dotted path (``torchrl_causal.trainers.OffPolicyILTrainer``), which archived runs keep.
"""

from torchrl_causal.trainers.base import Score, Trainer
from torchrl_causal.trainers.bc import BCTrainer
from torchrl_causal.trainers.collection import ResumableCollector
from torchrl_causal.trainers.gail import GAILTrainer
from torchrl_causal.trainers.off_policy import OffPolicyILTrainer

__all__ = [
    "BCTrainer",
    "GAILTrainer",
    "OffPolicyILTrainer",
    "ResumableCollector",
    "Score",
    "Trainer",
]
