"""GAIL (Causal GAIL with a causal window): rounds of on-policy episodes, discriminator
updates, then PPO epochs on the discriminator's reward (Appendix E's protocol).

Each round a TorchRL collector steps ``episodes_per_round``
envs for ``horizon`` steps each (at least that many episodes; finished ones restart).
The discriminator (a gradient penalty on its logit) makes ``discriminator_epochs``
passes over the round's policy transitions in shuffled minibatches of
``discriminator_batch_size``, each paired with as many expert transitions drawn at
random, its learning rate halving every ``discriminator_scheduler.step_size`` rounds
(StepLR). The discriminator's reward
(``algo.loss.reward``: its logit by default) feeds GAE, and ``ppo_epochs`` passes of
clipped PPO over shuffled minibatches update the actor and value network, with
gradient-norm clipping. With ``algo.loss.absorbing`` expert and policy transitions get
absorbing states for the discriminator, and terminal steps the absorbing state's
discounted reward.

``algo.warm_start`` (off in the paper's configs; ``+recipe=gail_bc_start``) starts the actor
from maximum-likelihood behaviour cloning on the expert transitions
(:meth:`~GAILTrainer.clone_expert_actions`, ``bc_updates`` steps of ``algo.batch_size``
rows) before the first rollout, then holds it for ``critic_rounds`` rounds in which the
discriminator and the value network learn its rollouts: PPO's first actor updates then
read advantages from a critic fitted to this actor, not from a random one.

The actor has no dropout (``algo.actor.dropout`` must be 0, which
:func:`~torchrl_causal.experiment.schema.validate_config` enforces): PPO's ratio divides the
loss's probability of an action by the one recorded when it was taken, and a mask
redrawn at every forward pass makes that ratio noise even before any update.

Networks, losses, optimisers and the expert data live on ``cfg.device``; the envs step
on the CPU and the collector moves observations to the policy and actions back.
"""

from __future__ import annotations

from collections.abc import Iterator, Mapping
from typing import Any

import torch
from hydra.utils import instantiate
from omegaconf import DictConfig
from tensordict import TensorDictBase
from tensordict.nn import TensorDictModuleBase

from torchrl_causal.errors import InvalidStateError
from torchrl_causal.experiment.builders import TRANSITION_KEYS, instantiate_with_strings, make_imitator_env, make_policy, observation_dim
from torchrl_causal.experiment.device import CPU
from torchrl_causal.objectives import ABSORBING_KEY, add_absorbing_transitions, gail_discriminator_batch
from torchrl_causal.objectives.utils import gaussian_nll, interior_actions
from torchrl_causal.trainers.base import Trainer
from torchrl_causal.trainers.collection import ResumableCollector
from torchrl_causal.trainers.warm_start import behaviour_clone

__all__ = ["GAILTrainer"]


