"""The expert's row of Table 1: the env's expert evaluated like every imitator.

A scripted expert (``RoverExpert``, Route Choice's ``X = Z xor O``) learns nothing, so
the run only evaluates it, in the raw env: the expert reads the latent variables that
the imitator's window hides.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from omegaconf import DictConfig
from tensordict.nn import TensorDictModuleBase
from torchrl.envs import EnvBase

from torchrl_causal.trainers.base import Trainer
from torchrl_causal.trainers.builders import make_env, make_expert

__all__ = ["ExpertRun"]


class ExpertRun(Trainer):
    """Evaluates ``cfg.env.expert`` in both regimes (no training, no window)."""

    unit = "steps"
    uses_window = False

    @property
    def total(self) -> int:
        return 0

    @classmethod
    def build_policy(cls, cfg: DictConfig, env: EnvBase) -> TensorDictModuleBase:
        return make_expert(cfg, env)

    @property
    def policy(self) -> TensorDictModuleBase:
        return self._policy

    def make_eval_env(self, regime: str, batch_size: int, seed: int) -> EnvBase:
        # The expert may be bound to the env it reads, so it is rebuilt for each env.
        env = make_env(self.cfg, regime, batch_size, seed)
        self._policy = self.build_policy(self.cfg, env)
        return env

    def setup(self) -> None:
        self._policy = None

    def train_step(self) -> Mapping[str, float]:
        raise RuntimeError("the expert is not trained")

    def training_state(self) -> dict[str, Any]:
        return {}

    def load_training_state(self, state: Mapping[str, Any]) -> None:
        pass
