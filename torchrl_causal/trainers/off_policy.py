"""Off-policy imitation (Causal SQIL, Causal IQ-Learn): the paper's Algorithms 2 and 3.

A TorchRL :class:`~torchrl.collectors.Collector` steps the imitator's env (the causal
window's encoding in ``"observation"``) and fills a policy replay buffer; the
demonstrations, encoded by the same window, fill a static expert buffer with
``"expert"`` = True. Each gradient step draws half its batch from each buffer (the
paper's expert buffer ratio 0.5), updates the twin critics (cosine-annealed learning
rate), the actor and the entropy coefficient with gradient-norm clipping, then the
target critics by Polyak averaging.

The counts are exact: the first ``random_steps`` env steps use uniformly random
actions (a whole number of collector batches, or the config is refused); after ``n``
further env steps ``floor(utd_ratio * n)`` gradient steps have run, interleaved with
collection every ``frames_per_batch`` env steps (by default one step of every batched
env); the cosine schedule of the critic learning rate spans exactly the run's number of
gradient steps, so none runs at learning rate zero. The actor collects in eval mode
(no dropout): the replay buffer holds the policy that is evaluated. With
``algo.absorbing`` the expert and policy transitions get absorbing states
(:func:`~torchrl_causal.objectives.add_absorbing_transitions`).
"""

from __future__ import annotations

from collections.abc import Mapping
from fractions import Fraction
from typing import Any

import torch
from omegaconf import DictConfig
from tensordict import TensorDict
from tensordict.nn import TensorDictModuleBase
from torchrl.collectors import Collector
from torchrl.data import LazyTensorStorage, TensorDictReplayBuffer
from torchrl.envs import EnvBase
from torchrl.objectives import SoftUpdate

from torchrl_causal.modules import make_qvalue_network, make_tanh_gaussian_actor
from torchrl_causal.objectives import IQLearnLoss, SQILLoss, add_absorbing_transitions, eval_mode
from torchrl_causal.trainers.base import Trainer
from torchrl_causal.trainers.builders import (
    TRANSITION_KEYS,
    expert_transitions,
    load_or_collect_demonstrations,
    make_imitator_env,
    observation_dim,
)

__all__ = ["OffPolicyILTrainer"]

_COLLECTED_KEYS = (*TRANSITION_KEYS, ("next", "reward"))


