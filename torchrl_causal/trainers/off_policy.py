"""Off-policy imitation (Causal SQIL, Causal IQ-Learn): the paper's Algorithms 2 and 3.

A TorchRL collector steps the imitator's env (the causal window's encoding in
``"observation"``) and fills a policy replay buffer; the demonstrations, encoded by the
same window, fill a static expert buffer with ``"expert"`` = True. Each gradient step
draws half its batch from each buffer (the paper's expert buffer ratio 0.5), updates the
twin critics (cosine-annealed learning rate), the actor and the entropy coefficient with
gradient-norm clipping, then the target critics by Polyak averaging. The first
``random_steps`` env steps use uniformly random actions; afterwards ``utd_ratio``
gradient steps follow every env step.

The policy buffer is a memory-mapped TorchRL storage in the run directory
(``replay/``): a checkpoint records its length and write cursor, never its contents.
"""

from __future__ import annotations

import logging
import math
import shutil
from collections.abc import Mapping
from typing import Any

import torch
from hydra.utils import instantiate
from omegaconf import DictConfig
from tensordict.nn import TensorDictModuleBase
from torchrl.data import LazyMemmapStorage, LazyTensorStorage, TensorDictReplayBuffer

from torchrl_causal.objectives import ExpertFlaggedSACLoss
from torchrl_causal.trainers.base import Trainer
from torchrl_causal.trainers.builders import (
    TRANSITION_KEYS,
    expert_transitions,
    load_or_collect_demonstrations,
    make_imitator_env,
    make_policy,
    observation_dim,
)
from torchrl_causal.trainers.collection import ResumableCollector
from torchrl_causal.trainers.run_directory import CheckpointError

__all__ = ["OffPolicyILTrainer"]

_COLLECTED_KEYS = (*TRANSITION_KEYS, ("next", "reward"))

log = logging.getLogger(__name__)


