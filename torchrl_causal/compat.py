"""The TorchRL private names this package relies on, in one place.

TorchRL keeps these out of its public API. Each is wrapped here under a name that says what
it does, so a TorchRL release that moves one breaks this module alone; ``pyproject.toml``
bounds ``torchrl`` to the minor version the tests pass on.

Examples:
    >>> import torch
    >>> from tensordict import TensorDict
    >>> reset_mask("_reset", TensorDict({"_reset": torch.tensor([[True], [False]])}, batch_size=[2]))
    tensor([ True, False])
    >>> reset_mask("_reset", TensorDict({}, batch_size=[3]))  # no reset key: every env resets
    tensor([True, True, True])
"""

from __future__ import annotations

import torch
from tensordict import TensorDictBase
from tensordict.utils import NestedKey
from torchrl.envs.transforms.utils import _get_reset
from torchrl.objectives import LossModule

__all__ = ["reduce_loss", "reset_mask"]


def reset_mask(reset_key: NestedKey, tensordict: TensorDictBase) -> torch.Tensor:
    """Which envs of ``tensordict``'s batch a reset call resets: its ``reset_key`` entry
    reduced to the batch shape, or all of them when the entry is absent (a full reset)."""
    return _get_reset(reset_key, tensordict)


def reduce_loss(loss_module: LossModule, loss: torch.Tensor, tensordict: TensorDictBase | None = None,
                *, weights: torch.Tensor | None = None) -> torch.Tensor:
    """``loss`` reduced as ``loss_module`` is configured to (its ``reduction``, with the
    sampler's importance ``weights`` when given), as TorchRL's own losses reduce theirs."""
    return loss_module._reduce_loss(loss, tensordict=tensordict, weights=weights)
