"""GAIL (Causal GAIL with a causal window): rounds of on-policy episodes, discriminator
updates, then PPO epochs on the discriminator's reward (Appendix E's protocol).

Each round a TorchRL :class:`~torchrl.collectors.Collector` steps ``episodes_per_round``
envs for ``horizon`` steps each (at least that many episodes; finished ones restart).
The discriminator (TorchRL's ``GAILLoss`` with a gradient penalty) takes
``discriminator_updates`` steps on minibatches of expert and fresh policy transitions,
its learning rate halving every ``discriminator_lr_step`` rounds (StepLR). The
discriminator's reward (``algo.reward``: its logit by default) feeds GAE, and
``ppo_epochs`` passes of clipped PPO over shuffled minibatches update the actor and
value network, with gradient-norm clipping. With ``algo.absorbing`` expert and policy
transitions get absorbing states for the discriminator, and terminal steps the
absorbing state's discounted reward.

The actor has no dropout (``algo.actor.dropout`` must be 0): PPO's ratio divides the
loss's probability of an action by the one recorded when it was taken, and a mask
redrawn at every forward pass makes that ratio noise even before any update.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import torch
from omegaconf import DictConfig
from tensordict import TensorDictBase
from tensordict.nn import TensorDictModuleBase
from torchrl.collectors import Collector
from torchrl.envs import EnvBase

from torchrl_causal.modules import make_gail_discriminator, make_gail_value_network, make_tanh_gaussian_actor
from torchrl_causal.objectives import ABSORBING_KEY, add_absorbing_transitions, gail_discriminator_batch, make_gail_losses
from torchrl_causal.trainers.base import Trainer
from torchrl_causal.trainers.device import CPU
from torchrl_causal.trainers.builders import (
    TRANSITION_KEYS,
    expert_transitions,
    load_or_collect_demonstrations,
    make_imitator_env,
    observation_dim,
)

__all__ = ["GAILTrainer"]


class GAILTrainer(Trainer):
    """(Causal) GAIL; progress is counted in rounds."""

    unit = "rounds"

    @property
    def total(self) -> int:
        return int(self.cfg.algo.rounds)

    @classmethod
    def build_policy(cls, cfg: DictConfig, env: EnvBase) -> TensorDictModuleBase:
        a = cfg.algo.actor
        return make_tanh_gaussian_actor(observation_dim(env), env.action_spec, hidden=int(a.hidden),
                                        num_blocks=int(a.blocks), dropout=float(a.dropout))

    @property
    def policy(self) -> TensorDictModuleBase:
        return self.losses.policy.actor_network

    def setup(self) -> None:
        algo = self.cfg.algo
        if float(algo.actor.dropout) != 0.0:
            raise ValueError(f"algo.actor.dropout must be 0 for GAIL, got {algo.actor.dropout}: PPO's probability ratio "
                             "needs the actor that collected the rollout, not a copy with a fresh dropout mask")
        self.env = make_imitator_env(self.cfg, self.window, "train", int(algo.episodes_per_round), int(self.cfg.seed))
        dim = observation_dim(self.env)
        self.losses = make_gail_losses(
            self.build_policy(self.cfg, self.env).to(self.device),
            make_gail_value_network(dim, hidden=int(algo.value.hidden)).to(self.device),
            make_gail_discriminator(dim + bool(algo.absorbing), self.env.action_spec,
                                    hidden=int(algo.discriminator.hidden),
                                    dropout=float(algo.discriminator.dropout)).to(self.device),
            gamma=float(algo.gamma), gae_lambda=float(algo.gae_lambda), clip_epsilon=float(algo.clip_epsilon),
            entropy_coeff=float(algo.entropy_coef), critic_coeff=float(algo.critic_coef),
            gp_lambda=float(algo.gradient_penalty), normalize_advantage=bool(algo.normalize_advantage),
            reward=str(algo.reward), absorbing=bool(algo.absorbing),
        )
        ppo = self.losses.policy
        self.policy_optimizer = torch.optim.Adam([
            {"params": list(ppo.actor_network_params.flatten_keys().values()), "lr": float(algo.lr_actor)},
            {"params": list(ppo.critic_network_params.flatten_keys().values()), "lr": float(algo.lr_critic)},
        ])
        self.discriminator_optimizer = torch.optim.Adam(self.losses.discriminator.parameters(),
                                                        lr=float(algo.lr_discriminator))
        self.discriminator_schedule = torch.optim.lr_scheduler.StepLR(
            self.discriminator_optimizer, step_size=int(algo.discriminator_lr_step), gamma=float(algo.discriminator_lr_gamma))
        self.expert = self._discriminator_rows(
            expert_transitions(self.window, load_or_collect_demonstrations(self.cfg))).to(self.device)
        self.generator = torch.Generator().manual_seed(int(self.cfg.seed))
        self.collector = None

    def _discriminator_rows(self, transitions: TensorDictBase) -> TensorDictBase:
        """What the discriminator sees of flat transitions (with their absorbing states, when enabled)."""
        if bool(self.cfg.algo.absorbing):
            return add_absorbing_transitions(transitions).select("observation", "action", ABSORBING_KEY)
        return transitions.select("observation", "action")

    def _sample(self, data: TensorDictBase, size: int) -> TensorDictBase:
        return data[torch.randint(data.numel(), (min(size, data.numel()),), generator=self.generator)]

    def _update_discriminator(self, rollout: TensorDictBase) -> torch.Tensor:
        algo = self.cfg.algo
        size = min(int(algo.discriminator_batch_size), rollout.numel(), self.expert.numel())
        losses = []
        for _ in range(int(algo.discriminator_updates)):
            batch = gail_discriminator_batch(self.losses.discriminator, self._sample(self.expert, size),
                                             self._sample(rollout, size))
            loss = self.losses.discriminator(batch)["loss"]
            self.discriminator_optimizer.zero_grad(set_to_none=True)
            loss.backward()
            self.discriminator_optimizer.step()
            losses.append(loss.detach())
        return torch.stack(losses).mean()

    def _update_policy(self, rollout: TensorDictBase) -> dict[str, torch.Tensor]:
        algo = self.cfg.algo
        ppo = self.losses.policy
        params = [p for group in self.policy_optimizer.param_groups for p in group["params"]]
        sums: dict[str, torch.Tensor] = {}
        count = 0
        for _ in range(int(algo.ppo_epochs)):
            order = torch.randperm(rollout.numel(), generator=self.generator)
            for start in range(0, rollout.numel(), int(algo.batch_size)):
                out = ppo(rollout[order[start:start + int(algo.batch_size)]])
                loss = out["loss_objective"] + out["loss_critic"] + out["loss_entropy"]
                self.policy_optimizer.zero_grad(set_to_none=True)
                loss.backward()
                torch.nn.utils.clip_grad_norm_(params, float(algo.max_grad_norm))
                self.policy_optimizer.step()
                for key in ("loss_objective", "loss_critic", "loss_entropy", "clip_fraction"):
                    sums[key] = sums.get(key, 0.0) + out[key].detach()
                count += 1
        return {f"train/{k}": v / count for k, v in sums.items()}

    def collect(self) -> TensorDictBase:
        """One round's rollout, ``[episodes_per_round, horizon]`` with time last."""
        if self.collector is None:
            self.env.set_seed(int(self.cfg.seed) * 1_000_003 + self.progress)
            frames = int(self.cfg.algo.episodes_per_round) * int(self.cfg.env.horizon)
            self.collector = iter(Collector(self.env, self.policy, frames_per_batch=frames, total_frames=-1,
                                            env_device=CPU, policy_device=self.device, storing_device=self.device,
                                            auto_register_policy_transforms=False))
        return next(self.collector)

    def train_step(self) -> Mapping[str, torch.Tensor]:
        rollout = self.collect()
        policy_rows = self._discriminator_rows(rollout.reshape(-1).select(*TRANSITION_KEYS))
        scalars = {"train/env_reward_per_step": rollout["next", "reward"].mean(),
                   "train/loss_discriminator": self._update_discriminator(policy_rows)}
        with torch.no_grad():
            rollout = self.losses.reward(rollout)
            rollout = self.losses.policy.value_estimator(rollout)
        scalars["train/discriminator_reward"] = rollout["next", "reward"].mean()
        scalars.update(self._update_policy(rollout.reshape(-1)))
        self.discriminator_schedule.step()
        self.progress += 1
        return scalars

    def close(self) -> None:
        self.collector = None
        self.env.close()

    def training_state(self) -> dict[str, Any]:
        return {
            "policy_loss": self.losses.policy.state_dict(),
            "discriminator": self.losses.discriminator.state_dict(),
            "policy_optimizer": self.policy_optimizer.state_dict(),
            "discriminator_optimizer": self.discriminator_optimizer.state_dict(),
            "discriminator_schedule": self.discriminator_schedule.state_dict(),
            "generator": self.generator.get_state(),
        }

    def load_training_state(self, state: Mapping[str, Any]) -> None:
        self.losses.policy.load_state_dict(state["policy_loss"])
        self.losses.discriminator.load_state_dict(state["discriminator"])
        self.policy_optimizer.load_state_dict(state["policy_optimizer"])
        self.discriminator_optimizer.load_state_dict(state["discriminator_optimizer"])
        self.discriminator_schedule.load_state_dict(state["discriminator_schedule"])
        self.generator.set_state(state["generator"].cpu())
        self.collector = None
