"""Causal GAIL wiring: TorchRL's :class:`~torchrl.objectives.GAILLoss` and :class:`~torchrl.objectives.ClipPPOLoss`.

Nothing here re-implements GAIL or PPO. :func:`make_gail_losses` configures the two
TorchRL losses with the paper's hyperparameters (Appendix E),
:class:`DiscriminatorReward` turns the discriminator into the reward PPO's GAE reads,
and :func:`gail_discriminator_batch` pairs expert and policy transitions in the layout
``GAILLoss`` expects.
"""

from __future__ import annotations

from typing import NamedTuple

import torch
from tensordict import TensorDict, TensorDictBase
from tensordict.nn import ProbabilisticTensorDictSequential, TensorDictModule, TensorDictModuleBase
from tensordict.utils import NestedKey
from torchrl.objectives import ClipPPOLoss, GAILLoss
from torchrl.objectives.utils import ValueEstimators

__all__ = ["DiscriminatorReward", "GAILLosses", "gail_discriminator_batch", "make_gail_losses"]


class DiscriminatorReward(TensorDictModuleBase):
    r"""Writes GAIL's reward :math:`-\log(1 - D(z, x))` to ``("next", "reward")``.

    ``D`` is the discriminator's probability that ``(observation, action)`` is an expert
    transition (TorchRL's :class:`~torchrl.objectives.GAILLoss` convention: label 1 for
    expert). The discriminator is evaluated without gradient and in eval mode (no
    dropout), then restored to its previous mode. Run it on collected rollouts before
    PPO computes advantages (e.g. as a collector ``postproc`` or right before
    ``ppo_loss.value_estimator(batch)``).

    Args:
        discriminator (TensorDictModule): writes the probability at ``probability_key``.

    Keyword Args:
        probability_key (NestedKey, optional): discriminator output. Defaults to ``"d_logits"``.
        reward_key (NestedKey, optional): where the reward goes. Defaults to ``("next", "reward")``.
        eps (float, optional): ``D`` is clamped to ``1 - eps`` so the reward stays finite.
            Defaults to ``1e-6``.

    Examples:
        >>> import torch
        >>> from tensordict import TensorDict
        >>> from torchrl.data import Bounded
        >>> from torchrl_causal.modules import make_gail_discriminator
        >>> spec = Bounded(-1.0, 1.0, shape=(2,))
        >>> reward = DiscriminatorReward(make_gail_discriminator(3, spec, hidden=8))
        >>> rollout = TensorDict({"observation": torch.randn(4, 5, 3), "action": spec.rand((4, 5))}, [4, 5])
        >>> r = reward(rollout)["next", "reward"]
        >>> r.shape, bool((r > 0).all())
        (torch.Size([4, 5, 1]), True)
    """

    def __init__(
        self,
        discriminator: TensorDictModule,
        *,
        probability_key: NestedKey = "d_logits",
        reward_key: NestedKey = ("next", "reward"),
        eps: float = 1e-6,
    ) -> None:
        super().__init__()
        if probability_key not in discriminator.out_keys:
            raise KeyError(
                f"discriminator writes {discriminator.out_keys}, not the probability key {probability_key!r}."
            )
        self.discriminator = discriminator
        self.probability_key = probability_key
        self.eps = eps
        self.in_keys = list(discriminator.in_keys)
        self.out_keys = [reward_key]

    @torch.no_grad()
    def forward(self, tensordict: TensorDictBase) -> TensorDictBase:
        was_training = self.discriminator.training
        self.discriminator.eval()
        try:
            probability = self.discriminator(tensordict.select(*self.in_keys)).get(self.probability_key)
        finally:
            self.discriminator.train(was_training)
        tensordict.set(self.out_keys[0], -torch.log1p(-probability.clamp(max=1.0 - self.eps)))
        return tensordict


def gail_discriminator_batch(loss: GAILLoss, expert: TensorDictBase, policy: TensorDictBase) -> TensorDict:
    """Pairs equally many expert and policy transitions in the layout :class:`~torchrl.objectives.GAILLoss` reads.

    Both inputs carry ``"observation"`` and ``"action"`` (or the keys the loss's
    discriminator uses); policy entries move to the loss's ``collector_*`` keys.

    Examples:
        >>> import torch
        >>> from tensordict import TensorDict
        >>> from torchrl.objectives import GAILLoss
        >>> from torchrl.data import Bounded
        >>> from torchrl_causal.modules import make_gail_discriminator
        >>> spec = Bounded(-1.0, 1.0, shape=(2,))
        >>> loss = GAILLoss(make_gail_discriminator(3, spec, hidden=8), use_grad_penalty=True, gp_lambda=5.0)
        >>> make = lambda: TensorDict({"observation": torch.randn(6, 3), "action": spec.rand((6,))}, [6])
        >>> batch = gail_discriminator_batch(loss, make(), make())
        >>> sorted(batch.keys())
        ['action', 'collector_action', 'collector_observation', 'observation']
    """
    if expert.batch_size != policy.batch_size:
        raise ValueError(
            f"GAILLoss needs as many expert as policy transitions, got batch sizes {tuple(expert.batch_size)} "
            f"(expert) and {tuple(policy.batch_size)} (policy)."
        )
    keys = loss.tensor_keys
    pairs = {
        keys.expert_observation: expert.get(keys.expert_observation),
        keys.expert_action: expert.get(keys.expert_action),
        keys.collector_observation: policy.get(keys.expert_observation),
        keys.collector_action: policy.get(keys.expert_action),
    }
    return TensorDict(pairs, batch_size=expert.batch_size)


