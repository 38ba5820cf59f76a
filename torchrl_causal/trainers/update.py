"""One gradient step of a SAC-family loss (SACLoss, SQILLoss, IQLearnLoss), as the
off-policy trainer takes it, with optional ``torch.compile``.

TorchRL's own :class:`~torchrl.trainers.Trainer` owns its optimizer and loss hooks; the
paper's protocol needs three optimisers (critic, actor, temperature), gradient-norm
clipping per network and a cosine schedule on the critic only, so the step is written
out here once, for the trainer and the throughput benchmarks alike. The optimisers,
the schedule and the target updater are given as factories (the partially instantiated
``algo.*_optimizer``, ``algo.critic_scheduler`` and ``algo.target_update`` nodes of the
config), which the update applies to the loss's parameters.
"""

from __future__ import annotations

import inspect
from collections.abc import Callable, Iterable, Mapping
from typing import Any, TypeVar, cast

import torch
from tensordict import TensorDictBase
from torchrl.objectives import SACLoss, TargetNetUpdater

from torchrl_causal.errors import InvalidValueError
from torchrl_causal.experiment.device import matmul_precision, resolve_precision
from torchrl_causal.experiment.timing import timed

__all__ = ["ActorCriticUpdate", "OptimizerFactory"]

#: Builds an optimiser from the parameters it updates (e.g. ``partial(torch.optim.Adam, lr=3e-4)``).
OptimizerFactory = Callable[[Iterable[torch.Tensor]], torch.optim.Optimizer]

_Forward = TypeVar("_Forward", bound=Callable[..., Any])


def _build_optimizer(factory: OptimizerFactory, params: list[torch.Tensor]) -> torch.optim.Optimizer:
    # On CUDA a fused step is one kernel per step instead of one per tensor, where the
    # optimiser offers it.
    if params[0].device.type == "cuda" and "fused" in inspect.signature(factory).parameters:
        # The signature just checked takes ``fused``, which OptimizerFactory does not name.
        return cast(Callable[..., torch.optim.Optimizer], factory)(params, fused=True)
    return factory(params)