class OffPolicyILTrainer(Trainer):
    """SQIL / IQ-Learn (``cfg.algo.loss``) on causally encoded observations.

    Progress is counted in env steps up to ``cfg.algo.total_steps``.
    """

    unit = "env steps"
    budget_key = "algo.total_steps"

    @classmethod
    def extendable_budget(cls, cfg: DictConfig) -> bool:
        # A cosine schedule spans the budget: a longer run is another run.
        return cfg.algo.critic_scheduler is None

    @property
    def policy(self) -> TensorDictModuleBase:
        return self.loss.actor_network

    def _make_loss(self) -> ExpertFlaggedSACLoss:
        algo = self.cfg.algo
        dim, spec = observation_dim(self.env), self.env.action_spec
        loss = instantiate(algo.loss)(make_policy(self.cfg, self.env), instantiate(algo.critic)(dim, spec))
        loss.make_value_estimator(**algo.value_estimator)
        return loss

    def setup(self) -> None:
        algo = self.cfg.algo
        self.env = make_imitator_env(self.cfg, self.window, "train", algo.num_envs, self.cfg.seed)
        self.loss = self._make_loss()
        self.target_updater = instantiate(algo.target_update)(self.loss)
        self.actor_optimizer = instantiate(algo.actor_optimizer)(self.loss.actor_network_params.flatten_keys().values())
        self.critic_optimizer = instantiate(algo.critic_optimizer)(
            self.loss.qvalue_network_params.flatten_keys().values())
        self.alpha_optimizer = instantiate(algo.alpha_optimizer)([self.loss.log_alpha])
        self.total_updates = max(1, math.ceil(algo.utd_ratio * max(0, self.total - algo.random_steps)))
        self.critic_schedule = None
        if algo.critic_scheduler is not None:
            self.critic_schedule = instantiate(algo.critic_scheduler)(self.critic_optimizer, T_max=self.total_updates)
        expert_batch = round(algo.batch_size * algo.expert_ratio)
        if not 1 <= expert_batch < algo.batch_size:
            raise ValueError(f"algo.batch_size={algo.batch_size} x algo.expert_ratio={algo.expert_ratio} leaves an "
                             "empty expert or policy half")
        demos = expert_transitions(self.window, load_or_collect_demonstrations(self.cfg))
        self.expert_buffer = TensorDictReplayBuffer(storage=LazyTensorStorage(demos.numel()), batch_size=expert_batch)
        self.expert_buffer.extend(demos)
        self.policy_buffer = TensorDictReplayBuffer(
            storage=LazyMemmapStorage(algo.buffer_size, scratch_dir=self.run.replay_dir / "storage", existsok=True),
            batch_size=algo.batch_size - expert_batch)
        self.updates = 0
        self.update_debt = 0.0  # fractional gradient steps owed by the UTD ratio
        frames = algo.frames_per_batch
        self.collector = ResumableCollector(
            self.env, self.policy, frames_per_batch=frames, total_frames=-1,
            init_random_frames=math.ceil(algo.random_steps / frames) * frames if algo.random_steps else None,
            device="cpu", auto_register_policy_transforms=False,
        )
        self.batches = iter(self.collector)

    def train_step(self) -> Mapping[str, float]:
        batch = next(self.batches)
        transitions = batch.reshape(-1).select(*_COLLECTED_KEYS)
        transitions.set("expert", torch.zeros((*transitions.batch_size, 1), dtype=torch.bool))
        self.policy_buffer.extend(transitions.exclude(("next", "reward")))
        self.progress += transitions.numel()
        scalars: dict[str, float] = {"train/reward_per_step": transitions["next", "reward"].mean().item()}
        if self.progress <= self.cfg.algo.random_steps:
            return scalars
        self.update_debt += self.cfg.algo.utd_ratio * transitions.numel()
        losses = []
        while self.update_debt >= 1.0:
            self.update_debt -= 1.0
            losses.append(self._update())
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
        for params in (self.loss.qvalue_network_params, self.loss.actor_network_params):
            torch.nn.utils.clip_grad_norm_(list(params.flatten_keys().values()), self.cfg.algo.max_grad_norm)
        for optimizer in self.optimizers:
            optimizer.step()
        if self.critic_schedule is not None and self.updates < self.total_updates:
            self.critic_schedule.step()
        self.target_updater.step()
        self.updates += 1
        return {"train/loss_qvalue": out["loss_qvalue"].item(), "train/loss_actor": out["loss_actor"].item(),
                "train/alpha": out["alpha"].item(), "train/entropy": out["entropy"].item()}

    def close(self) -> None:
        self.collector.shutdown()

    def finish(self) -> None:
        """Drops the replay buffer of a finished run that cannot be continued."""
        if not self.extendable_budget(self.cfg):
            shutil.rmtree(self.run.replay_dir, ignore_errors=True)

    def training_state(self) -> dict[str, Any]:
        # Zero-copy: the storage already lives in replay/storage; this writes its length,
        # the writer's cursor and the sampler's state beside it.
        self.policy_buffer.dumps(self.run.replay_dir)
        return {
            "loss": self.loss.state_dict(),
            "actor_optimizer": self.actor_optimizer.state_dict(),
            "critic_optimizer": self.critic_optimizer.state_dict(),
            "alpha_optimizer": self.alpha_optimizer.state_dict(),
            "critic_schedule": self.critic_schedule.state_dict() if self.critic_schedule is not None else {},
            "policy_buffer_len": len(self.policy_buffer),
            "collector": self.collector.state_dict(),
            "updates": self.updates,
            "update_debt": self.update_debt,
        }

    def load_training_state(self, state: Mapping[str, Any]) -> None:
        self.loss.load_state_dict(state["loss"])
        self.actor_optimizer.load_state_dict(state["actor_optimizer"])
        self.critic_optimizer.load_state_dict(state["critic_optimizer"])
        self.alpha_optimizer.load_state_dict(state["alpha_optimizer"])
        if self.critic_schedule is not None:
            self.critic_schedule.load_state_dict(state["critic_schedule"])
        if state["policy_buffer_len"]:
            try:
                self.policy_buffer.loads(self.run.replay_dir)
            except (OSError, ValueError, KeyError) as error:
                raise CheckpointError(f"the replay buffer in {self.run.replay_dir} cannot be read: {error}") from error
            if len(self.policy_buffer) != state["policy_buffer_len"]:
                # The run was killed between saving the buffer and the checkpoint: the
                # buffer holds a few more (valid) transitions than the checkpoint counted.
                log.warning("the replay buffer in %s holds %d transitions, the checkpoint counted %d; continuing",
                            self.run.replay_dir, len(self.policy_buffer), state["policy_buffer_len"])
        self.collector.load_state_dict(state["collector"])
        self.updates = int(state["updates"])
        self.update_debt = float(state["update_debt"])
