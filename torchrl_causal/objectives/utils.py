"""Helpers shared by the losses and the loops that drive them."""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager

import torch
from tensordict import TensorDictBase
from tensordict.nn import ProbabilisticTensorDictSequential
from torch import nn
from torchrl.data import TensorSpec

__all__ = ["BC_ACTION_MARGIN", "eval_mode", "gaussian_nll", "interior_actions"]

#: Fraction of the action range kept between cloned actions and the bounds, where a tanh
#: policy's log-probability is -inf.
BC_ACTION_MARGIN = 1e-3


@contextmanager
def eval_mode(*modules: nn.Module) -> Iterator[None]:
    """Puts ``modules`` in eval mode (no dropout) for the block, then restores each one's mode.

    Used wherever a network must act as the policy it is, not as a randomly thinned
    copy: rollouts, PPO's probability ratio, the policy samples of a soft-value target.

    Examples:
        >>> import torch
        >>> net = torch.nn.Dropout(0.5)
        >>> with eval_mode(net):
        ...     net.training
        False
        >>> net.training
        True
    """
    modes = [module.training for module in modules]
    try:
        for module in modules:
            module.eval()
        yield
    finally:
        for module, mode in zip(modules, modes):
            module.train(mode)


def interior_actions(spec: TensorSpec, actions: torch.Tensor, margin: float = BC_ACTION_MARGIN) -> torch.Tensor:
    """``actions`` clamped ``margin`` times the range inside the bounded ``spec``'s bounds.

    Examples:
        >>> import torch
        >>> from torchrl.data import Bounded
        >>> interior_actions(Bounded(-1.0, 1.0, shape=(2,)), torch.tensor([[-1.0, 0.5]]))
        tensor([[-0.9980,  0.5000]])
    """
    low, high = spec.space.low.to(actions.device), spec.space.high.to(actions.device)
    return actions.clamp(low + margin * (high - low), high - margin * (high - low))


def gaussian_nll(
    actor: ProbabilisticTensorDictSequential, tensordict: TensorDictBase, actions: torch.Tensor, weights: torch.Tensor
) -> torch.Tensor:
    r"""Weighted negative log-likelihood :math:`-\sum_i w_i \log \pi(a_i \mid o_i)` of ``actions`` under
    ``actor``'s distribution on ``tensordict``'s observations: maximum-likelihood behaviour
    cloning, which fits the policy's mean and its spread. ``weights`` has one entry per row
    (trailing singleton allowed); they usually sum to one. Run it under the loss's functional
    parameters (``params.to_module(actor)``) to differentiate those.

    Examples:
        >>> import torch
        >>> from tensordict import TensorDict
        >>> from torchrl.data import Bounded
        >>> from torchrl_causal.modules import make_tanh_gaussian_actor
        >>> spec = Bounded(-1.0, 1.0, shape=(2,))
        >>> actor = make_tanh_gaussian_actor(3, spec, hidden=8, num_blocks=1, dropout=0.0)
        >>> rows = TensorDict({"observation": torch.randn(4, 3)}, [4])
        >>> nll = gaussian_nll(actor, rows, interior_actions(spec, spec.rand((4,))), torch.full((4, 1), 0.25))
        >>> nll.shape, bool(torch.isfinite(nll))
        (torch.Size([]), True)
    """
    dist = actor.get_dist(tensordict.select(*actor.in_keys, strict=False))
    log_prob = dist.log_prob(actions)
    return -(weights.squeeze(-1) * log_prob.reshape(weights.shape[:-1])).sum()