class ActorCriticUpdate:
    """Loss forward, one backward of the sum of its ``loss_*`` outputs, gradient
    norms clipped per network, optimiser steps for critic, actor and alpha, the critic's
    learning-rate schedule, then the update of the target critics.

    SACLoss detaches the critics inside the actor loss, so one backward pass gives each
    network the gradient of its own objective. A step never reads a value back to the
    host: it returns the detached scalars :attr:`SCALARS` stacked in one tensor on the
    loss's device, for the caller to average on the device and log every so often.

    ``compile=True`` runs the loss forward through :func:`torch.compile` (the backward
    then runs the compiled backward graph), for the joint update and for the critic-only
    :meth:`critic_step` alike (a graph each, compiled at its first call); the optimiser
    steps stay eager so the scheduled learning rate never triggers a recompilation.
    Inductor is told to keep eager's random-number stream (``fallback_random``), so a
    compiled run draws the same dropout masks and action samples as an eager one and gives
    the same numbers. Shapes are static (``dynamic=False``): a batch of another size
    compiles a graph of its own. A first compiled call is timed as the run's ``compile``
    part (:func:`~torchrl_causal.experiment.timing.timed`).

    ``precision="bf16"`` runs the loss forward (and so its backward) under a bf16
    autocast (:func:`~torchrl_causal.experiment.device.matmul_precision`): the matmuls in
    bf16, the parameters, their gradients, the optimiser state and the losses' reductions
    in fp32.

    Args:
        loss: a :class:`~torchrl.objectives.SACLoss` (or subclass) whose networks are
            already on their device.

    Keyword Args:
        actor_optimizer, critic_optimizer, alpha_optimizer (OptimizerFactory): build
            each optimiser from its parameters. On CUDA the steps are fused where the
            optimiser offers it (``fused=True``).
        target_update (callable): builds the target-network updater from the loss
            (e.g. ``partial(SoftUpdate, tau=0.005)``); it is stepped after every update.
        max_grad_norm (float): gradient-norm clip, applied to the critics and the actor
            separately.
        critic_scheduler (callable, optional): builds the critic's learning-rate
            schedule from the critic optimiser and ``T_max=cosine_updates`` (e.g.
            ``partial(CosineAnnealingLR, eta_min=0.0)``); ``None`` keeps the learning
            rate constant.
        cosine_updates (int, optional): the updates the schedule spans; it is stepped
            after each of them and then stays at its end. Required with
            ``critic_scheduler``.
        compile (bool): compile the loss forward. Defaults to ``False``.
        compile_options (dict, optional): extra keyword arguments for
            :func:`torch.compile` (``backend``, ``mode``, ...).
        precision (str): ``"fp32"`` (default) or ``"bf16"`` (see above).

    Examples:
        >>> from functools import partial
        >>> from tensordict import TensorDict
        >>> from torchrl.data import Bounded
        >>> from torchrl.objectives import SoftUpdate
        >>> from torchrl_causal.modules import make_qvalue_network, make_tanh_gaussian_actor
        >>> from torchrl_causal.objectives import SQILLoss
        >>> spec = Bounded(-1.0, 1.0, shape=(2,))
        >>> loss = SQILLoss(make_tanh_gaussian_actor(3, spec, hidden=16, num_blocks=1),
        ...                 make_qvalue_network(3, spec, hidden=16, num_blocks=1))
        >>> loss.make_value_estimator(gamma=0.99)
        >>> adam = partial(torch.optim.Adam, lr=3e-4)
        >>> update = ActorCriticUpdate(loss, actor_optimizer=adam, critic_optimizer=adam, alpha_optimizer=adam,
        ...                            target_update=partial(SoftUpdate, tau=0.005), max_grad_norm=1.0,
        ...                            critic_scheduler=torch.optim.lr_scheduler.CosineAnnealingLR, cosine_updates=10)
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
        actor_optimizer: OptimizerFactory,
        critic_optimizer: OptimizerFactory,
        alpha_optimizer: OptimizerFactory,
        target_update: Callable[[SACLoss], TargetNetUpdater],
        max_grad_norm: float,
        critic_scheduler: Callable[..., torch.optim.lr_scheduler.LRScheduler] | None = None,
        cosine_updates: int | None = None,
        compile: bool = False,
        compile_options: Mapping[str, Any] | None = None,
        precision: str = "fp32",
    ) -> None:
        self.loss = loss
        self.max_grad_norm = float(max_grad_norm)
        self.target_updater = target_update(loss)
        self.critic_params = list(loss.qvalue_network_params.flatten_keys().values())
        self.actor_params = list(loss.actor_network_params.flatten_keys().values())
        self.critic_optimizer = _build_optimizer(critic_optimizer, self.critic_params)
        self.actor_optimizer = _build_optimizer(actor_optimizer, self.actor_params)
        self.alpha_optimizer = _build_optimizer(alpha_optimizer, [loss.log_alpha])
        if critic_scheduler is not None and (cosine_updates is None or cosine_updates < 1):
            raise InvalidValueError(f"a critic_scheduler needs cosine_updates >= 1, got {cosine_updates}")
        self.cosine_updates = cosine_updates
        self.critic_schedule = None if critic_scheduler is None else critic_scheduler(self.critic_optimizer, T_max=cosine_updates)
        #: updates taken so far (the cosine schedule's position; saved with the state).
        self.updates = 0
        self.precision = resolve_precision(precision)
        self.device = loss.log_alpha.device
        self.compile_options: dict[str, Any] | None = None
        if compile:
            # Static shapes: a training run feeds one batch size, and a second compiled update
            # of other network sizes in the same process would otherwise turn on automatic
            # dynamic shapes, which vmap over the twin critics cannot trace.
            options = {"dynamic": False, **(compile_options or {})}
            if options.get("backend", "inductor") == "inductor":
                options["options"] = {"fallback_random": True, **options.get("options", {})}
            self.compile_options = options
        self._forward = self._compiled(self.losses)
        self._critic_forward = self._compiled(self.critic_loss)
        self._compiled_calls: set[str] = set()

    def _compiled(self, forward: _Forward) -> _Forward:
        """``forward`` through :func:`torch.compile` with this update's options, or itself (eager)."""
        if self.compile_options is None:
            return forward
        return cast(_Forward, torch.compile(forward, **self.compile_options))

    def _timed_part(self, name: str) -> Any:
        """``timed("compile")`` around the first call of the compiled ``name`` (forward and
        backward: where the graphs are built), else nothing."""
        if self.compile_options is None or name in self._compiled_calls:
            return timed(None)
        self._compiled_calls.add(name)
        return timed("compile")

    @property
    def optimizers(self) -> tuple[torch.optim.Optimizer, ...]:
        return self.critic_optimizer, self.actor_optimizer, self.alpha_optimizer

    def losses(self, batch: TensorDictBase) -> tuple[torch.Tensor, torch.Tensor]:
        # Plain tensors out, no TensorDict: a compiled graph that returns one is rebuilt
        # after the graph, which costs more tracing time than the loss itself.
        with matmul_precision(self.precision, self.device):
            out = self.loss(batch)
        # Every "loss_*" entry (TorchRL's convention): SAC's three and the optional "loss_bc".
        total = sum(value for key, value in out.items() if key.startswith("loss_"))
        return total, torch.stack([out[key].detach() for key in self.SCALARS])

    def __call__(self, batch: TensorDictBase) -> torch.Tensor:
        """One update on ``batch``; returns :attr:`SCALARS` stacked, on the loss's device."""
        with self._timed_part("update"):
            total, scalars = self._forward(batch)
            for optimizer in self.optimizers:
                optimizer.zero_grad(set_to_none=True)
            total.backward()
        torch.nn.utils.clip_grad_norm_(self.critic_params, self.max_grad_norm)
        torch.nn.utils.clip_grad_norm_(self.actor_params, self.max_grad_norm)
        for optimizer in self.optimizers:
            optimizer.step()
        # A schedule always comes with its span (checked in __init__).
        if self.critic_schedule is not None and self.cosine_updates is not None and self.updates < self.cosine_updates:
            self.critic_schedule.step()
        self.target_updater.step()
        self.updates += 1
        return scalars

    def critic_loss(self, batch: TensorDictBase) -> torch.Tensor:
        """The loss's critic term on ``batch`` (the whole loss runs: its draws are the joint
        update's), in this update's precision."""
        with matmul_precision(self.precision, self.device):
            return self.loss(batch)["loss_qvalue"]

    def critic_step(self, batch: TensorDictBase) -> torch.Tensor:
        """One update of the critics alone (clipped, then the target update), the actor and
        alpha left as they are; returns the critic loss, detached. Used to fit the critics to
        a warm-started actor before the two learn together; it neither counts in
        :attr:`updates` nor steps the learning-rate schedule. Compiled (a graph of its own)
        when the update is."""
        with self._timed_part("critic"):
            loss_qvalue = self._critic_forward(batch)
            self.critic_optimizer.zero_grad(set_to_none=True)
            loss_qvalue.backward()
        torch.nn.utils.clip_grad_norm_(self.critic_params, self.max_grad_norm)
        self.critic_optimizer.step()
        for optimizer in (self.actor_optimizer, self.alpha_optimizer):
            optimizer.zero_grad(set_to_none=True)  # the actor and alpha losses were not backpropagated
        self.target_updater.step()
        return loss_qvalue.detach()

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
