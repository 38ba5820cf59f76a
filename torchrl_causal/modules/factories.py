"""Factories that wrap the paper's networks into TorchRL modules with TorchRL keys.

Input sizes are passed explicitly (``observation_dim``, and the action size read from
the action spec) rather than inferred lazily: TorchRL loss modules copy and stack
parameters at construction (twin critics, target networks), which requires materialised
parameters. Trainers pass the size of the encoding that
:class:`~torchrl_causal.transforms.CausalWindowTransform` writes to ``"observation"``.

Defaults follow the paper's Appendix E (hidden width 256; 3 residual blocks and dropout
0.05 for the stochastic actors; 4 blocks, no dropout for BC).
"""

from __future__ import annotations

import torch
from tensordict.nn import (
    AddStateIndependentNormalScale,
    InteractionType,
    TensorDictModule,
    TensorDictSequential,
)
from tensordict.utils import NestedKey
from torch import nn
from torchrl.data import Bounded, Composite, TensorSpec
from torchrl.modules import MLP, ProbabilisticActor, TanhModule, TanhNormal, ValueOperator

from torchrl_causal.errors import InvalidTypeError, InvalidValueError, UnknownKeyError
from torchrl_causal.modules.networks import ResidualMLP, SkipMLP, Standardize

__all__ = [
    "bounded_action_spec",
    "make_deterministic_actor",
    "make_gail_discriminator",
    "make_gail_value_network",
    "make_qvalue_network",
    "make_tanh_gaussian_actor",
]


def bounded_action_spec(action_spec: TensorSpec, action_key: NestedKey = "action") -> Bounded:
    """Returns the continuous bounded spec of one action, unwrapping a :class:`~torchrl.data.Composite`.

    Leading batch dimensions (a batched env's ``action_spec``) are dropped; their bounds
    must agree.

    Examples:
        >>> import torch
        >>> from torchrl.data import Bounded, Composite
        >>> spec = Composite(action=Bounded(-1.0, 1.0, shape=(4, 2)), shape=(4,))
        >>> bounded_action_spec(spec).shape
        torch.Size([2])
    """
    if isinstance(action_spec, Composite):
        if action_key not in action_spec.keys(True, True):
            raise UnknownKeyError(
                f"action key {action_key!r} not found in the composite action spec (keys: {list(action_spec.keys(True, True))})."
            )
        action_spec = action_spec[action_key]
    if not isinstance(action_spec, Bounded) or action_spec.dtype not in (
        torch.float16,
        torch.bfloat16,
        torch.float32,
        torch.float64,
    ):
        raise InvalidTypeError(
            f"action {action_key!r} needs a continuous Bounded spec, got {type(action_spec).__name__} with dtype {action_spec.dtype}."
        )
    low, high = action_spec.space.low, action_spec.space.high
    if not (torch.isfinite(low).all() and torch.isfinite(high).all() and (high > low).all()):
        raise InvalidValueError(f"action {action_key!r} needs finite bounds with high > low, got [{low}, {high}].")
    while action_spec.ndim > 1:
        first = action_spec[0]
        if not ((action_spec.space.low == first.space.low).all() and (action_spec.space.high == first.space.high).all()):
            raise InvalidValueError(f"action {action_key!r} has different bounds across its batch dimensions.")
        action_spec = first
    return action_spec


def _action_dim(spec: Bounded) -> int:
    return spec.shape.numel()


def _bound(values: torch.Tensor) -> float | torch.Tensor:
    # Scalar bounds stay Python floats so the distribution follows the module to any device.
    return values.flatten()[0].item() if (values == values.flatten()[0]).all() else values


def make_tanh_gaussian_actor(
    observation_dim: int,
    action_spec: TensorSpec,
    *,
    hidden: int = 256,
    num_blocks: int = 3,
    dropout: float = 0.05,
    log_std_init: float = 0.0,
    observation_key: NestedKey = "observation",
    action_key: NestedKey = "action",
) -> ProbabilisticActor:
    """Tanh-Gaussian actor with a state-independent learnable log-std (SQIL, IQ-Learn, GAIL).

    The residual MLP outputs the Gaussian's pre-tanh mean; the log-std is one learnable
    vector (``scale = exp(log_std)``); :class:`~torchrl.modules.TanhNormal` squashes
    samples to the spec's bounds. The actor samples by default (``InteractionType.RANDOM``),
    writes ``"loc"``, ``"scale"``, the action and its log-probability (PPO reads it).

    Examples:
        >>> import torch
        >>> from tensordict import TensorDict
        >>> from torchrl.data import Bounded
        >>> spec = Bounded(-0.4, 0.4, shape=(3,))
        >>> actor = make_tanh_gaussian_actor(5, spec, hidden=16, num_blocks=1)
        >>> td = actor(TensorDict({"observation": torch.randn(7, 5)}, [7]))
        >>> td["action"].shape, bool((td["action"].abs() <= 0.4).all())
        (torch.Size([7, 3]), True)
    """
    spec = bounded_action_spec(action_spec, action_key)
    action_dim = _action_dim(spec)
    body = nn.Sequential(
        ResidualMLP(observation_dim, action_dim, hidden=hidden, num_blocks=num_blocks, dropout=dropout),
        AddStateIndependentNormalScale(action_dim, scale_mapping="exp", init_value=log_std_init),
    )
    module = TensorDictModule(body, in_keys=[observation_key], out_keys=["loc", "scale"])
    return ProbabilisticActor(
        module,
        in_keys=["loc", "scale"],
        out_keys=[action_key],
        spec=spec,
        distribution_class=TanhNormal,
        distribution_kwargs={"low": _bound(spec.space.low), "high": _bound(spec.space.high)},
        default_interaction_type=InteractionType.RANDOM,
        return_log_prob=True,
    )


