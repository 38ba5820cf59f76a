"""The behaviour-cloning warm start shared by the trainers that learn a stochastic actor online.

Not in the paper: the soft-Q recipe (``+recipe=goal_valued_bc_anchored``) and GAIL's
(``+recipe=gail_bc_start``) start their actor from maximum-likelihood behaviour cloning on
the expert transitions instead of from a random network, so that online training starts
where Causal BC ends instead of spending its first rounds or env steps at zero success.
"""

from __future__ import annotations

import logging
from collections.abc import Callable

import torch

__all__ = ["behaviour_clone"]

log = logging.getLogger(__name__)


def behaviour_clone(nll: Callable[[], torch.Tensor], optimizer: torch.optim.Optimizer, updates: int, max_grad_norm: float) -> None:
    """``updates`` gradient steps of ``optimizer`` on ``nll()`` (a fresh expert batch's negative
    log-likelihood under the actor, each call), its gradient clipped to ``max_grad_norm``
    over the optimizer's first parameter group. Logs the NLL every 1000 steps and at the end.

    Examples:
        >>> import torch
        >>> mean = torch.zeros(1, requires_grad=True)
        >>> data = torch.tensor([1.0, 2.0, 3.0])
        >>> nll = lambda: 0.5 * ((data - mean) ** 2).mean()  # a unit Gaussian's NLL, up to a constant
        >>> behaviour_clone(nll, torch.optim.SGD([mean], lr=0.5), updates=200, max_grad_norm=10.0)
        >>> round(mean.item(), 4)  # the maximum-likelihood mean
        2.0
    """
    for step in range(1, updates + 1):
        loss = nll()
        optimizer.zero_grad(set_to_none=True)
        loss.backward()
        torch.nn.utils.clip_grad_norm_(optimizer.param_groups[0]["params"], max_grad_norm)
        optimizer.step()
        if step % 1000 == 0 or step == updates:
            log.info("warm start: behaviour cloning %d/%d, expert action NLL %.3f", step, updates, loss.item())
