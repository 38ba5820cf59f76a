"""Behavioural cloning (Causal BC with a causal window), Appendix E's protocol.

The demonstrations, encoded by the run's window, are split by episode into training and
validation sets (``val_fraction`` of the episodes, 20% in the paper); an actor with
``standardize_observation`` standardises its input by the training set's statistics.
Each epoch runs Adam on the Huber loss over shuffled minibatches of ``batch_size`` (2048:
large batches); training stops after ``patience`` epochs without a better validation loss
or after ``epochs`` epochs. BC never acts during training; the base class still evaluates it in
the train regime every ``eval_every`` epochs and, by default, keeps the best checkpoint of
those evaluations (by return, or by success with ``eval.select_by_success``). With
``algo.select_by_val_loss`` the kept policy is instead the epoch of the lowest validation loss,
the one early stopping measures (the classic early-stopping rule: the paper's BC learns from
the static dataset alone); the evaluations then only draw the training curve. Early stopping
itself reads the validation loss whatever the selection: a run selected by success still
stops ``patience`` epochs after the validation loss last improved (``algo.patience`` at
``algo.epochs`` or above turns it off). With
``algo.precision=bf16`` the training minibatches' forward runs under a bf16 autocast
(:func:`~torchrl_causal.experiment.device.matmul_precision`); the validation loss that
early stopping reads stays fp32.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

import torch
from hydra.utils import instantiate
from tensordict import TensorDictBase
from tensordict.nn import TensorDictModuleBase

from torchrl_causal.errors import InvalidValueError
from torchrl_causal.experiment.builders import expert_transitions, load_or_collect_demonstrations, make_imitator_env, make_policy
from torchrl_causal.experiment.device import matmul_precision
from torchrl_causal.experiment.timing import timed
from torchrl_causal.modules import fit_standardizers
from torchrl_causal.trainers.base import Trainer

__all__ = ["BCTrainer", "episode_split"]


def episode_split(episode: torch.Tensor, val_fraction: float, generator: torch.Generator) -> tuple[torch.Tensor, torch.Tensor]:
    """Row indices of the training and validation sets, splitting whole episodes.

    Splitting by episode keeps consecutive, nearly identical steps of one episode from
    landing on both sides, so the validation loss measures generalisation.

    Examples:
        >>> episode = torch.tensor([0, 0, 1, 1, 1, 2, 3, 3, 4, 4])
        >>> train, val = episode_split(episode, 0.2, torch.Generator().manual_seed(0))
        >>> len(set(episode[val].tolist())), sorted(torch.cat([train, val]).tolist()) == list(range(10))
        (1, True)
    """
    if not 0.0 < val_fraction < 1.0:
        raise InvalidValueError(f"val_fraction must lie in (0, 1), got {val_fraction}")
    episodes = torch.unique(episode)
    if episodes.numel() < 2:
        raise InvalidValueError(f"a validation split needs at least 2 demonstration episodes, got {episodes.numel()}")
    n_val = min(episodes.numel() - 1, max(1, round(val_fraction * episodes.numel())))
    held_out = episodes[torch.randperm(episodes.numel(), generator=generator)[:n_val]]
    is_val = torch.isin(episode, held_out)
    return (~is_val).nonzero().squeeze(-1), is_val.nonzero().squeeze(-1)


class BCTrainer(Trainer):
    """(Causal) BC with early stopping; progress is counted in epochs."""

    unit = "epochs"
    budget_key = "algo.epochs"

    @property
    def policy(self) -> TensorDictModuleBase:
        return self.loss.actor_network

    @property
    def selects_on_evaluation(self) -> bool:
        return not self.cfg.algo.get("select_by_val_loss", False)

    def setup(self) -> None:
        algo = self.cfg.algo
        demos = load_or_collect_demonstrations(self.cfg)
        data = expert_transitions(self.window, demos).select("observation", "action")
        self.generator = torch.Generator().manual_seed(self.cfg.seed)
        train, val = episode_split(demos["episode"], algo.val_fraction, self.generator)
        self.train_data, self.val_data = data[train].to(self.device), data[val].to(self.device)
        env = make_imitator_env(self.cfg, self.window, "train", 1, self.cfg.seed)
        self.loss = instantiate(algo.loss)(make_policy(self.cfg, env).to(self.device))
        env.close()
        fit_standardizers(self.policy, self.train_data["observation"])  # algo.actor.standardize_observation
        self.optimizer = instantiate(algo.optimizer)(self.loss.parameters())
        self.best_val_loss = math.inf
        self.epochs_without_improvement = 0

    def _batches(self, data: TensorDictBase, shuffle: bool):
        size = self.cfg.algo.batch_size
        order = torch.randperm(data.numel(), generator=self.generator) if shuffle else torch.arange(data.numel())
        for start in range(0, data.numel(), size):
            yield data[order[start : start + size]]

    @torch.no_grad()
    def validation_loss(self) -> float:
        self.policy.eval()
        try:
            total = sum(self.loss(batch)["loss_bc"].double() * batch.numel() for batch in self._batches(self.val_data, False))
        finally:
            self.policy.train()
        return total.item() / self.val_data.numel()  # one read per epoch: early stopping needs it

    def train_step(self) -> Mapping[str, float | torch.Tensor]:
        losses = []
        with timed("updates"):
            for batch in self._batches(self.train_data, True):
                with matmul_precision(self.precision, self.device):
                    loss = self.loss(batch)["loss_bc"]
                self.optimizer.zero_grad(set_to_none=True)
                loss.backward()
                self.optimizer.step()
                losses.append(loss.detach())
        self.updates_done += len(losses)
        with timed("evaluation"):
            val = self.validation_loss()
        self.progress += 1
        if val < self.best_val_loss:
            self.best_val_loss, self.epochs_without_improvement = val, 0
            if not self.selects_on_evaluation:  # the policy of the lowest validation loss so far
                self.keep_selected(train_return=math.nan, train_success=math.nan, val_loss=val)
        else:
            self.epochs_without_improvement += 1
            self.stopped = self.epochs_without_improvement >= self.cfg.algo.patience
        return {"train/loss_bc": torch.stack(losses).mean(), "val/loss_bc": val}

    def training_state(self) -> dict[str, Any]:
        return {
            "loss": self.loss.state_dict(),
            "optimizer": self.optimizer.state_dict(),
            "generator": self.generator.get_state(),
            "best_val_loss": self.best_val_loss,
            "epochs_without_improvement": self.epochs_without_improvement,
        }

    def load_training_state(self, state: Mapping[str, Any]) -> None:
        self.loss.load_state_dict(state["loss"])
        self.optimizer.load_state_dict(state["optimizer"])
        self.generator.set_state(state["generator"].cpu())
        self.best_val_loss = float(state["best_val_loss"])
        self.epochs_without_improvement = int(state["epochs_without_improvement"])
