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

Networks, losses, optimisers and both replay buffers live on ``cfg.device``; the envs
step on the CPU and the collector moves observations to the policy and actions back.
``collector_workers > 1`` steps the envs in that many processes (TorchRL's
:class:`~torchrl.collectors.MultiSyncCollector`), for the MuJoCo mazes whose physics is
the bottleneck. Loss scalars are averaged on the device and read back every
``log_every`` updates, so the update loop never waits for the device.
"""

from __future__ import annotations

from collections.abc import Mapping
from fractions import Fraction
from functools import partial
from typing import Any

import torch
from omegaconf import DictConfig
from tensordict import TensorDict
from tensordict.nn import TensorDictModuleBase
from torchrl.collectors import Collector, MultiSyncCollector
from torchrl.data import LazyTensorStorage, TensorDictReplayBuffer
from torchrl.envs import EnvBase

from torchrl_causal.modules import make_qvalue_network, make_tanh_gaussian_actor
from torchrl_causal.objectives import IQLearnLoss, SQILLoss, add_absorbing_transitions, eval_mode
from torchrl_causal.trainers.base import Trainer
from torchrl_causal.trainers.device import CPU
from torchrl_causal.trainers.builders import (
    TRANSITION_KEYS,
    expert_transitions,
    load_or_collect_demonstrations,
    make_imitator_env,
    observation_dim,
)
from torchrl_causal.trainers.update import ActorCriticUpdate

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
        # Built on the device before the loss copies them (twin and target critics, alpha).
        actor = self.build_policy(self.cfg, env).to(self.device)
        # With absorbing states the critic also reads the absorbing flag as one more feature.
        critic = make_qvalue_network(observation_dim(env) + bool(algo.absorbing), env.action_spec,
                                     hidden=int(algo.critic.hidden), num_blocks=int(algo.critic.blocks),
                                     dropout=float(algo.critic.dropout)).to(self.device)
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
        return loss.to(self.device)

    def setup(self) -> None:
        algo = self.cfg.algo
        self.workers = int(self.cfg.collector_workers)
        if self.workers < 1 or int(algo.num_envs) % self.workers:
            raise ValueError(f"collector_workers must be >= 1 and divide algo.num_envs, got {self.workers} "
                             f"workers for {algo.num_envs} envs")
        self.env = make_imitator_env(self.cfg, self.window, "train", int(algo.num_envs) // self.workers,
                                     int(self.cfg.seed))
        self.loss = self._make_loss(self.env)
        if int(algo.random_steps) % int(algo.frames_per_batch):
            raise ValueError(f"algo.random_steps={algo.random_steps} must be a multiple of algo.frames_per_batch="
                             f"{algo.frames_per_batch}: random actions are drawn for whole collector batches")
        if algo.critic_lr_schedule not in ("cosine", None, "none", "constant"):
            raise ValueError(f"algo.critic_lr_schedule must be 'cosine' or 'none', got {algo.critic_lr_schedule!r}")
        self.update = ActorCriticUpdate(
            self.loss, lr_actor=float(algo.lr_actor), lr_critic=float(algo.lr_critic), lr_alpha=float(algo.lr_alpha),
            max_grad_norm=float(algo.max_grad_norm), tau=float(algo.tau),
            cosine_updates=max(1, self.updates_due(self.total)) if algo.critic_lr_schedule == "cosine" else None,
            compile=bool(self.cfg.compile),
        )
        half = int(algo.batch_size) // 2
        if half < 1 or not 0.0 < float(algo.expert_ratio) < 1.0:
            raise ValueError(f"need batch_size >= 2 and 0 < expert_ratio < 1, got {algo.batch_size}, {algo.expert_ratio}")
        expert_batch = round(int(algo.batch_size) * float(algo.expert_ratio))
        demos = self._replay_format(expert_transitions(self.window, load_or_collect_demonstrations(self.cfg)))
        self.expert_buffer = TensorDictReplayBuffer(storage=LazyTensorStorage(demos.numel(), device=self.device),
                                                    batch_size=expert_batch)
        self.expert_buffer.extend(demos)
        self.policy_buffer = TensorDictReplayBuffer(storage=LazyTensorStorage(int(algo.buffer_size), device=self.device),
                                                    batch_size=int(algo.batch_size) - expert_batch)
        self.log_every = int(self.cfg.log_every)
        self._reset_scalar_sums()
        self.collector = None

    def updates_due(self, progress: int) -> int:
        """Gradient steps owed after ``progress`` env steps: ``floor(utd_ratio * (progress - random_steps))``."""
        utd = Fraction(float(self.cfg.algo.utd_ratio)).limit_denominator(1_000_000)  # exact for 0.25, 0.5, 0.1...
        return max(0, int(utd * (progress - int(self.cfg.algo.random_steps))))

    def _replay_format(self, transitions: TensorDict) -> TensorDict:
        return add_absorbing_transitions(transitions) if bool(self.cfg.algo.absorbing) else transitions

    def _make_collector(self) -> Collector | MultiSyncCollector:
        algo = self.cfg.algo
        frames = int(algo.frames_per_batch)
        remaining_random = max(0, int(algo.random_steps) - self.progress)
        devices = dict(env_device=CPU, policy_device=self.device, storing_device=self.device)
        # Resume restarts the episodes (env state is not checkpointed) with a fresh seed.
        seed = int(self.cfg.seed) * 1_000_003 + self.progress
        if self.workers == 1:
            self.env.set_seed(seed)
            return Collector(self.env, self.policy, frames_per_batch=frames, total_frames=-1,
                             init_random_frames=remaining_random or None, auto_register_policy_transforms=False,
                             **devices)
        make_worker_env = partial(make_imitator_env, self.cfg, self.window, "train",
                                  int(algo.num_envs) // self.workers, seed)
        # Every worker counts its own random frames, so each takes its share of them.
        collector = MultiSyncCollector([make_worker_env] * self.workers, self.policy, frames_per_batch=frames,
                                       total_frames=-1, init_random_frames=remaining_random // self.workers or None,
                                       cat_results="stack", auto_register_policy_transforms=False, **devices)
        collector.set_seed(seed)
        return collector

    def _reset_scalar_sums(self) -> None:
        # Sums stay on the device; only the counts, which the host knows, are Python ints.
        self.scalar_sums = torch.zeros(1 + len(ActorCriticUpdate.SCALARS), device=self.device)
        self.batches_since_log = self.updates_since_log = 0

    def _scalar_means(self) -> dict[str, torch.Tensor]:
        """The averages since the last log, still on the device (the logger reads them)."""
        means = {"train/reward_per_step": self.scalar_sums[0] / self.batches_since_log}
        if self.updates_since_log:
            losses = self.scalar_sums[1:] / self.updates_since_log
            means.update({f"train/{name}": value for name, value in zip(ActorCriticUpdate.SCALARS, losses)})
        self._reset_scalar_sums()
        return means

    def train_step(self) -> Mapping[str, torch.Tensor]:
        with eval_mode(self.policy):  # the collector also probes the policy when it is built
            if self.collector is None:
                self.collector = self._make_collector()
                self.batches = iter(self.collector)
            elif self.workers > 1:
                self.collector.update_policy_weights_()
            batch = next(self.batches)
        transitions = batch.reshape(-1).select(*_COLLECTED_KEYS)
        transitions.set("expert", torch.zeros((*transitions.batch_size, 1), dtype=torch.bool, device=transitions.device))
        self.policy_buffer.extend(self._replay_format(transitions.exclude(("next", "reward"))))
        self.progress += transitions.numel()
        self.scalar_sums[0] += transitions["next", "reward"].mean()
        self.batches_since_log += 1
        for _ in range(self.updates_due(self.progress) - self.update.updates):
            batch = torch.cat([self.expert_buffer.sample(), self.policy_buffer.sample()], dim=0)
            self.scalar_sums[1:] += self.update(batch)
            self.updates_since_log += 1
        due = self.updates_since_log >= self.log_every or self.update.updates == 0 or self.progress >= self.total
        return self._scalar_means() if due else {}

    def close(self) -> None:
        if self.workers > 1 and self.collector is not None:
            self.collector.shutdown()
        self.collector = None
        self.env.close()

    def training_state(self) -> dict[str, Any]:
        return {
            "loss": self.loss.state_dict(),
            **self.update.state_dict(),
            "policy_buffer": self.policy_buffer.state_dict(),
        }

    def load_training_state(self, state: Mapping[str, Any]) -> None:
        self.loss.load_state_dict(state["loss"])
        self.update.load_state_dict(state)
        self.policy_buffer.load_state_dict(state["policy_buffer"])
        self.collector = None