class GAILTrainer(Trainer):
    """(Causal) GAIL; progress is counted in rounds."""

    unit = "rounds"
    budget_key = "algo.rounds"

    @property
    def policy(self) -> TensorDictModuleBase:
        return self.losses.policy.actor_network

    def setup(self) -> None:
        algo = self.cfg.algo
        self.env = make_imitator_env(self.cfg, self.window, "train", algo.episodes_per_round, self.cfg.seed)
        dim, spec = observation_dim(self.env), self.env.action_spec
        # With absorbing states the discriminator also reads the absorbing flag as one more feature.
        self.losses = instantiate_with_strings(algo.loss)(
            make_policy(self.cfg, self.env).to(self.device),
            instantiate(algo.value)(dim).to(self.device),
            instantiate(algo.discriminator)(dim + int(algo.loss.absorbing), spec).to(self.device),
        )
        ppo = self.losses.policy
        self.actor_optimizer = instantiate(algo.actor_optimizer)(list(ppo.actor_network_params.flatten_keys().values()))
        self.critic_optimizer = instantiate(algo.critic_optimizer)(list(ppo.critic_network_params.flatten_keys().values()))
        self.discriminator_optimizer = instantiate(algo.discriminator_optimizer)(self.losses.discriminator.parameters())
        self.discriminator_schedule = instantiate(algo.discriminator_scheduler)(self.discriminator_optimizer)
        self.expert = self.discriminator_rows(self.demonstration_transitions()).to(self.device)
        self.generator = torch.Generator().manual_seed(self.cfg.seed)
        self.collector = ResumableCollector(
            self.env,
            self.policy,
            frames_per_batch=algo.episodes_per_round * self.cfg.env.horizon,
            total_frames=-1,
            env_device=CPU,
            policy_device=self.device,
            storing_device=self.device,
            auto_register_policy_transforms=False,
        )
        self.rollouts = iter(self.collector)

    def discriminator_rows(self, transitions: TensorDictBase) -> TensorDictBase:
        """What the discriminator sees of flat transitions (with their absorbing states, when enabled)."""
        if self.cfg.algo.loss.absorbing:
            return add_absorbing_transitions(transitions).select("observation", "action", ABSORBING_KEY)
        return transitions.select("observation", "action")

    @property
    def policy_optimizers(self) -> tuple[torch.optim.Optimizer, ...]:
        return self.actor_optimizer, self.critic_optimizer

    @property
    def warm_start(self) -> DictConfig | None:
        """``algo.warm_start`` (``bc_updates``, ``critic_rounds``), or ``None`` (the paper's random actor)."""
        return self.cfg.algo.get("warm_start")

    @property
    def actor_held(self) -> bool:
        """Whether this round is one of the warm start's critic rounds, in which PPO leaves the actor as it is."""
        return self.warm_start is not None and self.progress < self.warm_start.critic_rounds

    def expert_nll(self, rows: TensorDictBase) -> torch.Tensor:
        """Mean negative log-likelihood of expert ``rows``' actions under the actor's
        distribution (PPO's loss parameters, so the gradient reaches what PPO trains)."""
        ppo = self.losses.policy
        actions = interior_actions(ppo.actor_network.spec["action"], rows.get("action"))
        weights = torch.full((rows.numel(), 1), 1.0 / rows.numel(), device=actions.device)
        with ppo.actor_network_params.to_module(ppo.actor_network, preserve_module_state=False):
            return gaussian_nll(ppo.actor_network, rows, actions, weights)

    def clone_expert_actions(self) -> None:
        """Warm start, part 1: ``warm_start.bc_updates`` steps of maximum-likelihood behaviour
        cloning of the actor (mean and spread) on ``algo.batch_size`` expert rows drawn at
        random, with an Adam of its own (``algo.actor_optimizer``'s settings)."""
        if self.warm_start is None:
            raise InvalidStateError(f"{type(self).__name__}: a warm start needs algo.warm_start (bc_updates, critic_rounds)")
        params = list(self.losses.policy.actor_network_params.flatten_keys().values())
        optimizer = instantiate(self.cfg.algo.actor_optimizer)(params)
        behaviour_clone(
            lambda: self.expert_nll(self._sample(self.expert, self.cfg.algo.batch_size)),
            optimizer,
            self.warm_start.bc_updates,
            self.cfg.algo.max_grad_norm,
        )

    def _sample(self, data: TensorDictBase, size: int) -> TensorDictBase:
        return data[torch.randint(data.numel(), (min(size, data.numel()),), generator=self.generator)]

    def _minibatches(self, rows: TensorDictBase, batch_size: int, epochs: int) -> Iterator[TensorDictBase]:
        """``epochs`` passes over ``rows`` in minibatches of ``batch_size``, reshuffled every pass."""
        for _ in range(epochs):
            order = torch.randperm(rows.numel(), generator=self.generator)
            for start in range(0, rows.numel(), batch_size):
                yield rows[order[start : start + batch_size]]

    def _update_discriminator(self, policy_rows: TensorDictBase) -> torch.Tensor:
        """``discriminator_epochs`` passes over ``policy_rows``; returns the mean loss."""
        algo = self.cfg.algo
        size = min(algo.discriminator_batch_size, self.expert.numel())
        losses = []
        for policy in self._minibatches(policy_rows, size, algo.discriminator_epochs):
            batch = gail_discriminator_batch(self.losses.discriminator, self._sample(self.expert, policy.numel()), policy)
            loss = self.losses.discriminator(batch)["loss"]
            self.discriminator_optimizer.zero_grad(set_to_none=True)
            loss.backward()
            self.discriminator_optimizer.step()
            losses.append(loss.detach())
        self.updates_done += len(losses)
        return torch.stack(losses).mean()

    def _update_policy(self, rollout: TensorDictBase) -> dict[str, torch.Tensor]:
        algo = self.cfg.algo
        ppo = self.losses.policy
        sums: dict[str, torch.Tensor] = {}
        count = 0
        # A warm start's critic rounds step the critic alone, on its own loss.
        optimizers = (self.critic_optimizer,) if self.actor_held else self.policy_optimizers
        params = [p for optimizer in optimizers for group in optimizer.param_groups for p in group["params"]]
        for minibatch in self._minibatches(rollout, algo.batch_size, algo.ppo_epochs):
            out = ppo(minibatch)
            if self.actor_held:
                loss = out["loss_critic"]
            else:
                loss = out["loss_objective"] + out["loss_critic"] + out["loss_entropy"]
            for optimizer in optimizers:
                optimizer.zero_grad(set_to_none=True)
            loss.backward()
            torch.nn.utils.clip_grad_norm_(params, algo.max_grad_norm)
            for optimizer in optimizers:
                optimizer.step()
            for key in ("loss_objective", "loss_critic", "loss_entropy", "clip_fraction"):
                sums[key] = sums.get(key, 0.0) + out[key].detach()
            count += 1
        self.updates_done += count
        return {f"train/{k}": v / count for k, v in sums.items()}

    def train_step(self) -> Mapping[str, torch.Tensor]:
        # A fresh run's warm start (progress says whether it ran: a resumed run never repeats it).
        if self.warm_start is not None and self.progress == 0 and self.warm_start.bc_updates:
            self.clone_expert_actions()
        rollout = next(self.rollouts)  # [episodes_per_round, horizon], time last
        self.env_steps_done += rollout.numel()
        policy_rows = self.discriminator_rows(rollout.reshape(-1).select(*TRANSITION_KEYS))
        scalars = {
            "train/env_reward_per_step": rollout["next", "reward"].mean(),
            "train/loss_discriminator": self._update_discriminator(policy_rows),
        }
        with torch.no_grad():
            rollout = self.losses.reward(rollout)
            rollout = self.losses.policy.value_estimator(rollout)
        scalars["train/discriminator_reward"] = rollout["next", "reward"].mean()
        scalars.update(self._update_policy(rollout.reshape(-1)))
        self.discriminator_schedule.step()
        self.progress += 1
        return scalars

    def close(self) -> None:
        self.collector.shutdown()

    def training_state(self) -> dict[str, Any]:
        return {
            "policy_loss": self.losses.policy.state_dict(),
            "discriminator": self.losses.discriminator.state_dict(),
            "actor_optimizer": self.actor_optimizer.state_dict(),
            "critic_optimizer": self.critic_optimizer.state_dict(),
            "discriminator_optimizer": self.discriminator_optimizer.state_dict(),
            "discriminator_schedule": self.discriminator_schedule.state_dict(),
            "generator": self.generator.get_state(),
            "collector": self.collector.state_dict(),
        }

    def load_training_state(self, state: Mapping[str, Any]) -> None:
        self.losses.policy.load_state_dict(state["policy_loss"])
        self.losses.discriminator.load_state_dict(state["discriminator"])
        self.actor_optimizer.load_state_dict(state["actor_optimizer"])
        self.critic_optimizer.load_state_dict(state["critic_optimizer"])
        self.discriminator_optimizer.load_state_dict(state["discriminator_optimizer"])
        self.discriminator_schedule.load_state_dict(state["discriminator_schedule"])
        self.generator.set_state(state["generator"].cpu())
        self.collector.load_state_dict(state["collector"])
