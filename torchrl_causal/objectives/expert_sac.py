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

import torch
from tensordict import TensorDictBase
from tensordict.nn import ProbabilisticTensorDictSequential, TensorDictModule
from tensordict.utils import NestedKey
from torchrl.objectives import SACLoss

from torchrl_causal.objectives.absorbing import ABSORBING_KEY, AbsorbingIndicator
from torchrl_causal.objectives.utils import eval_mode

__all__ = ["ALPHA_CLAMP", "ExpertFlaggedSACLoss"]

#: The paper's clamp on the entropy coefficient, ``[exp(-log 1000), exp(-log 10)]``.
ALPHA_CLAMP: tuple[float, float] = (1e-3, 1e-1)


class ExpertFlaggedSACLoss(SACLoss):
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
        **kwargs,
    ) -> None:
        if not 0.0 < min_alpha <= max_alpha:
            raise ValueError(f"need 0 < min_alpha <= max_alpha, got min_alpha={min_alpha}, max_alpha={max_alpha}.")
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

    @property
    def absorbing(self) -> bool:
        """Whether the critics read the absorbing-state flags."""
        return isinstance(self.qvalue_network, AbsorbingIndicator)

    def _set_in_keys(self) -> None:
        super()._set_in_keys()
        reward = ("next", self.tensor_keys.reward)
        extra = [self.tensor_keys.expert]
        if self.absorbing:
            extra.append(("next", ABSORBING_KEY))
        self._in_keys = [key for key in self._in_keys if key != reward] + extra

    def _compute_target_v2(self, tensordict: TensorDictBase) -> torch.Tensor:
        with eval_mode(self.actor_network, self.qvalue_network):
            return super()._compute_target_v2(tensordict)

    def expert_flag(self, tensordict: TensorDictBase) -> torch.Tensor:
        """Returns the boolean expert flag of shape ``batch + (1,)``, with a clear error if it is malformed."""
        key = self.tensor_keys.expert
        flag = tensordict.get(key, None)
        if flag is None:
            raise KeyError(
                f"{type(self).__name__} needs the boolean expert flag {key!r} in the batch "
                f"(True for expert transitions); found keys {list(tensordict.keys(True, True))}."
            )
        if flag.dtype != torch.bool or flag.shape != (*tensordict.shape, 1):
            raise ValueError(
                f"expert flag {key!r} must be a bool tensor of shape {(*tensordict.shape, 1)}, "
                f"got dtype {flag.dtype} and shape {tuple(flag.shape)}."
            )
        return flag
