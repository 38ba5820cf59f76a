"""Network bodies from the paper's Appendix E ("Network architecture").

These are plain :class:`torch.nn.Module` s that map concatenated inputs to an output
vector; :mod:`torchrl_causal.modules.factories` wraps them into TorchRL actors, critics
and discriminators with TorchRL keys. Squashing to the action bounds is left to the
TorchRL pieces that own the bounds (:class:`~torchrl.modules.TanhNormal` for stochastic
actors, :class:`~torchrl.modules.TanhModule` for deterministic ones), so the bodies stay
unbounded and can serve as critics too.
"""

from __future__ import annotations

import torch
from torch import nn

from torchrl_causal.errors import InvalidValueError

__all__ = ["AutocastLinear", "ResidualBlock", "ResidualMLP", "SkipMLP", "Standardize", "fit_standardizers"]


def _check_positive(name: str, value: int) -> None:
    if not isinstance(value, int) or value < 1:
        raise InvalidValueError(f"{name} must be a positive integer, got {value!r}.")


def _check_dropout(dropout: float) -> None:
    if not 0.0 <= dropout < 1.0:
        raise InvalidValueError(f"dropout must lie in [0, 1), got {dropout!r}.")


def _concat(inputs: tuple[torch.Tensor, ...]) -> torch.Tensor:
    # TorchRL critics receive (observation, action) as separate tensors.
    return inputs[0] if len(inputs) == 1 else torch.cat(inputs, dim=-1)


def _autocast_dtype(device_type: str) -> torch.dtype | None:
    """The dtype of an enclosing :class:`torch.autocast` on ``device_type``, or ``None``."""
    return torch.get_autocast_dtype(device_type) if torch.is_autocast_enabled(device_type) else None


class AutocastLinear(nn.Linear):
    """:class:`torch.nn.Linear` that computes in an enclosing autocast's dtype even inside
    :func:`torch.vmap`, which autocast does not reach (the twin critics are vmapped: under
    ``algo.precision=bf16`` their matmuls would stay fp32). Without autocast it is
    ``nn.Linear``, the same parameters and state-dict keys.

    Examples:
        >>> layer = AutocastLinear(4, 2)
        >>> with torch.autocast("cpu", dtype=torch.bfloat16):
        ...     torch.vmap(layer)(torch.ones(3, 5, 4)).dtype
        torch.bfloat16
        >>> layer(torch.ones(3, 4)).dtype
        torch.float32
    """

    def forward(self, input: torch.Tensor) -> torch.Tensor:
        dtype = _autocast_dtype(input.device.type)
        if dtype is None:
            return super().forward(input)
        bias = None if self.bias is None else self.bias.to(dtype)
        return nn.functional.linear(input.to(dtype), self.weight.to(dtype), bias)


def _unbroadcast(tensor: torch.Tensor) -> torch.Tensor:
    """``tensor`` with every leading dim that ``expand`` repeated (stride 0) cut to size 1."""
    for dim in range(tensor.ndim - 1):
        if tensor.stride(dim) == 0 and tensor.shape[dim] > 1:
            tensor = tensor.narrow(dim, 0, 1)
    return tensor


def _project_parts(projection: nn.Linear, collapsed: list[torch.Tensor], batch_shape: torch.Size) -> torch.Tensor:
    """``projection(cat(inputs))`` as a sum of one linear map per input, each on the input
    with its expanded dims cut to size 1 (``collapsed``): an input shared by K rows is
    projected once, and the sum is broadcast back to ``batch_shape``."""
    dtype = _autocast_dtype(collapsed[0].device.type) or projection.weight.dtype  # as AutocastLinear computes
    weights = projection.weight.to(dtype).split([t.shape[-1] for t in collapsed], dim=-1)
    parts = [nn.functional.linear(t.to(dtype), w) for t, w in zip(collapsed, weights)]
    out = sum(parts[1:], parts[0]) + projection.bias.to(dtype)
    return out.expand(*batch_shape, out.shape[-1])


