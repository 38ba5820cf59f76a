r"""Causal GAIL on TorchRL's :class:`~torchrl.objectives.GAILLoss` and :class:`~torchrl.objectives.ClipPPOLoss`.

:func:`make_gail_losses` configures the discriminator loss and PPO with the paper's
hyperparameters (Appendix E), :class:`DiscriminatorReward` turns the discriminator
into the reward PPO's GAE reads, and :func:`gail_discriminator_batch` pairs expert and
policy transitions in the layout ``GAILLoss`` expects.

Three choices differ from a literal reading of the paper's "BCE + gradient penalty,
reward :math:`-\log(1 - D)`", each because the literal version does not learn the task:

* the discriminator outputs a logit and :class:`GAILDiscriminatorLoss` applies the
  gradient penalty to the logit with one interpolation weight per sample (Gulrajani
  et al., 2017); TorchRL's ``GAILLoss`` penalises the sigmoid probability, whose gradient
  cannot have unit norm where it saturates, with an independent weight per coordinate;
* the default reward is the logit :math:`\log D - \log(1 - D)`, zero where the
  discriminator cannot tell (see :class:`DiscriminatorReward`);
* the actor must act and be scored without dropout (PPO's ratio is only 1 before an
  update if the rollout and the loss evaluate the same policy).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal, NamedTuple

import torch
import torch.nn.functional as F
from tensordict import TensorDict, TensorDictBase
from tensordict.nn import ProbabilisticTensorDictSequential, TensorDictModule, TensorDictModuleBase, dispatch
from tensordict.utils import NestedKey
from torchrl.objectives import ClipPPOLoss, GAILLoss
from torchrl.objectives.utils import ValueEstimators

from torchrl_causal.compat import InKeysHook, reduce_loss
from torchrl_causal.errors import InvalidValueError, UnknownKeyError
from torchrl_causal.objectives.absorbing import ABSORBING_KEY, AbsorbingIndicator
from torchrl_causal.objectives.utils import eval_mode

__all__ = [
    "DiscriminatorReward",
    "GAILDiscriminatorLoss",
    "GAILLosses",
    "GAIL_REWARDS",
    "gail_discriminator_batch",
    "make_gail_losses",
]

#: The rewards :class:`DiscriminatorReward` can write.
GAIL_REWARDS: tuple[str, ...] = ("logit", "positive")


class GAILDiscriminatorLoss(InKeysHook, GAILLoss):
    r"""GAIL's discriminator loss on logits, with a per-sample gradient penalty.

    For ``N`` expert and ``N`` policy pairs and the discriminator logit :math:`\ell`,

    .. math::

        \mathcal L = \frac1N \sum_i \big[\operatorname{BCE}(\ell(u^E_i), 1)
            + \operatorname{BCE}(\ell(u^\pi_i), 0)\big]
            + \lambda\, \frac1N \sum_i \big(\lVert \nabla_u \ell(\hat u_i) \rVert_2 - 1\big)^2,
        \qquad \hat u_i = \epsilon_i u^\pi_i + (1 - \epsilon_i) u^E_i,\ \epsilon_i \sim U(0, 1),

    where :math:`u = (z, x)` and the gradient is taken with respect to observation and
    action together (Gulrajani et al., "Improved Training of Wasserstein GANs", 2017).
    The keys and batch layout are TorchRL's :class:`~torchrl.objectives.GAILLoss`'s;
    ``"gp_loss"`` is reported detached.

    With a discriminator wrapped in
    :class:`~torchrl_causal.objectives.absorbing.AbsorbingIndicator`, expert and
    policy rows also carry an absorbing flag (``expert_absorbing`` /
    ``collector_absorbing`` keys); pairs with an absorbing end are left out of the
    penalty (a path toward the absorbing state's zero observation crosses no real state).

    Args:
        discriminator_network (TensorDictModule): writes the logit at ``"d_logits"``.

    Keyword Args:
        use_grad_penalty (bool, optional): add the penalty. Defaults to ``True``.
        gp_lambda (float, optional): its weight. Defaults to ``5.0`` (paper).

    Examples:
        >>> import torch
        >>> from tensordict import TensorDict
        >>> from torchrl.data import Bounded
        >>> from torchrl_causal.modules import make_gail_discriminator
        >>> spec = Bounded(-1.0, 1.0, shape=(2,))
        >>> loss = GAILDiscriminatorLoss(make_gail_discriminator(3, spec, hidden=8))
        >>> make = lambda: TensorDict({"observation": torch.randn(6, 3), "action": spec.rand((6,))}, [6])
        >>> out = loss(gail_discriminator_batch(loss, make(), make()))
        >>> sorted(out.keys())
        ['gp_loss', 'loss']
        >>> out["loss"].backward()
    """

    @dataclass
    class _AcceptedKeys(GAILLoss._AcceptedKeys):
        """TorchRL's GAIL keys plus the absorbing flags of expert and policy rows.

        Attributes:
            expert_absorbing (NestedKey): defaults to ``"absorbing"``.
            collector_absorbing (NestedKey): defaults to ``"collector_absorbing"``.
        """

        expert_absorbing: NestedKey = ABSORBING_KEY
        collector_absorbing: NestedKey = "collector_absorbing"

    default_keys = _AcceptedKeys
    tensor_keys: _AcceptedKeys

    def __init__(
        self,
        discriminator_network: TensorDictModule,
        *,
        use_grad_penalty: bool = True,
        gp_lambda: float = 5.0,
        reduction: str | None = None,
    ) -> None:
        super().__init__(discriminator_network, use_grad_penalty=use_grad_penalty, gp_lambda=gp_lambda, reduction=reduction)

    @property
    def absorbing(self) -> bool:
        """Whether the discriminator reads absorbing-state flags."""
        return isinstance(self.discriminator_network, AbsorbingIndicator)

    def adjust_in_keys(self, keys: list[NestedKey]) -> list[NestedKey]:
        if not self.absorbing:
            return keys
        return sorted({*keys, self.tensor_keys.expert_absorbing, self.tensor_keys.collector_absorbing}, key=str)

    def _logits(self, observation: torch.Tensor, action: torch.Tensor, absorbing: torch.Tensor | None) -> torch.Tensor:
        keys = self.tensor_keys
        inputs = TensorDict({keys.expert_observation: observation, keys.expert_action: action}, batch_size=observation.shape[:-1])
        if absorbing is not None:
            inputs.set(ABSORBING_KEY, absorbing)
        with self.discriminator_network_params.to_module(self.discriminator_network, preserve_module_state=False):
            return self.discriminator_network(inputs).get(keys.discriminator_pred)

    @dispatch
    def forward(self, tensordict: TensorDictBase) -> TensorDictBase:
        keys = self.tensor_keys
        expert_obs, expert_act = tensordict.get(keys.expert_observation), tensordict.get(keys.expert_action)
        policy_obs, policy_act = tensordict.get(keys.collector_observation), tensordict.get(keys.collector_action)
        flags = None
        if self.absorbing:
            flags = (tensordict.get(keys.expert_absorbing), tensordict.get(keys.collector_absorbing))
        logits = self._logits(
            torch.cat([expert_obs, policy_obs]), torch.cat([expert_act, policy_act]), None if flags is None else torch.cat(flags)
        )
        expert_logits, policy_logits = logits.chunk(2, dim=0)
        loss = F.binary_cross_entropy_with_logits(
            expert_logits, torch.ones_like(expert_logits), reduction="none"
        ) + F.binary_cross_entropy_with_logits(policy_logits, torch.zeros_like(policy_logits), reduction="none")
        out = {}
        if self.use_grad_penalty:
            gp_loss = self.gp_lambda * self.gradient_penalty(expert_obs, expert_act, policy_obs, policy_act, flags)
            loss = loss + gp_loss
            out["gp_loss"] = gp_loss.detach()
        out["loss"] = reduce_loss(self, loss, tensordict)
        return TensorDict(out)

    def gradient_penalty(
        self,
        expert_obs: torch.Tensor,
        expert_act: torch.Tensor,
        policy_obs: torch.Tensor,
        policy_act: torch.Tensor,
        flags: tuple[torch.Tensor, torch.Tensor] | None = None,
    ) -> torch.Tensor:
        r""":math:`\frac1N \sum_i (\lVert \nabla_u \ell(\hat u_i) \rVert - 1)^2` on per-sample interpolates
        (without the ``gp_lambda`` weight), over the pairs whose ends are not absorbing."""
        weight = torch.rand((*expert_obs.shape[:-1], 1), dtype=expert_obs.dtype, device=expert_obs.device)
        obs = (weight * policy_obs + (1 - weight) * expert_obs).requires_grad_(True)
        act = (weight * policy_act + (1 - weight) * expert_act).requires_grad_(True)
        keep = None
        absorbing = None
        if flags is not None:
            keep = ~(flags[0] | flags[1]).squeeze(-1)
            absorbing = torch.zeros_like(flags[0])
        logits = self._logits(obs, act, absorbing)
        grads = torch.autograd.grad(logits.sum(), (obs, act), create_graph=True)
        norm = torch.cat(grads, dim=-1).norm(dim=-1)
        penalty = (norm - 1) ** 2
        if keep is not None:
            return penalty[keep].sum() / keep.sum().clamp(min=1)
        return penalty.mean()


class DiscriminatorReward(TensorDictModuleBase):
    r"""Writes GAIL's reward, computed from the discriminator logit :math:`\ell = \log D - \log(1 - D)`.

    ``reward="logit"`` (default) writes :math:`\ell` itself; ``reward="positive"``
    writes :math:`-\log(1 - D) = \operatorname{softplus}(\ell)`, GAIL's original reward.
    The positive reward is positive everywhere and :math:`\log 2 \approx 0.69` where
    the discriminator cannot tell (``D = 1/2``), so with goal termination (no bootstrap)
    and horizon truncation (bootstrap), staying out of the goal is worth about
    :math:`0.69/(1 - \gamma)` and entering it about :math:`0.69`: it teaches the policy
    to avoid the goal (Kostrikov et al., 2019, call it survival bias). The logit is zero
    at chance and is, for the optimal discriminator, :math:`\log \rho_E / \rho_\pi`, so
    the return is a divergence between occupancies and carries no constant per-step
    bonus or cost (the AIRL/f-divergence reward of Fu et al., 2018, and Ghasemipour et
    al., 2019). It is the default because it needs nothing from the data format.
    Absorbing states remove the remaining bias of either reward.

    With a discriminator wrapped in
    :class:`~torchrl_causal.objectives.absorbing.AbsorbingIndicator` (absorbing
    states) every terminal step, ``terminated`` True, also receives the discounted
    return of staying in the absorbing state for ever, :math:`\gamma r_a / (1 - \gamma)`
    with :math:`r_a` the reward of the absorbing state's logit: GAE does not bootstrap
    at termination, so this is exactly the value the absorbing state would contribute.

    ``D`` is evaluated without gradient and in eval mode (no dropout), then restored to
    its previous mode. Run it on collected rollouts before PPO computes advantages.

    Args:
        discriminator (TensorDictModule): writes the logit at ``logits_key``.

    Keyword Args:
        logits_key (NestedKey, optional): discriminator output. Defaults to ``"d_logits"``.
        reward_key (NestedKey, optional): where the reward goes. Defaults to ``("next", "reward")``.
        reward (str, optional): ``"logit"`` or ``"positive"``. Defaults to ``"logit"``.
        gamma (float, optional): discount of the absorbing state's return; required
            with an absorbing discriminator. Defaults to ``None``.
        terminated_key (NestedKey, optional): Defaults to ``("next", "terminated")``.

    Examples:
        >>> import torch
        >>> from tensordict import TensorDict
        >>> from torchrl.data import Bounded
        >>> from torchrl_causal.modules import make_gail_discriminator
        >>> spec = Bounded(-1.0, 1.0, shape=(2,))
        >>> discriminator = make_gail_discriminator(3, spec, hidden=8)
        >>> rollout = TensorDict({"observation": torch.randn(4, 5, 3), "action": spec.rand((4, 5))}, [4, 5])
        >>> logit = DiscriminatorReward(discriminator)(rollout.clone())["next", "reward"]
        >>> positive = DiscriminatorReward(discriminator, reward="positive")(rollout.clone())["next", "reward"]
        >>> logit.shape, bool((positive > 0).all()), torch.allclose(positive, torch.nn.functional.softplus(logit))
        (torch.Size([4, 5, 1]), True, True)
    """

    def __init__(
        self,
        discriminator: TensorDictModule,
        *,
        logits_key: NestedKey = "d_logits",
        reward_key: NestedKey = ("next", "reward"),
        reward: Literal["logit", "positive"] = "logit",
        gamma: float | None = None,
        terminated_key: NestedKey = ("next", "terminated"),
    ) -> None:
        super().__init__()
        if logits_key not in discriminator.out_keys:
            raise UnknownKeyError(f"discriminator writes {discriminator.out_keys}, not the logits key {logits_key!r}.")
        if reward not in GAIL_REWARDS:
            raise InvalidValueError(f"reward must be one of {GAIL_REWARDS}, got {reward!r}.")
        self.absorbing = isinstance(discriminator, AbsorbingIndicator)
        if self.absorbing and not (gamma is not None and 0.0 <= gamma < 1.0):
            raise InvalidValueError(f"an absorbing-state discriminator needs gamma in [0, 1), got {gamma!r}.")
        self.discriminator = discriminator
        self.logits_key = logits_key
        self.reward = reward
        self.gamma = gamma
        self.terminated_key = terminated_key
        self.in_keys = [key for key in discriminator.in_keys if key != ABSORBING_KEY]
        if self.absorbing:
            self.in_keys.append(terminated_key)
        self.out_keys = [reward_key]

    def reward_from_logits(self, logits: torch.Tensor) -> torch.Tensor:
        """The configured reward of discriminator logits."""
        return logits if self.reward == "logit" else F.softplus(logits)

    @torch.no_grad()
    def forward(self, tensordict: TensorDictBase) -> TensorDictBase:
        inputs = tensordict.select(*(key for key in self.in_keys if key != self.terminated_key))
        if self.absorbing:
            inputs.set(ABSORBING_KEY, torch.zeros((*inputs.shape, 1), dtype=torch.bool, device=inputs.device))
        with eval_mode(self.discriminator):
            reward = self.reward_from_logits(self.discriminator(inputs).get(self.logits_key))
            # An absorbing discriminator always comes with its gamma (checked in __init__).
            if self.absorbing and self.gamma is not None:
                absorbing_state = inputs[(0,) * inputs.batch_dims].unsqueeze(0).apply(torch.zeros_like)
                absorbing_state.set(ABSORBING_KEY, torch.ones(1, 1, dtype=torch.bool, device=inputs.device))
                absorbing_reward = self.reward_from_logits(self.discriminator(absorbing_state).get(self.logits_key))
                terminated = tensordict.get(self.terminated_key).to(reward.dtype)
                reward = reward + terminated * (self.gamma / (1 - self.gamma)) * absorbing_reward.reshape(())
        tensordict.set(self.out_keys[0], reward)
        return tensordict


def gail_discriminator_batch(loss: GAILLoss, expert: TensorDictBase, policy: TensorDictBase) -> TensorDict:
    """Pairs equally many expert and policy transitions in the layout :class:`~torchrl.objectives.GAILLoss` reads.

    Both inputs carry ``"observation"`` and ``"action"`` (or the keys the loss's
    discriminator uses), and the ``"absorbing"`` flag when the loss's discriminator
    reads absorbing states; policy entries move to the loss's ``collector_*`` keys.

    Examples:
        >>> import torch
        >>> from tensordict import TensorDict
        >>> from torchrl.data import Bounded
        >>> from torchrl_causal.modules import make_gail_discriminator
        >>> from torchrl_causal.objectives import AbsorbingIndicator
        >>> spec = Bounded(-1.0, 1.0, shape=(2,))
        >>> loss = GAILDiscriminatorLoss(AbsorbingIndicator(make_gail_discriminator(3 + 1, spec, hidden=8)))
        >>> rows = TensorDict({"observation": torch.randn(4, 3), "action": spec.rand((4,)),
        ...                    "absorbing": torch.tensor([[False], [False], [False], [True]])}, [4])
        >>> batch = gail_discriminator_batch(loss, rows, rows.clone())
        >>> sorted(batch.keys())
        ['absorbing', 'action', 'collector_absorbing', 'collector_action', 'collector_observation', 'observation']
    """
    if expert.batch_size != policy.batch_size:
        raise InvalidValueError(
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
    if getattr(loss, "absorbing", False):
        pairs[keys.expert_absorbing] = expert.get(ABSORBING_KEY)
        pairs[keys.collector_absorbing] = policy.get(ABSORBING_KEY)
    return TensorDict(pairs, batch_size=expert.batch_size)


class GAILLosses(NamedTuple):
    """The three pieces of a GAIL round: discriminator loss, PPO loss, reward writer."""

    discriminator: GAILDiscriminatorLoss
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
    reward: Literal["logit", "positive"] = "logit",
    absorbing: bool = False,
) -> GAILLosses:
    """Builds GAIL with the paper's settings on :class:`GAILDiscriminatorLoss` and TorchRL's ``ClipPPOLoss``.

    The discriminator loss is binary cross-entropy on logits (expert = 1) plus the
    gradient penalty ``gp_lambda * E[(||grad logit|| - 1)^2]`` on per-sample
    expert/policy interpolates. PPO uses clipping ``clip_epsilon``, an entropy bonus, a
    squared-error value loss weighted by ``critic_coeff``, normalised advantages and
    GAE(``gamma``, ``gae_lambda``) on the reward that :class:`DiscriminatorReward` writes
    (``reward``). ``absorbing=True`` wraps the discriminator, built for
    ``observation_dim + 1`` input features, in
    :class:`~torchrl_causal.objectives.absorbing.AbsorbingIndicator`.

    PPO's ratio compares the loss's log-probability with the one recorded at
    collection, so roll out and train the actor in the same mode: without dropout
    (e.g. in :func:`~torchrl_causal.objectives.utils.eval_mode`), or every forward
    pass draws a new mask and the ratio is noise before any update.

    Examples:
        >>> import torch
        >>> from tensordict import TensorDict
        >>> from torchrl.data import Bounded
        >>> from torchrl_causal.modules import (
        ...     make_gail_discriminator, make_gail_value_network, make_tanh_gaussian_actor)
        >>> spec = Bounded(-1.0, 1.0, shape=(2,))
        >>> gail = make_gail_losses(
        ...     make_tanh_gaussian_actor(3, spec, hidden=8, num_blocks=1, dropout=0.0),
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
        >>> abs(ppo_out["max_ratio"].item() - 1) < 1e-5  # same policy: the ratio is one before any update
        True
        >>> expert = TensorDict({"observation": torch.randn(10, 3), "action": spec.rand((10,))}, [10])
        >>> d_out = gail.discriminator(gail_discriminator_batch(gail.discriminator, expert, rollout.reshape(-1)))
        >>> sorted(d_out.keys())
        ['gp_loss', 'loss']
    """
    if absorbing:
        discriminator = AbsorbingIndicator(discriminator)
    discriminator_loss = GAILDiscriminatorLoss(discriminator, use_grad_penalty=True, gp_lambda=gp_lambda)
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
    logits_key = discriminator_loss.tensor_keys.discriminator_pred
    return GAILLosses(
        discriminator_loss, policy_loss, DiscriminatorReward(discriminator, logits_key=logits_key, reward=reward, gamma=gamma)
    )
