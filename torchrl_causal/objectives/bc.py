"""Causal BC: TorchRL's :class:`~torchrl.objectives.BCLoss` with a Huber regression loss."""

from __future__ import annotations

from functools import partial

import torch.nn.functional as F
from tensordict.nn import TensorDictModule, TensorDictParams
from torchrl.objectives import BCLoss

from torchrl_causal.errors import InvalidValueError

__all__ = ["HuberBCLoss"]


class HuberBCLoss(BCLoss):
    """Behaviour cloning of a deterministic actor with a Huber loss (the paper's Causal BC).

    Causal BC differs from BC only in its input (the causally adjusted encoding in
    ``"observation"``), so this is :class:`~torchrl.objectives.BCLoss` with
    ``F.huber_loss(prediction, expert_action, delta=delta)`` averaged over batch and
    action dimensions, written to ``"loss_bc"``.

    Args:
        actor_network (TensorDictModule): deterministic actor writing ``"action"``, e.g.
            :func:`~torchrl_causal.modules.make_deterministic_actor`.

    Keyword Args:
        delta (float, optional): Huber threshold between the quadratic and linear
            regimes. Defaults to ``1.0``.
        reduction (str, optional): ``"mean"`` (default), ``"sum"`` or ``"none"``.

    Examples:
        >>> import torch
        >>> from tensordict import TensorDict
        >>> from torchrl.data import Bounded
        >>> from torchrl_causal.modules import make_deterministic_actor
        >>> from torchrl_causal.objectives import HuberBCLoss
        >>> spec = Bounded(-1.0, 1.0, shape=(2,))
        >>> actor = make_deterministic_actor(3, spec, hidden=16, num_blocks=1)
        >>> loss = HuberBCLoss(actor)
        >>> batch = TensorDict({"observation": torch.randn(5, 3), "action": spec.rand((5,))}, [5])
        >>> out = loss(batch)
        >>> out["loss_bc"].shape
        torch.Size([])
        >>> out["loss_bc"].backward()
    """

    # BCLoss does not declare what convert_to_functional creates, so TorchRL warns on
    # every construction; declaring the target name here silences that (BC has no target).
    target_actor_network_params: TensorDictParams | None

    def __init__(self, actor_network: TensorDictModule, *, delta: float = 1.0, reduction: str | None = None) -> None:
        if not delta > 0:
            raise InvalidValueError(f"delta must be positive, got {delta!r}.")
        super().__init__(actor_network, loss_function=partial(F.huber_loss, reduction="none", delta=delta), reduction=reduction)
        self.delta = delta