class Standardize(nn.Module):
    """Per-feature standardisation ``(x - loc) / scale`` with ``loc`` and ``scale`` fitted to data.

    Not in the paper's architecture (Appendix E): an option for inputs whose features
    differ in scale by orders of magnitude, such as AntMaze's window (positions in metres
    up to ~20, hinge angles in radians, velocities); on AntMaze-Medium's C-BC it cost ~12
    points of success (``results/antmaze_medium.md``), so it is off by default. ``loc``
    and ``scale`` are buffers, so they travel with the network's state dict (checkpoints);
    before :meth:`fit` they are 0 and 1 and the module is the identity.

    Args:
        features (int): size of the last input dimension.

    Examples:
        >>> import torch
        >>> standardize = Standardize(2)
        >>> samples = torch.tensor([[0.0, 5.0], [10.0, 5.0]])
        >>> standardize.fit(samples)(samples)  # the constant feature keeps scale 1
        tensor([[-0.7071,  0.0000],
                [ 0.7071,  0.0000]])
    """

    # Buffers (registered in __init__), declared so that they read as tensors.
    loc: torch.Tensor
    scale: torch.Tensor

    def __init__(self, features: int) -> None:
        super().__init__()
        _check_positive("features", features)
        self.register_buffer("loc", torch.zeros(features))
        self.register_buffer("scale", torch.ones(features))

    @torch.no_grad()
    def fit(self, samples: torch.Tensor, min_scale: float = 1e-6) -> Standardize:
        """Sets ``loc`` and ``scale`` to the mean and standard deviation of ``samples``
        (``(n, features)``, ``n >= 2``); a feature whose deviation is below ``min_scale``
        keeps scale 1, so a constant input is centred, not blown up. Returns ``self``."""
        if samples.ndim != 2 or samples.shape[-1] != self.loc.numel() or samples.shape[0] < 2:
            raise InvalidValueError(
                f"Standardize({self.loc.numel()}).fit needs (n >= 2, {self.loc.numel()}) samples, got shape {tuple(samples.shape)}."
            )
        samples = samples.to(self.loc)
        deviation = samples.std(dim=0)
        self.loc.copy_(samples.mean(dim=0))
        self.scale.copy_(torch.where(deviation > min_scale, deviation, torch.ones_like(deviation)))
        return self

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return (x - self.loc) / self.scale


def fit_standardizers(module: nn.Module, samples: torch.Tensor) -> int:
    """Fits every :class:`Standardize` inside ``module`` to ``samples``; returns how many."""
    standardizers = [child for child in module.modules() if isinstance(child, Standardize)]
    for standardize in standardizers:
        standardize.fit(samples)
    return len(standardizers)


class ResidualBlock(nn.Module):
    """Pre-norm residual block: ``x + Linear(Dropout(SiLU(LN(Linear(SiLU(LN(x)))))))``.

    Args:
        width (int): feature width of the block's input and output.
        dropout (float, optional): dropout probability before the second linear
            layer. Defaults to ``0.0``.

    Examples:
        >>> import torch
        >>> block = ResidualBlock(8)
        >>> block(torch.zeros(5, 8)).shape
        torch.Size([5, 8])
    """

    def __init__(self, width: int, dropout: float = 0.0) -> None:
        super().__init__()
        _check_positive("width", width)
        _check_dropout(dropout)
        self.body = nn.Sequential(
            nn.LayerNorm(width),
            nn.SiLU(),
            AutocastLinear(width, width),
            nn.LayerNorm(width),
            nn.SiLU(),
            nn.Dropout(dropout),
            AutocastLinear(width, width),
        )

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return x + self.body(x)


