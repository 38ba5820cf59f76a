"""Soft Q Imitation Learning (Reddy et al., 2020) as a TorchRL loss: the paper's Algorithm 2."""

from __future__ import annotations

from tensordict import TensorDictBase
from tensordict.nn import ProbabilisticTensorDictSequential, TensorDictModule, dispatch

from torchrl_causal.objectives.expert_sac import ALPHA_CLAMP, ExpertFlaggedSACLoss

__all__ = ["SQILLoss"]


class SQILLoss(ExpertFlaggedSACLoss):
    r"""SQIL: SAC trained on rewards relabelled from the batch's expert flag.

    Each transition gets ``r = expert_reward`` (1 by default) if ``"expert"`` is ``True``
    and ``r = 0`` otherwise,
    written to ``("next", "reward")`` of a shallow copy of the batch (the caller's batch is
    untouched apart from SAC's priority key), then TorchRL's
    :class:`~torchrl.objectives.SACLoss` runs unchanged: the critics regress onto

    .. math::

        y = r + \gamma (1 - d) \big(\min_j Q_{\bar\theta_j}(z', a') - \alpha \log \pi(a' \mid z')\big),
        \quad a' \sim \pi(\cdot \mid z'),

    with ``d`` the ``("next", "terminated")`` flag (time-limit truncation still
    bootstraps) and ``gamma`` set by :meth:`~torchrl.objectives.LossModule.make_value_estimator` (TD(0), 0.99 by
    default). The critic loss is squared error summed over the twin critics
    (TorchRL's convention; the paper's ``1/2`` factor only rescales gradients).

    With ``absorbing=True`` (see
    :class:`~torchrl_causal.objectives.expert_sac.ExpertFlaggedSACLoss`) an absorbing
    transition earns the reward of its episode's label, so reaching the goal is worth
    the discounted value of the absorbing state instead of zero.

    Args:
        actor_network (ProbabilisticTensorDictSequential): stochastic actor, e.g.
            :func:`~torchrl_causal.modules.make_tanh_gaussian_actor`.
        qvalue_network (TensorDictModule): Q(observation, action) network, e.g.
            :func:`~torchrl_causal.modules.make_qvalue_network`.

    Keyword Args:
        loss_function (str, optional): critic regression loss. Defaults to ``"l2"``.
        expert_reward (float, optional): reward of an expert transition. Defaults to
            ``1.0`` (SQIL); ``2.0`` with half-expert batches gives the critic gradient of
            :class:`~torchrl_causal.objectives.IQLearnLoss` ``variant="paper"``, doubled.
        absorbing (bool, optional): read absorbing-state flags. Defaults to ``False``.
        goal_value, bc_weight: the goal's value and the behaviour-cloning anchor, off by
            default (see :class:`~torchrl_causal.objectives.expert_sac.ExpertFlaggedSACLoss`).
        min_alpha, max_alpha (float, optional): alpha clamp, defaults ``1e-3`` and ``0.1``.
        **kwargs: see :class:`~torchrl_causal.objectives.expert_sac.ExpertFlaggedSACLoss`
            and :class:`~torchrl.objectives.SACLoss`.

    Examples:
        >>> import torch
        >>> from tensordict import TensorDict
        >>> from torchrl.data import Bounded
        >>> from torchrl.objectives import SoftUpdate
        >>> from torchrl_causal.modules import make_qvalue_network, make_tanh_gaussian_actor
        >>> from torchrl_causal.objectives import SQILLoss
        >>> spec = Bounded(-1.0, 1.0, shape=(2,))
        >>> actor = make_tanh_gaussian_actor(3, spec, hidden=16, num_blocks=1)
        >>> qvalue = make_qvalue_network(3, spec, hidden=16, num_blocks=1)
        >>> loss = SQILLoss(actor, qvalue)
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
        >>> round(float(out["alpha"]), 6)  # alpha_init=1 is clamped to the paper's upper bound
        0.1
        >>> (out["loss_actor"] + out["loss_qvalue"] + out["loss_alpha"]).backward()
        >>> target_updater.step()
    """

    def __init__(
        self,
        actor_network: ProbabilisticTensorDictSequential,
        qvalue_network: TensorDictModule,
        *,
        loss_function: str = "l2",
        expert_reward: float = 1.0,
        min_alpha: float = ALPHA_CLAMP[0],
        max_alpha: float = ALPHA_CLAMP[1],
        absorbing: bool = False,
        **kwargs,
    ) -> None:
        super().__init__(
            actor_network,
            qvalue_network,
            loss_function=loss_function,
            min_alpha=min_alpha,
            max_alpha=max_alpha,
            absorbing=absorbing,
            **kwargs,
        )
        self.expert_reward = float(expert_reward)

    def relabel(self, tensordict: TensorDictBase) -> TensorDictBase:
        """Returns a shallow copy of the batch with ``("next", reward)`` = ``expert_reward`` for
        expert, 0 for policy transitions, plus :meth:`goal_bootstrap` (``goal_value="expert"``):
        the terminal flag still stops the bootstrap, so the goal's value enters as reward."""
        relabelled = tensordict.copy()
        reward = self.expert_flag(tensordict).to(self.log_alpha.dtype) * self.expert_reward
        relabelled.set(("next", self.tensor_keys.reward), reward + self.goal_bootstrap(tensordict))
        return relabelled

    @dispatch
    def forward(self, tensordict: TensorDictBase) -> TensorDictBase:
        relabelled = self.relabel(tensordict)
        out = super().forward(relabelled)
        # SACLoss writes per-sample priorities for prioritized replay; hand them back.
        tensordict.set(self.tensor_keys.priority, relabelled.get(self.tensor_keys.priority))
        return out