class OffPolicyILTrainer(Trainer):
    """SQIL / IQ-Learn on causally encoded observations (``cfg.algo.loss``).

    Progress is counted in env steps up to ``cfg.algo.total_steps``.
    """

    unit = "env steps"

    @property
    def total(self) -> int:
        return int(self.cfg.algo.total_steps)

    @classmethod
    def build_policy(cls, cfg: DictConfig, env: EnvBase) -> TensorDictModuleBase:
        a = cfg.algo.actor
        return make_tanh_gaussian_actor(observation_dim(env), env.action_spec, hidden=int(a.hidden),
                                        num_blocks=int(a.blocks), dropout=float(a.dropout))

    @property
    def policy(self) -> TensorDictModuleBase:
        return self.loss.actor_network

    def _make_loss(self, env: EnvBase) -> SQILLoss | IQLearnLoss:
        algo = self.cfg.algo
        actor = self.build_policy(self.cfg, env)
        # With absorbing states the critic also reads the absorbing flag as one more feature.
        critic = make_qvalue_network(observation_dim(env) + bool(algo.absorbing), env.action_spec,
                                     hidden=int(algo.critic.hidden),
                                     num_blocks=int(algo.critic.blocks), dropout=float(algo.critic.dropout))
        kwargs: dict[str, Any] = dict(alpha_init=float(algo.alpha_init), min_alpha=float(algo.alpha_min),
                                      max_alpha=float(algo.alpha_max), target_entropy=algo.target_entropy,
                                      absorbing=bool(algo.absorbing))
        if algo.loss == "sqil":
            loss = SQILLoss(actor, critic, **kwargs)
        elif algo.loss == "iq_learn":
            loss = IQLearnLoss(actor, critic, variant=str(algo.variant), num_value_samples=int(algo.value_samples),
                               **kwargs)
        else:
            raise ValueError(f"algo.loss must be 'sqil' or 'iq_learn', got {algo.loss!r}")
        loss.make_value_estimator(gamma=float(algo.gamma))
        return loss

    def setup(self) -> None:
        algo = self.cfg.algo
        self.env = make_imitator_env(self.cfg, self.window, "train", int(algo.num_envs), int(self.cfg.seed))
        self.loss = self._make_loss(self.env)
        self.target_updater = SoftUpdate(self.loss, tau=float(algo.tau))
        self.actor_optimizer = torch.optim.Adam(self.loss.actor_network_params.flatten_keys().values(),
                                                lr=float(algo.lr_actor))
        self.critic_optimizer = torch.optim.Adam(self.loss.qvalue_network_params.flatten_keys().values(),
                                                 lr=float(algo.lr_critic))
        self.alpha_optimizer = torch.optim.Adam([self.loss.log_alpha], lr=float(algo.lr_alpha))
        if int(algo.random_steps) % int(algo.frames_per_batch):
            raise ValueError(f"algo.random_steps={algo.random_steps} must be a multiple of algo.frames_per_batch="
                             f"{algo.frames_per_batch}: random actions are drawn for whole collector batches")
        self.total_updates = self.updates_due(self.total)
        if algo.critic_lr_schedule == "cosine":
            self.critic_schedule = torch.optim.lr_scheduler.CosineAnnealingLR(self.critic_optimizer,
                                                                              max(1, self.total_updates))
        elif algo.critic_lr_schedule in (None, "none", "constant"):
            self.critic_schedule = None
        else:
            raise ValueError(f"algo.critic_lr_schedule must be 'cosine' or 'none', got {algo.critic_lr_schedule!r}")
        half = int(algo.batch_size) // 2
        if half < 1 or not 0.0 < float(algo.expert_ratio) < 1.0:
            raise ValueError(f"need batch_size >= 2 and 0 < expert_ratio < 1, got {algo.batch_size}, {algo.expert_ratio}")
        expert_batch = round(int(algo.batch_size) * float(algo.expert_ratio))
        demos = self._replay_format(expert_transitions(self.window, load_or_collect_demonstrations(self.cfg)))
        self.expert_buffer = TensorDictReplayBuffer(storage=LazyTensorStorage(demos.numel()), batch_size=expert_batch)
        self.expert_buffer.extend(demos)
        self.policy_buffer = TensorDictReplayBuffer(storage=LazyTensorStorage(int(algo.buffer_size)),
                                                    batch_size=int(algo.batch_size) - expert_batch)
        self.updates = 0
        self.collector = None

    def updates_due(self, progress: int) -> int:
        """Gradient steps owed after ``progress`` env steps: ``floor(utd_ratio * (progress - random_steps))``."""
        utd = Fraction(float(self.cfg.algo.utd_ratio)).limit_denominator(1_000_000)  # exact for 0.25, 0.5, 0.1...
        return max(0, int(utd * (progress - int(self.cfg.algo.random_steps))))

    def _replay_format(self, transitions: TensorDict) -> TensorDict:
        return add_absorbing_transitions(transitions) if bool(self.cfg.algo.absorbing) else transitions

    def _make_collector(self) -> Collector:
        algo = self.cfg.algo
        frames = int(algo.frames_per_batch)
        remaining_random = max(0, int(algo.random_steps) - self.progress)
        # Resume restarts the episodes (env state is not checkpointed) with a fresh seed.
        self.env.set_seed(int(self.cfg.seed) * 1_000_003 + self.progress)
        return Collector(
            self.env, self.policy, frames_per_batch=frames, total_frames=-1,
            init_random_frames=remaining_random or None,
            device="cpu", auto_register_policy_transforms=False,
        )

    def train_step(self) -> Mapping[str, float]:
        with eval_mode(self.policy):  # the collector also probes the policy when it is built
            if self.collector is None:
                self.collector = iter(self._make_collector())
            batch = next(self.collector)
        transitions = batch.reshape(-1).select(*_COLLECTED_KEYS)
        transitions.set("expert", torch.zeros((*transitions.batch_size, 1), dtype=torch.bool))
        self.policy_buffer.extend(self._replay_format(transitions.exclude(("next", "reward"))))
        self.progress += transitions.numel()
        scalars: dict[str, float] = {"train/reward_per_step": transitions["next", "reward"].mean().item()}
        losses = [self._update() for _ in range(self.updates_due(self.progress) - self.updates)]
        if losses:
            scalars.update({k: sum(d[k] for d in losses) / len(losses) for k in losses[0]})
        return scalars

    @property
    def optimizers(self) -> tuple[torch.optim.Optimizer, ...]:
        return self.critic_optimizer, self.actor_optimizer, self.alpha_optimizer

    def _update(self) -> dict[str, float]:
        batch = torch.cat([self.expert_buffer.sample(), self.policy_buffer.sample()], dim=0)
        out = self.loss(batch)
        for optimizer in self.optimizers:
            optimizer.zero_grad(set_to_none=True)
        # SACLoss detaches the critics inside the actor loss, so one backward pass gives
        # each network the gradient of its own objective.
        (out["loss_qvalue"] + out["loss_actor"] + out["loss_alpha"]).backward()
        max_norm = float(self.cfg.algo.max_grad_norm)
        for params in (self.loss.qvalue_network_params, self.loss.actor_network_params):
            torch.nn.utils.clip_grad_norm_(list(params.flatten_keys().values()), max_norm)
        for optimizer in self.optimizers:
            optimizer.step()
        if self.critic_schedule is not None and self.updates < self.total_updates:
            self.critic_schedule.step()
        self.target_updater.step()
        self.updates += 1
        return {"train/loss_qvalue": out["loss_qvalue"].item(), "train/loss_actor": out["loss_actor"].item(),
                "train/alpha": out["alpha"].item(), "train/entropy": out["entropy"].item()}

    def close(self) -> None:
        self.collector = None
        self.env.close()

    def training_state(self) -> dict[str, Any]:
        return {
            "loss": self.loss.state_dict(),
            "actor_optimizer": self.actor_optimizer.state_dict(),
            "critic_optimizer": self.critic_optimizer.state_dict(),
            "alpha_optimizer": self.alpha_optimizer.state_dict(),
            "critic_schedule": self.critic_schedule.state_dict() if self.critic_schedule is not None else {},
            "policy_buffer": self.policy_buffer.state_dict(),
            "updates": self.updates,
        }

    def load_training_state(self, state: Mapping[str, Any]) -> None:
        self.loss.load_state_dict(state["loss"])
        self.actor_optimizer.load_state_dict(state["actor_optimizer"])
        self.critic_optimizer.load_state_dict(state["critic_optimizer"])
        self.alpha_optimizer.load_state_dict(state["alpha_optimizer"])
        if self.critic_schedule is not None:
            self.critic_schedule.load_state_dict(state["critic_schedule"])
        self.policy_buffer.load_state_dict(state["policy_buffer"])
        self.updates = int(state["updates"])
        self.collector = None