class ResidualMLP(nn.Module):
    """The paper's residual MLP backbone (actor and Q-networks of every algorithm).

    A linear projection to ``hidden`` features, ``num_blocks`` :class:`ResidualBlock` s
    and a linear output head. Several inputs are concatenated along the last dimension,
    so a Q-network is ``ResidualMLP(obs_dim + act_dim, 1)`` called as ``net(obs, act)``.

    Args:
        in_features (int): size of the (concatenated) input.
        out_features (int): size of the output.

    Keyword Args:
        hidden (int, optional): hidden width. Defaults to ``256`` (paper).
        num_blocks (int, optional): number of residual blocks. Defaults to ``3``
            (paper's SQIL, IQ-Learn and GAIL actors; BC uses ``4``).
        dropout (float, optional): dropout inside each block. Defaults to ``0.0``
            (paper's actors use ``0.05``, BC ``0.0``).

    Examples:
        >>> import torch
        >>> net = ResidualMLP(3 + 2, 1, hidden=16, num_blocks=2)
        >>> net(torch.zeros(4, 3), torch.zeros(4, 2)).shape
        torch.Size([4, 1])
    """

    def __init__(
        self,
        in_features: int,
        out_features: int,
        *,
        hidden: int = 256,
        num_blocks: int = 3,
        dropout: float = 0.0,
    ) -> None:
        super().__init__()
        _check_positive("in_features", in_features)
        _check_positive("out_features", out_features)
        _check_positive("hidden", hidden)
        if not isinstance(num_blocks, int) or num_blocks < 0:
            raise InvalidValueError(f"num_blocks must be a non-negative integer, got {num_blocks!r}.")
        self.in_features = in_features
        self.projection = AutocastLinear(in_features, hidden)
        self.blocks = nn.Sequential(*(ResidualBlock(hidden, dropout) for _ in range(num_blocks)))
        self.head = AutocastLinear(hidden, out_features)

    def forward(self, *inputs: torch.Tensor) -> torch.Tensor:
        features = sum(t.shape[-1] for t in inputs)
        if features != self.in_features:
            raise InvalidValueError(
                f"ResidualMLP expects {self.in_features} input features, got {features} (input shapes {[tuple(t.shape) for t in inputs]})."
            )
        collapsed = [_unbroadcast(t) for t in inputs] if len(inputs) > 1 else list(inputs)
        if any(c is not t for c, t in zip(collapsed, inputs)):
            # IQ-Learn's K policy samples per state arrive as an expanded state beside K
            # actions; projecting the state once makes that pass ~2x faster (355-dim window).
            x = _project_parts(self.projection, collapsed, inputs[0].shape[:-1])
        else:
            x = self.projection(_concat(inputs))
        # In the parameters' dtype: under a bf16 autocast (algo.precision=bf16) the matmuls
        # and activations are bf16, and the losses reading this output reduce in fp32.
        return self.head(self.blocks(x)).to(self.head.weight.dtype)


class SkipMLP(nn.Module):
    """Three-layer ReLU MLP with a skip connection around the middle layer (GAIL's discriminator).

    ``h1 = Dropout(ReLU(L1(x)))``, ``h2 = h1 + Dropout(ReLU(L2(h1)))``, ``out = L3(h2)``.

    Args:
        in_features (int): size of the (concatenated) input.
        out_features (int): size of the output.

    Keyword Args:
        hidden (int, optional): hidden width. Defaults to ``256``.
        dropout (float, optional): dropout after each hidden activation.
            Defaults to ``0.2`` (paper's discriminator).
        output_activation (type of nn.Module, optional): applied to the output,
            e.g. :class:`torch.nn.Sigmoid` for a probability. Defaults to ``None``.

    Examples:
        >>> import torch
        >>> net = SkipMLP(4, 1, hidden=8, output_activation=torch.nn.Sigmoid)
        >>> out = net(torch.zeros(2, 3), torch.zeros(2, 1))
        >>> out.shape, bool(((out > 0) & (out < 1)).all())
        (torch.Size([2, 1]), True)
    """

    def __init__(
        self,
        in_features: int,
        out_features: int,
        *,
        hidden: int = 256,
        dropout: float = 0.2,
        output_activation: type[nn.Module] | None = None,
    ) -> None:
        super().__init__()
        _check_positive("in_features", in_features)
        _check_positive("out_features", out_features)
        _check_positive("hidden", hidden)
        _check_dropout(dropout)
        self.input_layer = nn.Sequential(nn.Linear(in_features, hidden), nn.ReLU(), nn.Dropout(dropout))
        self.hidden_layer = nn.Sequential(nn.Linear(hidden, hidden), nn.ReLU(), nn.Dropout(dropout))
        self.head = nn.Linear(hidden, out_features)
        self.output_activation = nn.Identity() if output_activation is None else output_activation()

    def forward(self, *inputs: torch.Tensor) -> torch.Tensor:
        h = self.input_layer(_concat(inputs))
        return self.output_activation(self.head(h + self.hidden_layer(h)))
