"""Helpers shared by the losses and the loops that drive them."""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager

from torch import nn

__all__ = ["eval_mode"]


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