def make_deterministic_actor(
    observation_dim: int,
    action_spec: TensorSpec,
    *,
    hidden: int = 256,
    num_blocks: int = 4,
    dropout: float = 0.0,
    standardize_observation: bool = False,
    observation_key: NestedKey = "observation",
    action_key: NestedKey = "action",
) -> TensorDictSequential:
    """Deterministic actor for Causal BC: residual MLP then tanh to the spec's bounds.

    With ``standardize_observation`` a :class:`~torchrl_causal.modules.networks.Standardize`
    comes first, the identity until :func:`~torchrl_causal.modules.networks.fit_standardizers`
    fits it (the BC trainer does, on the training demonstrations).

    Examples:
        >>> import torch
        >>> from tensordict import TensorDict
        >>> from torchrl.data import Bounded
        >>> spec = Bounded(-1.0, 1.0, shape=(2,))
        >>> actor = make_deterministic_actor(4, spec, hidden=16, num_blocks=1)
        >>> actor(TensorDict({"observation": torch.randn(3, 4)}, [3]))["action"].shape
        torch.Size([3, 2])
    """
    spec = bounded_action_spec(action_spec, action_key)
    body: nn.Module = ResidualMLP(observation_dim, _action_dim(spec), hidden=hidden, num_blocks=num_blocks, dropout=dropout)
    if standardize_observation:
        body = nn.Sequential(Standardize(observation_dim), body)
    return TensorDictSequential(
        TensorDictModule(body, in_keys=[observation_key], out_keys=[action_key]),
        TanhModule(in_keys=[action_key], out_keys=[action_key], spec=spec),
    )


def make_qvalue_network(
    observation_dim: int,
    action_spec: TensorSpec,
    *,
    hidden: int = 256,
    num_blocks: int = 3,
    dropout: float = 0.0,
    observation_key: NestedKey = "observation",
    action_key: NestedKey = "action",
) -> ValueOperator:
    """Q-network over ``(observation, action)`` with the paper's residual MLP; writes ``"state_action_value"``.

    Pass one instance to :class:`~torchrl_causal.objectives.SQILLoss` or
    :class:`~torchrl_causal.objectives.IQLearnLoss`: the loss makes the twin copies.

    Examples:
        >>> import torch
        >>> from tensordict import TensorDict
        >>> from torchrl.data import Bounded
        >>> q = make_qvalue_network(4, Bounded(-1.0, 1.0, shape=(2,)), hidden=16, num_blocks=1)
        >>> td = TensorDict({"observation": torch.randn(3, 4), "action": torch.zeros(3, 2)}, [3])
        >>> q(td)["state_action_value"].shape
        torch.Size([3, 1])
    """
    spec = bounded_action_spec(action_spec, action_key)
    body = ResidualMLP(observation_dim + _action_dim(spec), 1, hidden=hidden, num_blocks=num_blocks, dropout=dropout)
    return ValueOperator(body, in_keys=[observation_key, action_key])


def make_gail_value_network(observation_dim: int, *, hidden: int = 256, observation_key: NestedKey = "observation") -> ValueOperator:
    """GAIL's critic: a three-layer ReLU MLP over the observation; writes ``"state_value"``.

    Examples:
        >>> import torch
        >>> from tensordict import TensorDict
        >>> v = make_gail_value_network(4, hidden=16)
        >>> v(TensorDict({"observation": torch.randn(3, 4)}, [3]))["state_value"].shape
        torch.Size([3, 1])
    """
    body = MLP(in_features=observation_dim, out_features=1, num_cells=[hidden, hidden], activation_class=nn.ReLU)
    return ValueOperator(body, in_keys=[observation_key])


def make_gail_discriminator(
    observation_dim: int,
    action_spec: TensorSpec,
    *,
    hidden: int = 256,
    dropout: float = 0.2,
    observation_key: NestedKey = "observation",
    action_key: NestedKey = "action",
    out_key: NestedKey = "d_logits",
) -> TensorDictModule:
    """GAIL's discriminator: a skip-connected three-layer ReLU MLP with dropout, logit output.

    The output is the logit of the probability that ``(observation, action)`` comes from
    the expert, written to ``"d_logits"`` (the key TorchRL's
    :class:`~torchrl.objectives.GAILLoss` reads). Logits, not probabilities: the loss is
    binary cross-entropy with logits, the gradient penalty acts on the logit (a sigmoid
    output cannot keep a unit gradient where it saturates), and the reward is built from
    the logit without rounding ``D`` to 0 or 1.

    Examples:
        >>> import torch
        >>> from tensordict import TensorDict
        >>> from torchrl.data import Bounded
        >>> d = make_gail_discriminator(4, Bounded(-1.0, 1.0, shape=(2,)), hidden=16)
        >>> td = TensorDict({"observation": torch.randn(3, 4), "action": torch.zeros(3, 2)}, [3])
        >>> d(td)["d_logits"].shape
        torch.Size([3, 1])
    """
    spec = bounded_action_spec(action_spec, action_key)
    body = SkipMLP(observation_dim + _action_dim(spec), 1, hidden=hidden, dropout=dropout)
    return TensorDictModule(body, in_keys=[observation_key, action_key], out_keys=[out_key])
