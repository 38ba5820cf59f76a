"""Inverse soft-Q imitation learning (IQ-Learn, Garg et al., 2021) as a TorchRL loss.

Two variants: the paper's Algorithm 3 (``variant="paper"``) and Garg et al.'s online
objective (``variant="iq_learn"``). Not to be confused with TorchRL's
:class:`~torchrl.objectives.IQLLoss`, which is Implicit Q-Learning (offline RL), a
different algorithm.
"""

from __future__ import annotations

from typing import Literal

import torch
from tensordict import TensorDictBase
from tensordict.nn import ProbabilisticTensorDictSequential, TensorDictModule, set_composite_lp_aggregate
from torchrl.envs.utils import ExplorationType, set_exploration_type
from torchrl.modules.distributions.utils import rsample_and_log_prob
from torchrl.objectives.utils import ValueEstimators

from torchrl_causal.compat import assert_on_device, entropy_coefficient, priority_weights, qvalues_per_critic, reduce_loss
from torchrl_causal.errors import InvalidValueError
from torchrl_causal.objectives.expert_sac import ALPHA_CLAMP, ExpertFlaggedSACLoss
from torchrl_causal.objectives.utils import eval_mode

__all__ = ["IQLearnLoss", "IQ_LEARN_VARIANTS"]

#: The critic objectives :class:`IQLearnLoss` implements.
IQ_LEARN_VARIANTS: tuple[str, ...] = ("paper", "iq_learn")


