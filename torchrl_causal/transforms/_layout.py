"""Where every (variable, lag) of an adjustment window lives in the encoded vector.

Shared by the online (per-step ring buffer) and offline (whole-trajectory) paths of
:class:`~torchrl_causal.transforms.CausalWindowTransform`, so both read the same columns
of the same per-step *frame* and cannot drift apart.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import NamedTuple

import torch
from torchrl.data import Binary, Categorical, MultiCategorical, MultiOneHot, OneHot, TensorSpec, Unbounded
from torchrl.data.tensor_specs import ContinuousBox

from torchrl_causal.errors import InvalidTypeError
from torchrl_causal.graphs.window import AdjustmentWindow

__all__ = ["FeatureSlice", "LagRing", "WindowLayout", "spec_bounds"]


class FeatureSlice(NamedTuple):
    """One block of the encoding: ``variable`` at ``lag`` steps back occupies ``columns``."""

    variable: str
    lag: int
    columns: slice


class WindowLayout:
    """Column bookkeeping for one window and one set of variable shapes.

    A *frame* is everything recorded about one time step, flattened: the admissible state
    variables (window order) then the action, ``frame_width`` columns in all. The
    encoding picks, for each feature column, one frame column at one lag.

    Args:
        window: the adjustment window.
        shapes: event shape (without batch dimensions) of every variable in
            ``window.lags``.
    """

    def __init__(self, window: AdjustmentWindow, shapes: Mapping[str, tuple[int, ...]]) -> None:
        self.window = window
        self.shapes = {var: tuple(int(s) for s in shapes[var]) for var in window.lags if window.lags[var]}
        widths = {var: math.prod(shape) for var, shape in self.shapes.items()}
        framed = [var for var in self.shapes if var != window.action]
        self.state_variables: tuple[str, ...] = tuple(framed)
        # vector-valued variables (the common case) concatenate without a reshape per step
        self.has_nonvector_state = any(len(self.shapes[var]) != 1 for var in framed)
        self.has_action = window.action in self.shapes
        if self.has_action:
            framed.append(window.action)
        self.vector_action = self.has_action and len(self.shapes[window.action]) == 1
        self.widths = widths
        self.frame_offsets: dict[str, int] = {}
        offset = 0
        for var in framed:
            self.frame_offsets[var] = offset
            offset += widths[var]
        self.frame_width = offset
        self.state_width = offset - (widths[window.action] if self.has_action else 0)

        self.features: list[FeatureSlice] = []
        lags: list[torch.Tensor] = []
        columns: list[torch.Tensor] = []
        start = 0
        for var in self.shapes:
            for lag in window.lags[var]:
                width = widths[var]
                self.features.append(FeatureSlice(var, lag, slice(start, start + width)))
                lags.append(torch.full((width,), lag, dtype=torch.long))
                first = self.frame_offsets[var]
                columns.append(torch.arange(first, first + width))
                start += width
        self.num_features = start
        self.feature_lag = torch.cat(lags) if lags else torch.zeros(0, dtype=torch.long)
        self.feature_column = torch.cat(columns) if columns else torch.zeros(0, dtype=torch.long)

    @property
    def num_slots(self) -> int:
        """Frames the online ring buffer keeps: the current step and ``k`` past ones."""
        return self.window.k + 1

    def ring_index(self, slot: int) -> torch.Tensor:
        """``[num_features]`` flat indices into a ``[k + 1, frame_width]`` ring whose current
        frame sits in ``slot``: the frame ``lag`` steps back sits in slot
        ``(slot - lag) mod (k + 1)``.

        One slot at a time: the table of every slot would hold ``(k + 1) x num_features``
        indices, quadratic in ``k`` (1 GB at ``k = 2000`` on AntMaze).
        """
        return (slot - self.feature_lag).remainder(self.num_slots) * self.frame_width + self.feature_column

    def bounds(self, variable_bounds: Mapping[str, tuple[torch.Tensor, torch.Tensor]]) -> tuple[torch.Tensor, torch.Tensor]:
        """Per-feature ``(low, high)`` (trailing dimension ``num_features``).

        ``variable_bounds[var]`` holds flattened bounds ``[..., width]`` (leading batch
        dimensions allowed). Features at lag >= 1 are zero before an episode has lasted
        that long (Algorithm 2's zero-padding), so their bounds are widened to hold 0.
        """
        lows, highs = [], []
        for feature in self.features:
            low, high = variable_bounds[feature.variable]
            if feature.lag > 0:
                low, high = low.clamp(max=0), high.clamp(min=0)
            lows.append(low)
            highs.append(high)
        return torch.cat(lows, -1), torch.cat(highs, -1)


class LagRing:
    """The last ``k + 1`` frames of every env of a batch, in one preallocated tensor.

    The current step sits in slot ``slot`` and the frame ``lag`` steps back in slot
    ``(slot - lag) mod (k + 1)``, so a step moves a pointer instead of the data. All envs
    of a batch step together, hence one pointer; a reset zeroes the rows of its envs.
    Per-slot views are built once so that the step path is a few ``copy_`` calls and one
    ``index_select``.

    Args:
        layout: the window layout.
        states: ``[*batch, state_width]`` first states of every env.
    """

    __slots__ = (
        "frames",
        "slot",
        "action_shape",
        "_num_slots",
        "_state_width",
        "_flat",
        "_states",
        "_actions",
        "_index",
        "_lag",
        "_column",
        "_frame_width",
    )

    def __init__(self, layout: WindowLayout, states: torch.Tensor) -> None:
        batch = states.shape[:-1]
        self.frames = states.new_zeros((*batch, layout.num_slots, layout.frame_width))
        self._num_slots = layout.num_slots
        self._state_width = layout.state_width
        self._flat = self.frames.flatten(-2)
        self._states = tuple(self.frames[..., s, : layout.state_width] for s in range(layout.num_slots))
        self._actions = tuple(self.frames[..., s, layout.state_width :] for s in range(layout.num_slots))
        # what ring_index(slot) reads, on the ring's device, so that a step copies nothing to it
        self._lag = layout.feature_lag.to(states.device)
        self._column = layout.feature_column.to(states.device)
        self._frame_width = layout.frame_width
        self._index = self._index_at(0)
        self.action_shape = self._actions[0].shape
        self.slot = 0
        self._states[0].copy_(states)

    def _index_at(self, slot: int) -> torch.Tensor:
        """:meth:`WindowLayout.ring_index` of ``slot``, on the ring's device."""
        return (slot - self._lag).remainder(self._num_slots) * self._frame_width + self._column

    @property
    def batch_size(self) -> torch.Size:
        return self.frames.shape[:-2]

    def reset(self, states: torch.Tensor, mask: torch.Tensor) -> None:
        """Starts a new episode in the envs selected by the boolean ``mask`` (batch-shaped)."""
        self.frames[mask] = 0
        self.frames[mask, self.slot, : self._state_width] = states[mask].to(self.frames.dtype)

    def restore(self, frames: torch.Tensor, slot: int) -> None:
        """Puts back saved ``frames`` and ``slot`` (a checkpointed episode in flight)."""
        self.frames.copy_(frames)
        self.slot = slot
        self._index = self._index_at(slot)

    def record_action(self, action: torch.Tensor) -> None:
        """Stores the action taken at the current step (``[*batch, action_width]``)."""
        self._actions[self.slot].copy_(action)

    def advance(self, states: torch.Tensor) -> None:
        """Moves to the next step, whose states are ``[*batch, state_width]``."""
        self.slot = (self.slot + 1) % self._num_slots
        self._index = self._index_at(self.slot)
        self._states[self.slot].copy_(states)

    def encode(self) -> torch.Tensor:
        """``[*batch, num_features]``: the current encoding."""
        return self._flat.index_select(-1, self._index)


def spec_bounds(spec: TensorSpec, batch_ndim: int, dtype: torch.dtype) -> tuple[torch.Tensor, torch.Tensor] | None:
    """Flattened ``(low, high)`` of a leaf spec as ``dtype`` (shape ``batch + (width,)``).

    Returns ``None`` for unbounded specs. Discrete specs give their integer range.
    """
    if isinstance(spec, Unbounded):
        return None
    shape, device = spec.shape, spec.device
    if isinstance(spec, (OneHot, MultiOneHot, Binary)):
        low, high = torch.zeros(shape, device=device), torch.ones(shape, device=device)
    elif isinstance(spec, MultiCategorical):
        low, high = torch.zeros(shape, device=device), (spec.nvec - 1).expand(shape)
    elif isinstance(spec, Categorical):
        low, high = torch.zeros(shape, device=device), torch.full(shape, spec.space.n - 1, device=device)
    elif isinstance(spec.space, ContinuousBox):
        low, high = spec.space.low.expand(shape), spec.space.high.expand(shape)
    else:
        raise InvalidTypeError(f"cannot derive bounds from a {type(spec).__name__} spec")
    batch = shape[:batch_ndim]
    return low.to(dtype).reshape(*batch, -1), high.to(dtype).reshape(*batch, -1)
