"""Shared base of :class:`SQILLoss` and :class:`IQLearnLoss`: SAC on expert-flagged batches.

Both algorithms keep SAC's actor update, twin critics, target critics and entropy
tuning (the paper's Algorithms 2 and 3 differ only in the critic loss), so they subclass
TorchRL's :class:`~torchrl.objectives.SACLoss` and read one extra key: a boolean
``"expert"`` flag that marks expert transitions in a mixed replay batch. With
``absorbing=True`` they also read the absorbing-state flags of
:mod:`torchrl_causal.objectives.absorbing`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import torch
from tensordict import TensorDictBase
from tensordict.nn import ProbabilisticTensorDictSequential, TensorDictModule, dispatch
from tensordict.utils import NestedKey
from torchrl.envs.utils import ExplorationType, set_exploration_type
from torchrl.objectives import SACLoss
from torchrl.objectives.sac import compute_rsample_log_prob

from torchrl_causal.compat import SACLossWithHooks, entropy_coefficient, priority_weights, qvalues_per_critic, reduce_loss
from torchrl_causal.errors import InvalidValueError, UnknownKeyError
from torchrl_causal.objectives.absorbing import ABSORBING_KEY, AbsorbingIndicator
from torchrl_causal.objectives.utils import eval_mode, gaussian_nll, interior_actions

__all__ = ["ALPHA_CLAMP", "BC_SCALES", "GOAL_VALUES", "ExpertFlaggedSACLoss"]

#: The paper's clamp on the entropy coefficient, ``[exp(-log 1000), exp(-log 10)]``.
ALPHA_CLAMP: tuple[float, float] = (1e-3, 1e-1)

#: What a goal-terminated transition bootstraps from — ``None`` (zero, the paper's
#: objective) or ``"expert"`` (the value of an expert state held for ever).
GOAL_VALUES: tuple[str | None, ...] = (None, "expert")

#: What the behaviour-cloning anchor's weight is multiplied by — ``"actor_loss"``
#: (``|loss_actor|``, about the batch's mean ``Q``, TD3+BC's normaliser) or
#: ``"expert_value"`` (the critic's scale ``r_E / (1 - gamma)``, a constant).
BC_SCALES: tuple[str, ...] = ("actor_loss", "expert_value")

#: Where :meth:`ExpertFlaggedSACLoss.actor_loss` leaves its pass's deterministic action for
#: the anchor in :meth:`~ExpertFlaggedSACLoss.forward` (SACLoss's forward keeps only the
#: actor loss's log-probability); ``forward`` removes it from the batch again.
_BC_ACTION_KEY = "_bc_deterministic_action"


class ExpertFlaggedSACLoss(SACLossWithHooks):
    """:class:`~torchrl.objectives.SACLoss` (v2, no state-value network) that reads an ``"expert"`` flag.

    Subclasses replace SAC's critic loss; the actor loss, entropy tuning toward
    ``-|A|`` (``target_entropy="auto"``) and target networks are SAC's. The entropy
    coefficient is clamped to ``[min_alpha, max_alpha]`` through SACLoss's own clamp,
    which is applied in place to ``log_alpha`` every time alpha is read, so an
    optimizer step that leaves the range is undone before alpha is next used.

    Targets are computed with the actor and the critics in eval mode: the next action
    ``a'`` is drawn from the policy being learned, not from a copy thinned by a fresh
    dropout mask (the actor loss keeps dropout as a regulariser).

    With ``absorbing=True`` the critic is wrapped in
    :class:`~torchrl_causal.objectives.absorbing.AbsorbingIndicator`, so it reads the
    ``"absorbing"`` flag (``("next", "absorbing")`` for the bootstrap) as one more
    input feature: build it for ``observation_dim + 1`` features. Batches then come from
    :func:`~torchrl_causal.objectives.absorbing.add_absorbing_transitions`, and goal
    termination no longer makes the episode's end worth zero.

    Args:
        actor_network (ProbabilisticTensorDictSequential): stochastic actor.
        qvalue_network (TensorDictModule): Q(observation, action) network, copied
            ``num_qvalue_nets`` times.

    Keyword Args:
        num_qvalue_nets (int, optional): number of critics. Defaults to ``2``.
        alpha_init (float, optional): initial entropy coefficient, before clamping.
            Defaults to ``1.0`` (``log alpha = 0`` as in the paper's pseudocode).
        min_alpha (float, optional): lower clamp of alpha. Defaults to ``1e-3``.
        max_alpha (float, optional): upper clamp of alpha. Defaults to ``0.1``.
        absorbing (bool, optional): read absorbing-state flags (see above).
            Defaults to ``False``.
        goal_value (str, optional): ``None`` (default, the paper's objective): a
            goal-terminated transition bootstraps from zero, which makes every imitation
            reward that pays expert-like steps pay stopping short of the goal. ``"expert"``:
            it bootstraps from :attr:`expert_value`, the value of an expert state kept for
            ever (``expert_reward / (1 - gamma)``), so reaching the goal is worth what
            staying on the expert's path is worth, and no more. Unlike ``absorbing`` it adds
            no rows, no action and no entropy bonus in the goal.
        bc_weight (float, optional): ``None`` (default) or ``w > 0``: adds ``"loss_bc"``,
            a behaviour-cloning anchor on the expert rows (TD3+BC's, Fujimoto & Gu 2021):
            ``w * scale * mean((mode(pi(z)) - x_E)^2)``, ``scale`` set by ``bc_scale``.
        bc_scale (str, optional): the anchor's scale. ``"actor_loss"`` (default):
            ``|loss_actor|``, the batch's ``|mean(alpha log pi - Q)|``, which tracks TD3+BC's
            ``mean |Q|`` normaliser once the critics have grown. Just after a warm start it
            does not: the critics' values at a narrow cloned actor's actions start near
            zero, the actor loss crosses zero and the anchor vanishes exactly when the actor
            starts to move (measured on AntMaze-Medium: 500 joint updates take the cloned
            actor from 40% to 0% success). ``"expert_value"``: :attr:`expert_value`, the
            critic's scale under imitation labels, a constant: it holds the cloned actor
            (55% after the same 500 updates) but stays as strong for the whole run, and one
            400k-step C-SQIL run with it ended below the default (65.2% against 77.4% at
            deployment, ``results/antmaze_medium_recipe.md``).
        bc_separate_pass (bool, optional): ``False`` (default): the anchor reads the
            deterministic action of the actor loss's own pass over the batch (one actor
            forward per update, the same dropout mask). ``True``: the anchor runs a second
            actor pass with a fresh dropout mask (:meth:`behaviour_cloning_anchor`), as every
            run did before issue 56; it costs an actor forward and backward per update and
            draws one more dropout mask, so it reproduces the random stream, and the numbers,
            of the recipe runs made then. Equal values and gradients without dropout.
        **kwargs: forwarded to :class:`~torchrl.objectives.SACLoss`.
    """

    @dataclass
    class _AcceptedKeys(SACLoss._AcceptedKeys):
        """Keys of :class:`~torchrl.objectives.SACLoss` plus the expert flag.

        Attributes:
            expert (NestedKey): boolean entry of shape ``batch + (1,)``, ``True`` for
                expert transitions. Defaults to ``"expert"``.
        """

        expert: NestedKey = "expert"

    default_keys = _AcceptedKeys
    tensor_keys: _AcceptedKeys

    def __init__(
        self,
        actor_network: ProbabilisticTensorDictSequential,
        qvalue_network: TensorDictModule,
        *,
        num_qvalue_nets: int = 2,
        alpha_init: float = 1.0,
        min_alpha: float = ALPHA_CLAMP[0],
        max_alpha: float = ALPHA_CLAMP[1],
        absorbing: bool = False,
        goal_value: Literal["expert"] | None = None,
        bc_weight: float | None = None,
        bc_scale: Literal["actor_loss", "expert_value"] = "actor_loss",
        bc_separate_pass: bool = False,
        **kwargs,
    ) -> None:
        if not 0.0 < min_alpha <= max_alpha:
            raise InvalidValueError(f"need 0 < min_alpha <= max_alpha, got min_alpha={min_alpha}, max_alpha={max_alpha}.")
        if goal_value not in GOAL_VALUES:
            raise InvalidValueError(f"goal_value must be one of {GOAL_VALUES}, got {goal_value!r}.")
        if goal_value is not None and absorbing:
            raise InvalidValueError("goal_value and absorbing are two answers to the same bias: choose one.")
        if bc_weight is not None and not bc_weight > 0:
            raise InvalidValueError(f"bc_weight must be None (off) or positive, got {bc_weight!r}.")
        if bc_scale not in BC_SCALES:
            raise InvalidValueError(f"bc_scale must be one of {BC_SCALES}, got {bc_scale!r}.")
        if absorbing:
            qvalue_network = AbsorbingIndicator(qvalue_network)
        super().__init__(
            actor_network,
            qvalue_network,
            None,
            num_qvalue_nets=num_qvalue_nets,
            alpha_init=alpha_init,
            min_alpha=min_alpha,
            max_alpha=max_alpha,
            **kwargs,
        )
        if bc_weight is not None and self.reduction == "none":
            raise InvalidValueError("bc_weight needs a reduced loss (reduction='mean' or 'sum'), got reduction='none'.")
        self.goal_value = goal_value
        self.bc_weight = bc_weight
        self.bc_scale = bc_scale
        self.bc_separate_pass = bool(bc_separate_pass)

    #: The per-step reward of an expert transition in the critic's target (SQIL's label;
    #: subclasses whose critic reward is implicit say what it is).
    expert_reward: float = 1.0

    #: The value estimator's discount as a Python float, set by :meth:`~torchrl.objectives.LossModule.make_value_estimator`.
    _discount: float | None = None

    def make_value_estimator(self, value_type=None, **hyperparams) -> None:
        super().make_value_estimator(value_type, **hyperparams)
        # Read once here: ``float()`` of the estimator's gamma buffer inside a compiled loss
        # splits its graph, and alpha's in-place clamp between the pieces then breaks the
        # backward (IQ-Learn with the goal value, compiled).
        self._discount = float(self.value_estimator.gamma)

    @property
    def discount(self) -> float:
        """The discount of the value estimator (:meth:`~torchrl.objectives.LossModule.make_value_estimator`)."""
        if self._discount is None:
            self.make_value_estimator()  # TorchRL's default estimator, as ``value_estimator`` builds it
        assert self._discount is not None  # set by make_value_estimator (for the type checker)
        return self._discount

    @property
    def expert_value(self) -> float:
        r"""The soft value of an expert state kept for ever, :math:`r_E / (1 - \gamma)`.

        Under SQIL's labels every state of a demonstration that never ends is worth this
        (:math:`\sum_t \gamma^t r_E`); the goal, where the expert stays, is such a state.
        """
        return self.expert_reward / (1.0 - self.discount)

    def goal_bootstrap(self, tensordict: TensorDictBase) -> torch.Tensor | float:
        r""":math:`\gamma\, d\, V_{goal}` for every transition (``d`` the terminal flag), or
        ``0.0`` with ``goal_value=None``: what the critic target adds for entering the goal."""
        if self.goal_value is None:
            return 0.0
        terminated = tensordict.get(("next", self.tensor_keys.terminated)).to(self.log_alpha.dtype)
        return self.discount * self.expert_value * terminated

    def expert_actions(self, tensordict: TensorDictBase) -> tuple[torch.Tensor, torch.Tensor]:
        """The batch's actions clipped inside the bounds, and the expert rows' weights (sum 1)."""
        expert = self.expert_flag(tensordict).to(self.log_alpha.dtype)
        weights = expert / expert.sum().clamp_min(1.0)
        # Clipped inside the bounds: a tanh-Gaussian gives the bounds themselves density zero.
        actions = interior_actions(self.actor_network.spec[self.tensor_keys.action], tensordict.get(self.tensor_keys.action))
        return actions, weights

    def behaviour_cloning_nll(self, tensordict: TensorDictBase) -> torch.Tensor:
        """Mean negative log-likelihood of the expert rows' actions under the actor (maximum-
        likelihood behaviour cloning: fits the mean and the spread); used to warm-start it."""
        actions, weights = self.expert_actions(tensordict)
        with self.actor_network_params.to_module(self.actor_network, preserve_module_state=False):
            return gaussian_nll(self.actor_network, tensordict, actions, weights)

    def anchor_error(self, deterministic_action: torch.Tensor, tensordict: TensorDictBase) -> torch.Tensor:
        """Mean squared error between ``deterministic_action`` (the actor's, one row per row of
        the batch) and the expert rows' actions, averaged over the expert rows."""
        actions, weights = self.expert_actions(tensordict)
        return (weights * (deterministic_action - actions).pow(2).mean(-1, keepdim=True)).sum()

    def behaviour_cloning_anchor(self, tensordict: TensorDictBase) -> torch.Tensor:
        """:meth:`anchor_error` of the actor's deterministic action from an actor pass of its
        own (``bc_separate_pass=True``; the actor loss's pass gives it otherwise)."""
        with (
            set_exploration_type(ExplorationType.DETERMINISTIC),
            self.actor_network_params.to_module(self.actor_network, preserve_module_state=False),
        ):
            dist = self.actor_network.get_dist(tensordict.select(*self.actor_network.in_keys, strict=False))
            mode = dist.deterministic_sample
        return self.anchor_error(mode, tensordict)

    def actor_loss(self, tensordict: TensorDictBase) -> tuple[torch.Tensor, dict[str, torch.Tensor]]:
        """SAC's actor loss, ``mean(alpha log pi(a|z) - min_j Q_j(z, a))`` with ``a`` reparameterised.

        With the one-pass anchor (``bc_weight`` set, ``bc_separate_pass=False``) the same
        distribution also gives the anchor's deterministic action, left in the batch for
        :meth:`forward`. The draws (the dropout mask, then the
        action noise) are SAC's, in SAC's order, so ``loss_actor`` is the number SAC's own
        actor loss gives with the same random state. Without the anchor this is SAC's.
        """
        if self.bc_weight is None or self.bc_separate_pass:
            return super().actor_loss(tensordict)
        weights = priority_weights(self, tensordict)
        with (
            set_exploration_type(ExplorationType.RANDOM),
            self.actor_network_params.to_module(self.actor_network, preserve_module_state=False),
        ):
            dist = self.actor_network.get_dist(tensordict)
            action, log_prob = compute_rsample_log_prob(dist)
        critic_input = tensordict.select(*self.qvalue_network.in_keys, strict=False)
        critic_input.set(self.tensor_keys.action, action)
        # The critics' parameters detached: the actor loss moves the actor only.
        q = qvalues_per_critic(self, critic_input, self.qvalue_network_params.detach()).get(self.tensor_keys.state_action_value)
        loss = reduce_loss(self, entropy_coefficient(self) * log_prob - q.min(0)[0].squeeze(-1), tensordict=tensordict, weights=weights)
        tensordict.set(_BC_ACTION_KEY, dist.deterministic_sample)
        return loss, {"log_prob": log_prob.detach()}

    @dispatch
    def forward(self, tensordict: TensorDictBase) -> TensorDictBase:
        out = super().forward(tensordict)
        if self.bc_weight is not None:
            scale = out["loss_actor"].detach().abs() if self.bc_scale == "actor_loss" else self.expert_value
            if self.bc_separate_pass:
                anchor = self.behaviour_cloning_anchor(tensordict)
            else:
                anchor = self.anchor_error(tensordict.pop(_BC_ACTION_KEY), tensordict)
            out.set("loss_bc", self.bc_weight * scale * anchor)
        return out

    @property
    def absorbing(self) -> bool:
        """Whether the critics read the absorbing-state flags."""
        return isinstance(self.qvalue_network, AbsorbingIndicator)

    def adjust_in_keys(self, keys: list[NestedKey]) -> list[NestedKey]:
        reward = ("next", self.tensor_keys.reward)
        extra = [self.tensor_keys.expert]
        if self.absorbing:
            extra.append(("next", ABSORBING_KEY))
        return [key for key in keys if key != reward] + extra

    def critic_target(self, tensordict: TensorDictBase) -> torch.Tensor:
        with eval_mode(self.actor_network, self.qvalue_network):
            return super().critic_target(tensordict)

    def expert_flag(self, tensordict: TensorDictBase) -> torch.Tensor:
        """Returns the boolean expert flag of shape ``batch + (1,)``, with a clear error if it is malformed."""
        key = self.tensor_keys.expert
        flag = tensordict.get(key, None)
        if flag is None:
            raise UnknownKeyError(
                f"{type(self).__name__} needs the boolean expert flag {key!r} in the batch "
                f"(True for expert transitions); found keys {list(tensordict.keys(True, True))}."
            )
        if flag.dtype != torch.bool or flag.shape != (*tensordict.shape, 1):
            raise InvalidValueError(
                f"expert flag {key!r} must be a bool tensor of shape {(*tensordict.shape, 1)}, "
                f"got dtype {flag.dtype} and shape {tuple(flag.shape)}."
            )
        return flag
