"""One gradient step of a SAC-family loss (SACLoss, SQILLoss, IQLearnLoss), as the
off-policy trainer takes it, with optional ``torch.compile``.

TorchRL's own :class:`~torchrl.trainers.Trainer` owns its optimizer and loss hooks; the
paper's protocol needs three Adam optimisers (critic, actor, temperature), gradient-norm
clipping per network and a cosine schedule on the critic only, so the step is written
out here once, for the trainer and the throughput benchmarks alike.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import torch
from tensordict import TensorDictBase
from torchrl.objectives import SACLoss, SoftUpdate

__all__ = ["ActorCriticUpdate"]


class ActorCriticUpdate:
    """Loss forward, one backward of ``loss_qvalue + loss_actor + loss_alpha``, gradient
    norms clipped per network, Adam steps for critic, actor and alpha, the critic's
    cosine learning-rate schedule, then a Polyak update of the target critics.

    SACLoss detaches the critics inside the actor loss, so one backward pass gives each
    network the gradient of its own objective. A step never reads a value back to the
    host: it returns the detached scalars :attr:`SCALARS` stacked in one tensor on the
    loss's device, for the caller to average on the device and log every so often.

    ``compile=True`` runs the loss forward through :func:`torch.compile` (the backward
    then runs the compiled backward graph); the optimiser steps stay eager so the
    scheduled learning rate never triggers a recompilation. Inductor is told to keep
    eager's random-number stream (``fallback_random``), so a compiled run draws the same
    dropout masks and action samples as an eager one and gives the same numbers.

    Args:
        loss: a :class:`~torchrl.objectives.SACLoss` (or subclass) whose networks are
            already on their device. On CUDA the Adam steps are fused.

    Keyword Args:
        lr_actor, lr_critic, lr_alpha (float): Adam learning rates.
        max_grad_norm (float): gradient-norm clip, applied to the critics and the actor
            separately.
        tau (float): Polyak factor of the target critics.
        cosine_updates (int, optional): length of the critic's cosine schedule in
            updates; ``None`` keeps the learning rate constant.
        compile (bool): compile the loss forward. Defaults to ``False``.
        compile_options (dict, optional): extra keyword arguments for
            :func:`torch.compile` (``backend``, ``mode``, ...).

    Examples:
        >>> from tensordict import TensorDict
        >>> from torchrl.data import Bounded
        >>> from torchrl_causal.modules import make_qvalue_network, make_tanh_gaussian_actor
        >>> from torchrl_causal.objectives import SQILLoss
        >>> spec = Bounded(-1.0, 1.0, shape=(2,))
        >>> loss = SQILLoss(make_tanh_gaussian_actor(3, spec, hidden=16, num_blocks=1),
        ...                 make_qvalue_network(3, spec, hidden=16, num_blocks=1))
        >>> loss.make_value_estimator(gamma=0.99)
        >>> update = ActorCriticUpdate(loss, lr_actor=3e-4, lr_critic=3e-4, lr_alpha=3e-4, max_grad_norm=1.0,
        ...                            tau=0.005, cosine_updates=10)
        >>> batch = TensorDict({
        ...     "observation": torch.randn(4, 3), "action": spec.rand((4,)),
        ...     "expert": torch.tensor([[True], [True], [False], [False]]),
        ...     "next": {"observation": torch.randn(4, 3), "done": torch.zeros(4, 1, dtype=torch.bool),
        ...              "terminated": torch.zeros(4, 1, dtype=torch.bool)},
        ... }, [4])
        >>> scalars = update(batch)
        >>> scalars.shape, update.updates, update.SCALARS
        (torch.Size([4]), 1, ('loss_qvalue', 'loss_actor', 'alpha', 'entropy'))
    """

    #: The loss outputs a step returns, in order.
    SCALARS: tuple[str, ...] = ("loss_qvalue", "loss_actor", "alpha", "entropy")

    def __init__(
        self,
        loss: SACLoss,
        *,
        lr_actor: float,
        lr_critic: float,
        lr_alpha: float,
        max_grad_norm: float,
        tau: float,
        cosine_updates: int | None = None,
        compile: bool = False,
        compile_options: Mapping[str, Any] | None = None,
    ) -> None:
        self.loss = loss
        self.max_grad_norm = float(max_grad_norm)
        self.target_updater = SoftUpdate(loss, tau=tau)
        fused = loss.log_alpha.device.type == "cuda"  # one kernel per step instead of one per tensor
        self.critic_params = list(loss.qvalue_network_params.flatten_keys().values())
        self.actor_params = list(loss.actor_network_params.flatten_keys().values())
        self.critic_optimizer = torch.optim.Adam(self.critic_params, lr=lr_critic, fused=fused)
        self.actor_optimizer = torch.optim.Adam(self.actor_params, lr=lr_actor, fused=fused)
        self.alpha_optimizer = torch.optim.Adam([loss.log_alpha], lr=lr_alpha, fused=fused)
        if cosine_updates is not None and cosine_updates < 1:
            raise ValueError(f"cosine_updates must be >= 1 (or None for a constant rate), got {cosine_updates}")
        self.cosine_updates = cosine_updates
        self.critic_schedule = (None if cosine_updates is None
                                else torch.optim.lr_scheduler.CosineAnnealingLR(self.critic_optimizer, cosine_updates))
        self.updates = 0
        if compile:
            options = dict(compile_options or {})
            if options.get("backend", "inductor") == "inductor":
                options["options"] = {"fallback_random": True, **options.get("options", {})}
            self._forward = torch.compile(self._losses, **options)
        else:
            self._forward = self._losses

    @property
    def optimizers(self) -> tuple[torch.optim.Optimizer, ...]:
        return self.critic_optimizer, self.actor_optimizer, self.alpha_optimizer

    def _losses(self, batch: TensorDictBase) -> tuple[torch.Tensor, torch.Tensor]:
        # Plain tensors out, no TensorDict: a compiled graph that returns one is rebuilt
        # after the graph, which costs more tracing time than the loss itself.
        out = self.loss(batch)
        total = out["loss_qvalue"] + out["loss_actor"] + out["loss_alpha"]
        return total, torch.stack([out[key].detach() for key in self.SCALARS])

    def __call__(self, batch: TensorDictBase) -> torch.Tensor:
        """One update on ``batch``; returns :attr:`SCALARS` stacked, on the loss's device."""
        total, scalars = self._forward(batch)
        for optimizer in self.optimizers:
            optimizer.zero_grad(set_to_none=True)
        total.backward()
        torch.nn.utils.clip_grad_norm_(self.critic_params, self.max_grad_norm)
        torch.nn.utils.clip_grad_norm_(self.actor_params, self.max_grad_norm)
        for optimizer in self.optimizers:
            optimizer.step()
        if self.critic_schedule is not None and self.updates < self.cosine_updates:
            self.critic_schedule.step()
        self.target_updater.step()
        self.updates += 1
        return scalars

    def state_dict(self) -> dict[str, Any]:
        """Optimiser and schedule states and the update count (the loss saves its own)."""
        return {
            "actor_optimizer": self.actor_optimizer.state_dict(),
            "critic_optimizer": self.critic_optimizer.state_dict(),
            "alpha_optimizer": self.alpha_optimizer.state_dict(),
            "critic_schedule": self.critic_schedule.state_dict() if self.critic_schedule is not None else {},
            "updates": self.updates,
        }

    def load_state_dict(self, state: Mapping[str, Any]) -> None:
        self.actor_optimizer.load_state_dict(state["actor_optimizer"])
        self.critic_optimizer.load_state_dict(state["critic_optimizer"])
        self.alpha_optimizer.load_state_dict(state["alpha_optimizer"])
        if self.critic_schedule is not None:
            self.critic_schedule.load_state_dict(state["critic_schedule"])
        self.updates = int(state["updates"])
