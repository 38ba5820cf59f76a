"""Replay buffers of raw transitions, encoded at sampling time from each step's own episode.

A window encoding reads the ``k`` steps before the current one in the same episode. A
replay buffer samples rows that are, in general, not next to those steps, so encoding a
sample in place fills the lags from unrelated rows. :class:`EpisodeHistory` makes every
sampled step bring its ``k`` predecessors along, and :class:`EpisodeWindowEncoder` encodes
each sampled step from them; :meth:`CausalWindowTransform.make_rb_transform_and_sample_unit
<torchrl_causal.transforms.CausalWindowTransform.make_rb_transform_and_sample_unit>` builds
the pair.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any, cast

import torch
from tensordict import TensorDictBase, unravel_key
from tensordict.utils import NestedKey
from torchrl.data.replay_buffers import Sequence
from torchrl.data.replay_buffers.storages import Storage
from torchrl.envs import Transform

from torchrl_causal.errors import InvalidStateError, InvalidValueError, UnknownKeyError
from torchrl_causal.graphs.errors import check_window_size

if TYPE_CHECKING:
    from torchrl_causal.transforms.causal_window import CausalWindowTransform

__all__ = ["EpisodeHistory", "EpisodeWindowEncoder"]

#: Trajectory ids :class:`EpisodeHistory` looks for when given no ``traj_key``.
DEFAULT_TRAJ_KEYS: tuple[NestedKey, ...] = (("collector", "traj_ids"), "episode")


class EpisodeHistory(Sequence):
    """Expands every sampled step into the ``k`` steps before it in its episode, then itself.

    A TorchRL sample unit (``ReplayBuffer(sample_unit=...)``) that works with any anchor
    sampler (uniform, prioritized, slices): each sampled step becomes ``k + 1``
    consecutive stored records, the sampled step last. This is TorchRL's
    ``Sequence(length=1, burn_in=k)``: at an episode's start (the ``done_key`` of the
    previous record) the window repeats the episode's first record, which the stored
    ``init_key`` marks, so :class:`EpisodeWindowEncoder` zero-pads the lags that reach
    before it, exactly as the online transform does.

    Some steps cannot be encoded: those whose earlier steps the ring buffer has
    overwritten (the first ``< k`` steps after the oldest stored record, when that record
    is not an episode start), and those whose earlier steps are stored elsewhere
    (trajectories flattened side by side, e.g. ``collector_batch.reshape(-1)``), which the
    stored trajectory id (``traj_key``) reveals.
    Their windows are replaced by the window of the next encodable sampled step (with
    every per-record info entry), so the batch keeps its size; at most ``k`` records per
    write seam and per trajectory cut are affected. A batch with no encodable step raises.

    The storage must be a 1-D :class:`~torchrl.data.replay_buffers.TensorStorage` of
    TensorDicts whose trajectories are stored in time order (as ``extend`` writes whole
    episodes, consecutive batches of one env, or a demonstration dataset).

    Args:
        k: window size (steps before the sampled one).

    Keyword Args:
        init_key: the stored flag that is True at each episode's first step (TorchRL's
            :class:`~torchrl.envs.InitTracker`). Defaults to ``"is_init"``.
        traj_key: a stored trajectory id; records of another trajectory never count as
            a step's history. Defaults to the first of ``("collector", "traj_ids")`` (set
            by TorchRL collectors) and ``"episode"`` (set by
            :func:`~torchrl_causal.data.collect_demonstrations`) that the storage holds;
            without either, adjacent records are taken as consecutive steps up to an
            episode boundary.
        done_key: the stored end-of-episode flag. Defaults to ``("next", "done")``.

    Examples:
        >>> import torch
        >>> from tensordict import TensorDict
        >>> from torchrl.data import LazyTensorStorage
        >>> storage = LazyTensorStorage(8)
        >>> is_init, done = torch.zeros(8, 1, dtype=torch.bool), torch.zeros(8, 1, dtype=torch.bool)
        >>> is_init[[0, 3]] = True  # two episodes: records 0-2 and 3-7
        >>> done[[2, 7]] = True
        >>> storage.set(range(8), TensorDict({"is_init": is_init, ("next", "done"): done}, [8]))
        >>> index, info = EpisodeHistory(2).expand(torch.tensor([4, 7]), {}, storage)
        >>> index.reshape(2, 3).tolist()  # step 4 repeats its episode's first record 3
        [[3, 3, 4], [5, 6, 7]]
    """

    def __init__(
        self,
        k: int,
        *,
        init_key: NestedKey = "is_init",
        traj_key: NestedKey | None = None,
        done_key: NestedKey = ("next", "done"),
    ) -> None:
        check_window_size(k)
        super().__init__(length=1, episode_boundary="pad", done_key=unravel_key(done_key), burn_in=k)
        self.init_key = unravel_key(init_key)
        self.traj_key = None if traj_key is None else unravel_key(traj_key)

    @property
    def window_length(self) -> int:
        """The records per sampled step, ``k + 1``."""
        return self.burn_in + 1

    def expand(
        self, index: torch.Tensor | tuple[torch.Tensor], info: dict[str, Any], storage: Storage
    ) -> tuple[torch.Tensor, dict[str, Any]]:
        if getattr(storage, "ndim", 1) != 1:
            raise InvalidValueError(
                f"EpisodeHistory needs a 1-D storage, got {storage.ndim} dimensions: store transitions "
                "flattened in time order (e.g. batch.reshape(-1)) with their trajectory ids"
            )
        if isinstance(index, tuple):  # coordinates, as SliceSampler gives them: one per storage dim
            (index,) = index
        expanded, info = super().expand(index, info, storage)
        # On a 1-D storage (checked above) Sequence gives one tensor of record indices.
        index = cast(torch.Tensor, expanded)
        width = self.window_length
        windows = index.reshape(-1, width)
        # linked[b, j]: record j of window b is a genuine step of the sampled step's trajectory
        linked = info["validity_mask"].reshape(-1, width).clone()
        trajectory = self._trajectory_ids(storage, index.device)
        if trajectory is not None:
            trajectory = trajectory[windows]
            linked &= (trajectory == trajectory[:, -1:]).all(-1)
        positions = torch.arange(width, device=index.device)
        first = torch.where(linked, -1, positions).amax(1) + 1  # start of the unbroken run ending at the step
        starts = self._column(storage, self.init_key, index.device).any(-1)[windows]
        encodable = (first == 0) | starts.gather(1, first.unsqueeze(1)).squeeze(1)
        if bool(encodable.all()):
            return index, info
        good = encodable.nonzero().squeeze(-1)
        if not good.numel():
            raise InvalidStateError(
                f"none of the {len(encodable)} sampled steps has its {self.burn_in} previous steps in the storage "
                "(overwritten, or stored apart from them)"
            )
        following = torch.searchsorted(good, torch.arange(len(encodable), device=index.device)) % good.numel()
        records = (good[following].unsqueeze(1) * width + positions).reshape(-1)
        info = {key: value[records] if isinstance(value, torch.Tensor) and value.ndim else value for key, value in info.items()}
        return index[records], info

    def _trajectory_ids(self, storage: Storage, device: torch.device) -> torch.Tensor | None:
        if self.traj_key is not None:
            return self._column(storage, self.traj_key, device)
        for key in DEFAULT_TRAJ_KEYS:
            try:
                return self._column(storage, key, device)
            except KeyError:
                continue
        return None

    def _column(self, storage: Storage, key: NestedKey, device: torch.device) -> torch.Tensor:
        """``[len(storage), -1]``: one stored entry of every record."""
        try:
            column = storage.get(key)
        except KeyError:
            hint = " (True at each episode's first step: collect with torchrl.envs.InitTracker)" if key == self.init_key else ""
            raise UnknownKeyError(f"EpisodeHistory needs {key!r} in the stored transitions{hint}") from None
        return column.reshape(column.shape[0], -1).to(device)


class EpisodeWindowEncoder(Transform):
    """Encodes batches sampled with :class:`EpisodeHistory`: one row per sampled step.

    The replay-buffer counterpart of ``transform``: reads the ``[B * (k + 1)]`` records
    of ``B`` windows and returns the ``B`` sampled steps, each encoded from its own
    window by :meth:`~torchrl_causal.transforms.CausalWindowTransform.encode_trajectories`
    (so with exactly the values the online transform gives that step).

    Use it with :class:`~torchrl.data.ReplayBuffer`: its ``sample(return_info=True)``
    info holds one entry per window record, the sampled steps' being every
    ``(k + 1)``-th (``info["index"][k::k + 1]``). :class:`~torchrl.data.TensorDictReplayBuffer`
    writes that per-record info into the ``k + 1`` times smaller batch and fails.

    Args:
        transform: the :class:`~torchrl_causal.transforms.CausalWindowTransform` to apply.
    """

    def __init__(self, transform: CausalWindowTransform) -> None:
        super().__init__(in_keys=transform.in_keys, out_keys=transform.out_keys)
        self.transform = transform

    def forward(self, tensordict: TensorDictBase) -> TensorDictBase:
        width = self.transform.window.k + 1
        if tensordict.batch_dims != 1 or tensordict.numel() % width:
            raise InvalidValueError(
                f"expected a flat batch of windows of {width} records (sampled with EpisodeHistory({width - 1})), "
                f"got batch_size={list(tensordict.batch_size)}"
            )
        return self.transform.encode_trajectories(tensordict.reshape(-1, width))[:, -1]
