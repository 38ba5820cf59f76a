"""Transforms of the action a policy emits, before the env reads it."""

from __future__ import annotations

import torch
from torchrl.data import Binary, Bounded, Composite, TensorSpec
from torchrl.envs import Transform

from torchrl_causal.errors import InvalidTypeError

__all__ = ["RelaxedBinaryAction"]


class RelaxedBinaryAction(Transform):
    """Presents a binary action (e.g. Route Choice's X) as a continuous one in ``[0, 1]``.

    The continuous-control actors of every algorithm output a bounded real action; the
    env receives ``action > 0.5``. This is the algorithms' relaxation, not part of the
    env's mechanism: the builders append it to a binary-action env
    (:func:`~torchrl_causal.experiment.builders.make_imitator_env`).

    Examples:
        >>> from torchrl.envs import TransformedEnv
        >>> from torchrl.data import Bounded
        >>> from torchrl_causal.envs import RouteChoiceEnv
        >>> env = TransformedEnv(RouteChoiceEnv(batch_size=(3,), seed=0), RelaxedBinaryAction())
        >>> spec = env.action_spec
        >>> isinstance(spec, Bounded), spec.space.low.unique().item(), spec.space.high.unique().item()
        (True, 0.0, 1.0)
        >>> td = env.reset().set("action", torch.tensor([[0.2], [0.7], [0.5]]))
        >>> env.step(td)["next", "terminated"].shape
        torch.Size([3, 1])
    """

    def __init__(self, action_key: str = "action") -> None:
        super().__init__(in_keys_inv=[action_key], out_keys_inv=[action_key])

    def _inv_apply_transform(self, action: torch.Tensor) -> torch.Tensor:
        return (action > 0.5).to(action.dtype)

    def transform_action_spec(self, action_spec: TensorSpec) -> TensorSpec:
        if isinstance(action_spec, Composite):
            for key in self.in_keys_inv:
                action_spec[key] = self.transform_action_spec(action_spec[key])
            return action_spec
        if not isinstance(action_spec, Binary):
            raise InvalidTypeError(f"RelaxedBinaryAction expects a Binary action spec, got {type(action_spec).__name__}")
        return Bounded(0.0, 1.0, shape=action_spec.shape, device=action_spec.device, dtype=torch.float32)