class GAILLosses(NamedTuple):
    """The three pieces of a GAIL round: discriminator loss, PPO loss, reward writer."""

    discriminator: GAILLoss
    policy: ClipPPOLoss
    reward: DiscriminatorReward


def make_gail_losses(
    actor: ProbabilisticTensorDictSequential,
    value_network: TensorDictModule,
    discriminator: TensorDictModule,
    *,
    gamma: float = 0.99,
    gae_lambda: float = 0.95,
    clip_epsilon: float = 0.2,
    entropy_coeff: float = 1e-2,
    critic_coeff: float = 0.5,
    gp_lambda: float = 5.0,
    normalize_advantage: bool = True,
) -> GAILLosses:
    """Builds GAIL with the paper's settings from TorchRL's ``GAILLoss`` and ``ClipPPOLoss``.

    The discriminator loss is binary cross-entropy (expert = 1) plus a gradient penalty
    ``gp_lambda * E[(||grad D|| - 1)^2]`` on expert/policy interpolates. PPO uses
    clipping ``clip_epsilon``, an entropy bonus, a squared-error value loss weighted by
    ``critic_coeff``, normalised advantages and GAE(``gamma``, ``gae_lambda``) on the
    reward that :class:`DiscriminatorReward` writes.

    Examples:
        >>> import torch
        >>> from tensordict import TensorDict
        >>> from torchrl.data import Bounded
        >>> from torchrl_causal.modules import (
        ...     make_gail_discriminator, make_gail_value_network, make_tanh_gaussian_actor)
        >>> spec = Bounded(-1.0, 1.0, shape=(2,))
        >>> gail = make_gail_losses(
        ...     make_tanh_gaussian_actor(3, spec, hidden=8, num_blocks=1),
        ...     make_gail_value_network(3, hidden=8),
        ...     make_gail_discriminator(3, spec, hidden=8))
        >>> rollout = TensorDict({
        ...     "observation": torch.randn(2, 5, 3),
        ...     "next": {"observation": torch.randn(2, 5, 3),
        ...              "done": torch.zeros(2, 5, 1, dtype=torch.bool),
        ...              "terminated": torch.zeros(2, 5, 1, dtype=torch.bool)},
        ... }, [2, 5])
        >>> with torch.no_grad():
        ...     rollout = gail.policy.actor_network(rollout)  # writes action and its log-prob
        >>> rollout = gail.reward(rollout)
        >>> with torch.no_grad():
        ...     rollout = gail.policy.value_estimator(rollout)  # GAE on the discriminator's reward
        >>> ppo_out = gail.policy(rollout.reshape(-1))
        >>> sorted(k for k in ppo_out.keys() if k.startswith("loss_"))
        ['loss_critic', 'loss_entropy', 'loss_objective']
        >>> expert = TensorDict({"observation": torch.randn(10, 3), "action": spec.rand((10,))}, [10])
        >>> d_out = gail.discriminator(gail_discriminator_batch(gail.discriminator, expert, rollout.reshape(-1)))
        >>> sorted(d_out.keys())
        ['gp_loss', 'loss']
    """
    discriminator_loss = GAILLoss(discriminator, use_grad_penalty=True, gp_lambda=gp_lambda)
    policy_loss = ClipPPOLoss(
        actor,
        value_network,
        clip_epsilon=clip_epsilon,
        entropy_coeff=entropy_coeff,
        critic_coeff=critic_coeff,
        loss_critic_type="l2",
        normalize_advantage=normalize_advantage,
    )
    policy_loss.make_value_estimator(ValueEstimators.GAE, gamma=gamma, lmbda=gae_lambda)
    probability_key = discriminator_loss.tensor_keys.discriminator_pred
    return GAILLosses(discriminator_loss, policy_loss, DiscriminatorReward(discriminator, probability_key=probability_key))