class IQLearnLoss(ExpertFlaggedSACLoss):
    r"""IQ-Learn with the chi-squared critic objective, SAC actor and entropy tuning.

    Both variants score a transition of critic :math:`j` by its implicit reward
    :math:`\hat r_j(z, x) = Q_{\theta_j}(z, x) - \gamma (1 - d)\, V(z')` and regularise it
    with :math:`\tfrac12 \mathbb E_{\text{all}}[\hat r_j^2]`; soft values are Monte-Carlo
    estimates over ``K`` policy samples,
    :math:`V(z) = \frac1K \sum_{m} [Q(z, \tilde x_m) - \alpha \log \pi(\tilde x_m \mid z)]`,
    :math:`\tilde x_m \sim \pi(\cdot \mid z)` (drawn without dropout and without gradient
    to the actor). The expert expectation averages the rows whose ``"expert"`` flag is
    ``True``; "all" averages the whole batch.

    ``variant="paper"`` (default; the paper's Algorithm 3, which produced its Table 1):
    :math:`V = \bar V` uses the target critics, :math:`\min_i Q_{\bar\theta_i}` inside
    the sample mean, and is a constant of the loss

    .. math::

        \mathcal L = \sum_j -\mathbb E_{\text{expert}}[\hat r_j] + \tfrac12 \mathbb E_{\text{all}}[\hat r_j^2].

    Its critic gradient is
    :math:`\mathbb E_{\text{all}}[(\hat r_j - e/p)\nabla Q_{\theta_j}]` (``e`` the flag,
    ``p`` the expert fraction of the batch), which is exactly half the gradient of
    :class:`~torchrl_causal.objectives.SQILLoss` with ``expert_reward = 1/p`` and the
    same :math:`\bar V`: with the paper's half-expert batches, **the paper's IQ-Learn
    critic is SQIL with expert reward 2** (at ``K = 1`` even the draw of
    :math:`\bar V` is SAC's).

    ``variant="iq_learn"`` (Garg et al., "IQ-Learn: Inverse soft-Q Learning for
    Imitation", NeurIPS 2021, online setting): the inverse-RL objective
    :math:`\max_Q \mathbb E_{\rho_E}[\phi(\hat r)] - (1 - \gamma)\mathbb E_{\rho_0}[V(s_0)]`
    with the initial-state term rewritten, by telescoping, as an expectation over any
    replayed transitions, and every value taken from the online critic :math:`j` itself
    (so it carries gradient; the target critics are unused by this loss):

    .. math::

        \mathcal L = \sum_j -\mathbb E_{\text{expert}}[\hat r_j]
            + \mathbb E_{\text{all}}\big[V_j(z) - \gamma (1 - d) V_j(z')\big]
            + \tfrac12 \mathbb E_{\text{all}}[\hat r_j^2], \qquad
        \hat r_j = Q_{\theta_j}(z, x) - \gamma (1 - d) V_j(z').

    Each critic learns its own soft value; SAC's ``min`` over critics stays in the actor
    loss. The value term costs ``2K`` critic evaluations per row with gradient.

    In both, ``d`` is ``("next", "terminated")`` and ``gamma`` comes from
    :meth:`~torchrl.objectives.LossModule.make_value_estimator` (TD(0) only: the implicit reward is a one-step
    quantity). The actor and alpha losses are :class:`~torchrl.objectives.SACLoss`'s;
    the batch carries no reward. With ``reduction="none"`` the per-transition loss is
    :math:`\sum_j -\frac{N}{N_{\text{expert}}}\,e\,\hat r_j + \tfrac12 \hat r_j^2`
    (plus the value term for ``"iq_learn"``), whose batch mean is the objective. The
    priority written to ``"td_error"`` is :math:`\max_j |\hat r_j|`.

    This implementation is written from the two papers. The IQ-Learn authors' code is
    released under a research-only licence and its method is patented; none of it is
    used here.

    Args:
        actor_network (ProbabilisticTensorDictSequential): stochastic actor.
        qvalue_network (TensorDictModule): Q(observation, action) network.

    Keyword Args:
        variant (str, optional): ``"paper"`` or ``"iq_learn"`` (see above). Defaults to ``"paper"``.
        num_value_samples (int, optional): ``K``, the number of policy samples per soft
            value. Defaults to ``16`` (paper's AntMaze; HumanoidMaze uses ``1``).
        min_alpha (float, optional): lower clamp of alpha. Defaults to ``1e-3``.
        max_alpha (float, optional): upper clamp of alpha. Defaults to ``0.1``.
        absorbing (bool, optional): read absorbing-state flags. Defaults to ``False``.
        goal_value, bc_weight: the goal's value (``variant="paper"`` only: its expert reward
            is ``1/p``, so the goal is worth ``(1/p) / (1 - gamma)``) and the
            behaviour-cloning anchor, off by default (see
            :class:`~torchrl_causal.objectives.expert_sac.ExpertFlaggedSACLoss`).
        **kwargs: see :class:`~torchrl_causal.objectives.expert_sac.ExpertFlaggedSACLoss`
            and :class:`~torchrl.objectives.SACLoss`.

    Examples:
        >>> import torch
        >>> from tensordict import TensorDict
        >>> from torchrl.data import Bounded
        >>> from torchrl.objectives import SoftUpdate
        >>> from torchrl_causal.modules import make_qvalue_network, make_tanh_gaussian_actor
        >>> from torchrl_causal.objectives import IQLearnLoss
        >>> spec = Bounded(-1.0, 1.0, shape=(2,))
        >>> actor = make_tanh_gaussian_actor(3, spec, hidden=16, num_blocks=1)
        >>> qvalue = make_qvalue_network(3, spec, hidden=16, num_blocks=1)
        >>> loss = IQLearnLoss(actor, qvalue, num_value_samples=4)
        >>> loss.make_value_estimator(gamma=0.99)
        >>> target_updater = SoftUpdate(loss, tau=0.005)
        >>> batch = TensorDict({
        ...     "observation": torch.randn(4, 3),
        ...     "action": spec.rand((4,)),
        ...     "expert": torch.tensor([[True], [True], [False], [False]]),
        ...     "next": {
        ...         "observation": torch.randn(4, 3),
        ...         "done": torch.zeros(4, 1, dtype=torch.bool),
        ...         "terminated": torch.zeros(4, 1, dtype=torch.bool),
        ...     },
        ... }, [4])
        >>> out = loss(batch)
        >>> sorted(out.keys())
        ['alpha', 'entropy', 'loss_actor', 'loss_alpha', 'loss_qvalue']
        >>> (out["loss_actor"] + out["loss_qvalue"] + out["loss_alpha"]).backward()
        >>> target_updater.step()
        >>> online = IQLearnLoss(actor, qvalue, variant="iq_learn", num_value_samples=2)
        >>> online.make_value_estimator(gamma=0.99)
        >>> online(batch)["loss_qvalue"].backward()
    """

    SUPPORTED_VALUE_ESTIMATORS = (ValueEstimators.TD0,)

    def __init__(
        self,
        actor_network: ProbabilisticTensorDictSequential,
        qvalue_network: TensorDictModule,
        *,
        variant: Literal["paper", "iq_learn"] = "paper",
        num_value_samples: int = 16,
        min_alpha: float = ALPHA_CLAMP[0],
        max_alpha: float = ALPHA_CLAMP[1],
        absorbing: bool = False,
        **kwargs,
    ) -> None:
        if variant not in IQ_LEARN_VARIANTS:
            raise InvalidValueError(f"variant must be one of {IQ_LEARN_VARIANTS}, got {variant!r}.")
        if not isinstance(num_value_samples, int) or num_value_samples < 1:
            raise InvalidValueError(f"num_value_samples must be a positive integer, got {num_value_samples!r}.")
        if variant == "iq_learn" and kwargs.get("goal_value") is not None:
            raise InvalidValueError(
                "goal_value is derived for the paper's variant (SQIL with expert reward 1/p); "
                "variant='iq_learn' learns its implicit reward and has no such value."
            )
        super().__init__(actor_network, qvalue_network, min_alpha=min_alpha, max_alpha=max_alpha, absorbing=absorbing, **kwargs)
        self.variant = variant
        self.num_value_samples = num_value_samples

    def soft_values(self, states: TensorDictBase, qvalue_params: TensorDictBase) -> torch.Tensor:
        r"""Per-critic, per-sample soft values :math:`Q_j(z, \tilde x_m) - \alpha \log \pi(\tilde x_m \mid z)`.

        The ``K`` policy samples of every state are drawn in one pass of the actor (eval
        mode, no gradient) and the ``K * batch`` rows go through all critics in one
        vmapped call with ``qvalue_params`` (the stacked online or target parameters).

        Returns:
            a tensor of shape ``(num_critics, K, *batch, 1)``; it carries gradient to
            ``qvalue_params`` when they require it.
        """
        with (
            torch.no_grad(),
            eval_mode(self.actor_network),
            set_exploration_type(ExplorationType.RANDOM),
            self.actor_network_params.to_module(self.actor_network, preserve_module_state=False),
            set_composite_lp_aggregate(True),
        ):
            dist = self.actor_network.get_dist(states.select(*self.actor_network.in_keys, strict=False))
            actions, log_prob = rsample_and_log_prob(dist, (self.num_value_samples,))
        samples = states.select(*self.qvalue_network.in_keys, strict=False).expand(self.num_value_samples, *states.shape)
        samples.set(self.tensor_keys.action, actions)
        q = qvalues_per_critic(self, samples, qvalue_params).get(self.tensor_keys.state_action_value)
        return q - entropy_coefficient(self) * log_prob.unsqueeze(-1)

    def bootstrap_discount(self, tensordict: TensorDictBase) -> torch.Tensor:
        r""":math:`\gamma (1 - d)` of every transition, shape ``batch + (1,)``: TorchRL's TD(0)
        estimate of a zero reward and a next value of one, so the estimator owns gamma and done handling."""
        keys = self.value_estimator.tensor_keys
        td = tensordict.select(("next", keys.done), ("next", keys.terminated), keys.steps_to_next_obs, strict=False)
        ones = torch.ones((*tensordict.shape, 1), dtype=self.log_alpha.dtype, device=self.log_alpha.device)
        td.set(("next", keys.reward), torch.zeros_like(ones))
        return self.value_estimator.value_estimate(td, next_value=ones)

    def qvalue_v2_loss(self, tensordict: TensorDictBase) -> tuple[torch.Tensor, dict[str, torch.Tensor]]:
        """The chi-squared critic loss of ``variant``; replaces SAC's soft Bellman regression in :meth:`forward`."""
        expert = self.expert_flag(tensordict).to(self.log_alpha.dtype)
        num_expert = expert.sum()
        message = (
            f"IQLearnLoss needs at least one expert transition per batch (flag {self.tensor_keys.expert!r}); "
            "sample expert and policy transitions together (the paper uses half of each)."
        )
        if expert.device.type == "cpu" and not torch.compiler.is_compiling():
            if not num_expert:  # reading a CPU tensor costs nothing
                raise InvalidValueError(message)
        else:
            # On an accelerator, or inside a compiled graph, a host read would stall the
            # update loop (or split the graph): the device checks the count itself.
            assert_on_device(num_expert > 0, message)
        weights = priority_weights(self, tensordict)
        discount = self.bootstrap_discount(tensordict)
        next_states = tensordict.get("next")
        if self.variant == "paper":
            with torch.no_grad(), eval_mode(self.qvalue_network):
                next_value = self.soft_values(next_states, self.target_qvalue_network_params).min(0)[0].mean(0)
            value_term: torch.Tensor | float = 0.0
        else:
            keys = list({*self.actor_network.in_keys, *self.qvalue_network.in_keys} - {self.tensor_keys.action})
            both = torch.cat([tensordict.select(*keys, strict=False), next_states.select(*keys, strict=False)])
            state_value, next_value = self.soft_values(both, self.qvalue_network_params).mean(1).chunk(2, dim=1)
            value_term = state_value - discount * next_value
        q = qvalues_per_critic(self, tensordict.select(*self.qvalue_network.in_keys, strict=False), self.qvalue_network_params).get(
            self.tensor_keys.state_action_value
        )
        # The paper's critic is SQIL with expert reward 1/p (p the batch's expert fraction):
        # its goal is worth (1/p) / (1 - gamma), goal_bootstrap's value at expert reward 1.
        inverse_fraction = expert.numel() / num_expert
        implicit_reward = q - discount * next_value - self.goal_bootstrap(tensordict) * inverse_fraction
        expert_weight = expert * inverse_fraction
        per_sample = (0.5 * implicit_reward - expert_weight) * implicit_reward + value_term
        loss = reduce_loss(self, per_sample.sum(0).squeeze(-1), tensordict=tensordict, weights=weights)
        td_error = implicit_reward.detach().abs().max(0)[0].squeeze(-1)
        return loss, {"td_error": td_error}
