"""The private names of the libraries this package relies on, in one place.

TorchRL (and, in two places each, torch and OmegaConf) keep these out of their public
API. Each is wrapped here under a name that says what it does, so a release that moves
one breaks this module alone; ``pyproject.toml`` bounds ``torchrl`` to the minor version
the tests pass on. ``tests/test_structure.py`` checks that no other module reads a private
name it does not define.

Two TorchRL hooks are private methods a subclass must override: the keys a loss reads
(``_set_in_keys``) and SAC's critic target (``_compute_target_v2``). :class:`InKeysHook`
and :class:`SACLossWithHooks` override them once, here, and hand each to a public method
(:meth:`~InKeysHook.adjust_in_keys`, :meth:`~SACLossWithHooks.critic_target`) that the
package's losses override instead.

Examples:
    >>> import torch
    >>> from tensordict import TensorDict
    >>> reset_mask("_reset", TensorDict({"_reset": torch.tensor([[True], [False]])}, batch_size=[2]))
    tensor([ True, False])
    >>> reset_mask("_reset", TensorDict({}, batch_size=[3]))  # no reset key: every env resets
    tensor([True, True, True])
"""

from __future__ import annotations

from typing import Any

import torch
from omegaconf import Node
from omegaconf.basecontainer import BaseContainer
from tensordict import TensorDictBase
from tensordict.utils import NestedKey
from torchrl.collectors import Collector
from torchrl.envs.transforms.utils import _get_reset
from torchrl.objectives import LossModule, SACLoss

__all__ = [
    "InKeysHook",
    "SACLossWithHooks",
    "assert_on_device",
    "collector_carrier",
    "config_child",
    "config_holds_value",
    "dynamo_supported",
    "entropy_coefficient",
    "priority_weights",
    "qvalues_per_critic",
    "reduce_loss",
    "reset_mask",
]


def reset_mask(reset_key: NestedKey, tensordict: TensorDictBase) -> torch.Tensor:
    """Which envs of ``tensordict``'s batch a reset call resets: its ``reset_key`` entry
    reduced to the batch shape, or all of them when the entry is absent (a full reset)."""
    return _get_reset(reset_key, tensordict)


def reduce_loss(
    loss_module: LossModule, loss: torch.Tensor, tensordict: TensorDictBase | None = None, *, weights: torch.Tensor | None = None
) -> torch.Tensor:
    """``loss`` reduced as ``loss_module`` is configured to (its ``reduction``, with the
    sampler's importance ``weights`` when given), as TorchRL's own losses reduce theirs."""
    return loss_module._reduce_loss(loss, tensordict=tensordict, weights=weights)


def priority_weights(loss_module: LossModule, tensordict: TensorDictBase) -> torch.Tensor | None:
    """The prioritized sampler's importance weights in ``tensordict``, or ``None`` when the
    batch has none or ``loss_module`` is told not to use them (its ``use_prioritized_weights``)."""
    return loss_module._maybe_get_priority_weight(tensordict)


def qvalues_per_critic(loss_module: SACLoss, tensordict: TensorDictBase, qvalue_params: TensorDictBase) -> TensorDictBase:
    """``loss_module``'s critic applied to ``tensordict`` once per critic, vmapped over the
    stacked ``qvalue_params`` (online or target): outputs gain a leading critic dimension."""
    return loss_module._vmap_qnetworkN0(tensordict, qvalue_params)


def entropy_coefficient(loss_module: SACLoss) -> torch.Tensor:
    """SAC's entropy coefficient ``exp(log_alpha)``, without gradient, after the loss's clamp
    (``min_alpha``/``max_alpha``) has been applied in place to ``log_alpha``."""
    return loss_module._alpha


def collector_carrier(collector: Collector) -> TensorDictBase:
    """The step ``collector`` acts on next (its carrier): the one piece of its runtime
    state that TorchRL's own state dict leaves out."""
    return collector._carrier


def dynamo_supported() -> bool:
    """Whether ``torch.compile`` (dynamo) supports this Python and this torch."""
    return torch._dynamo.is_dynamo_supported()


def assert_on_device(condition: torch.Tensor, message: str) -> None:
    """Fail with ``message`` where ``condition`` (a one-element bool tensor) is false, checked
    by the device itself: no host read, so no stall of an accelerator or break of a compiled graph."""
    torch._assert_async(condition, message)


def config_child(node: BaseContainer, key: Any) -> Any:
    """The node under ``key`` of an OmegaConf container, its interpolations left unresolved."""
    return node._get_node(key)


def config_holds_value(node: Node) -> bool:
    """Whether an OmegaConf node is neither ``None`` nor missing (``???``)."""
    return not node._is_none() and not node._is_missing()


class InKeysHook:
    """Mixin for a TorchRL loss that reads other keys than its parent: override
    :meth:`adjust_in_keys`. (TorchRL builds a loss's ``in_keys`` lazily, and again after
    ``set_keys``, through its private ``_set_in_keys``.) List it before the TorchRL loss.

    Examples:
        >>> import torch
        >>> from tensordict.nn import TensorDictModule
        >>> from torchrl.objectives import GAILLoss
        >>> class FlaggedGAIL(InKeysHook, GAILLoss):
        ...     def adjust_in_keys(self, keys):
        ...         return [*keys, "flag"]
        >>> discriminator = TensorDictModule(torch.nn.Linear(3, 1), in_keys=["x"], out_keys=["d"])
        >>> "flag" in FlaggedGAIL(discriminator).in_keys
        True
    """

    _in_keys: list[NestedKey]  # TorchRL's LossModule sets it

    def adjust_in_keys(self, keys: list[NestedKey]) -> list[NestedKey]:
        """The keys the loss reads, given those its TorchRL parent reads (``keys``, a copy)."""
        return keys

    def _set_in_keys(self) -> None:
        super()._set_in_keys()  # type: ignore[misc]
        self._in_keys = self.adjust_in_keys(list(self._in_keys))


class SACLossWithHooks(InKeysHook, SACLoss):
    """TorchRL's :class:`~torchrl.objectives.SACLoss` with a public override point for the
    critic's soft Bellman target (SAC v2's private ``_compute_target_v2``): override
    :meth:`critic_target`, calling ``super().critic_target(tensordict)`` for SAC's own."""

    def critic_target(self, tensordict: TensorDictBase) -> torch.Tensor:
        r"""SAC v2's critic target: the value estimator's target over the next state's soft value
        :math:`\min_j Q'_j(s', a') - \alpha \log\pi(a' \mid s')`, :math:`a' \sim \pi(\cdot \mid s')`,
        from the target critics, without gradient (TD(0): :math:`r + \gamma (1 - d)\, V(s')`)."""
        return super()._compute_target_v2(tensordict)

    def _compute_target_v2(self, tensordict: TensorDictBase) -> torch.Tensor:
        return self.critic_target(tensordict)
