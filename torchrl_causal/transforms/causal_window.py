"""The causal adjustment window of Algorithm 2 as a TorchRL transform."""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any, Literal

import torch
from tensordict import TensorDictBase, unravel_key
from tensordict.utils import NestedKey
from torchrl.data import Bounded, Composite, TensorSpec, Unbounded
from torchrl.envs import EnvBase, Transform, TransformedEnv
from torchrl.envs.batched_envs import BatchedEnvBase

from torchrl_causal.compat import reset_mask
from torchrl_causal.errors import InvalidStateError, InvalidTypeError, InvalidValueError, MissingAttributeError, UnknownKeyError
from torchrl_causal.graphs.errors import WindowSizeError, check_window_size
from torchrl_causal.graphs.template import TimeSliceTemplate
from torchrl_causal.graphs.window import AdjustmentWindow
from torchrl_causal.transforms._layout import FeatureSlice, LagRing, WindowLayout, spec_bounds
from torchrl_causal.transforms.replay import EpisodeHistory, EpisodeWindowEncoder

__all__ = ["CausalWindowTransform", "causal_template", "imitator_window", "step_keys"]

#: Sub-tensordicts of a confounded env that no imitator may see: the variables latent to
#: the imitator, and the structural causal model's own (the confounder U).
LATENT_KEY = "latent"
CONFOUNDER_KEY = "scm"


class CausalWindowTransform(Transform):
    """Writes the windowed causal adjustment set of each step into one observation vector.

    This is the ``Encode(s, t)`` of the paper's Algorithms 2 and 3: at every reset and
    step, the values of every admissible variable of ``window`` at every lag the window
    names are concatenated into ``out_key``; lags that reach before the episode's first
    step are zero-padded.

    **What the imitator sees.** Everything it must not condition on is removed, from the
    env's outputs, its observation spec and encoded trajectories alike: the window's
    ``excluded`` observed keys (e.g. the compass ``"W"``), the ``"latent"``
    sub-tensordict (variables latent to the imitator) and the ``"scm"`` sub-tensordict
    (the confounder ``U`` and any other mechanism internals). What remains is
    ``out_key``, the admissible state variables' raw keys at the current step (values
    the encoding already holds at lag 0, kept for diagnostics such as the position
    trajectory and so that stored transitions can be encoded again), and the keys that
    are no variable of the window: ``"action"``, ``"reward"``, the done flags, the
    env's ``"success"`` and whatever other transforms add (e.g. ``"is_init"``).

    **Keys.** An admissible state variable ``v`` is the root key ``v``. The window's
    action variable is read from ``action_key``; its lags (always >= 1) come from the
    actions the transform has seen taken in the current episode.

    **Encoding order.** Variables in ``window.lags`` order (the template's order, the
    action last), and within a variable by increasing lag, lag 0 (the current step)
    first; each ``(variable, lag)`` block holds the variable's values flattened.
    :meth:`feature_layout` names the columns of every block.

    **State.** One ring buffer of the last ``k + 1`` frames per environment of the
    (arbitrarily shaped) batch, zeroed when an environment is reset; a partial reset
    (``"_reset"`` mask) clears only the environments it names. The window itself, the
    keys, the variable shapes and the ring buffer are saved in the module's state dict
    (:meth:`get_extra_state`), so a reloaded transform encodes identically and continues
    the episodes in flight, and loading the state of a different window raises.

    **Offline.** :meth:`encode_trajectories` encodes stored, time-ordered episodes (a
    demonstration dataset, a rollout) and gives exactly the tensors the transform
    produces online. A replay buffer's sample is not time-ordered: its rows' earlier
    steps are elsewhere in the storage, so calling the transform on a batch
    (:meth:`forward`, which is what a replay-buffer transform does) raises.
    :meth:`make_rb_transform_and_sample_unit` gives the replay-buffer transform and
    sample unit that encode every sampled step from its own episode's earlier steps.

    Args:
        window: the adjustment window to apply.

    Keyword Args:
        out_key: where the encoding is written. Defaults to ``"observation"``.
        action_key: the env key of the window's action variable. Defaults to
            ``"action"``.
        include_current: keep lag 0 (the current step) of the state variables. ``False``
            encodes only past steps, the paper's Algorithm 1 line 14 reading (lags
            ``1..k``). Defaults to ``True``.
        causal: ``False`` turns ``window`` into its non-causal twin: every observed
            variable, excluded ones such as ``W`` included, at the window's lags (the
            window-matched baseline). Defaults to ``True``.
        check_nan: raise, naming the variable, when the encoding contains a NaN (one
            reduction per step). Defaults to ``True``.
        chunk_size: rows encoded at once by :meth:`encode_trajectories`, bounding its
            temporary memory. Defaults to ``2048``.

    Examples:
        >>> import torch
        >>> from tensordict import TensorDict
        >>> from torchrl_causal.graphs import AdjustmentWindow
        >>> window = AdjustmentWindow(k=1, action="X", lags={"P": (0, 1), "X": (1,)},
        ...                           excluded=frozenset({"W"}), observed=("P", "W", "X"))
        >>> transform = CausalWindowTransform(window)
        >>> [(f.variable, f.lag, f.columns) for f in transform.feature_layout({"P": (1,), "X": (1,)})]
        [('P', 0, slice(0, 1, None)), ('P', 1, slice(1, 2, None)), ('X', 1, slice(2, 3, None))]
        >>> episode = TensorDict(  # one 3-step episode: P_t = t + 1, X_t = 10 (t + 1)
        ...     {"P": torch.tensor([[1.0], [2.0], [3.0]]), "W": torch.zeros(3, 1),
        ...      "action": torch.tensor([[10.0], [20.0], [30.0]]),
        ...      "is_init": torch.tensor([[True], [False], [False]]),
        ...      "next": {"P": torch.tensor([[2.0], [3.0], [4.0]]), "W": torch.zeros(3, 1)}},
        ...     batch_size=[3])
        >>> encoded = transform.encode_trajectories(episode)
        >>> encoded["observation"]  # [P_t, P_{t-1}, X_{t-1}], zero before the first step
        tensor([[ 1.,  0.,  0.],
                [ 2.,  1., 10.],
                [ 3.,  2., 20.]])
        >>> encoded["next", "observation"][-1]
        tensor([ 4.,  3., 30.])
        >>> "W" in encoded.keys()
        False

    In an environment (see :meth:`from_env`):

        >>> from torchrl.envs import TransformedEnv
        >>> from torchrl_causal.envs import RouteChoiceEnv
        >>> base = RouteChoiceEnv(batch_size=[4], seed=0)  # single-stage: horizon 1, so k = 0
        >>> env = TransformedEnv(base, CausalWindowTransform.from_env(base, k=0))
        >>> sorted(env.observation_spec.keys())  # W, ("latent", "O") and ("scm", "U") hidden
        ['Z', 'observation', 'success']
    """

    def __init__(
        self,
        window: AdjustmentWindow,
        *,
        out_key: NestedKey = "observation",
        action_key: NestedKey = "action",
        include_current: bool = True,
        causal: bool = True,
        check_nan: bool = True,
        chunk_size: int = 2048,
    ) -> None:
        if not isinstance(window, AdjustmentWindow):
            raise InvalidTypeError(f"window must be an AdjustmentWindow, got {type(window).__name__}")
        # The transform stores the window it applies (not the switches), so a reloaded
        # transform never depends on how they were set.
        if not causal:
            window = window.non_causal_twin()
        if not include_current:
            window = window.past_only()
        if window.observed:
            unobserved = [var for var in window.lags if var not in window.observed]
            if unobserved:
                raise InvalidValueError(f"window variables {unobserved} are not observed by the imitator {window.observed}")
        out_key = unravel_key(out_key)
        inadmissible = set(window.excluded) | {v for v in window.observed if v not in window.lags and v != window.action}
        hidden_keys = (LATENT_KEY, CONFOUNDER_KEY, *sorted(inadmissible))
        if out_key in window.lags or out_key in hidden_keys:
            raise InvalidValueError(f"out_key {out_key!r} would overwrite a variable of the window or a hidden key")
        if chunk_size < 1:
            raise InvalidValueError(f"chunk_size must be positive, got {chunk_size}")
        state_keys = [var for var, lags in window.lags.items() if lags and var != window.action]
        super().__init__(in_keys=state_keys, out_keys=[out_key])
        self.window = window
        self.out_key = out_key
        self.action_key = unravel_key(action_key)
        self.check_nan = check_nan
        self.chunk_size = chunk_size
        self.hidden_keys: tuple[NestedKey, ...] = hidden_keys
        self._layout: WindowLayout | None = None
        self._dtype: torch.dtype | None = None
        self._ring: LagRing | None = None

    # ------------------------------------------------------------------ construction

    @classmethod
    def from_env(
        cls,
        env: EnvBase,
        k: int,
        *,
        causal: bool = True,
        mode: Literal["exact", "relaxed"] = "relaxed",
        window_matched: bool = False,
        **kwargs: Any,
    ) -> CausalWindowTransform:
        """Builds the transform from ``env.causal_template``.

        Args:
            env: an env exposing ``causal_template`` (a
                :class:`~torchrl_causal.graphs.TimeSliceTemplate`), possibly wrapped in
                :class:`~torchrl.envs.TransformedEnv`, or a TorchRL batched env
                (:class:`~torchrl.envs.SerialEnv`, :class:`~torchrl.envs.ParallelEnv`)
                of such envs, started or not: the template is read from the first
                sub-env, and every other sub-env must have the same one.
            k: window size.
            causal: ``True`` applies :func:`~torchrl_causal.graphs.windowed_adjustment`
                (``mode`` as given); ``False`` gives a non-causal baseline that keeps
                every observed variable, W included.
            mode: ``"exact"`` or ``"relaxed"`` (causal windows only).
            window_matched: with ``causal=False``, stack every observed variable over the
                same lags a causal window of size ``k`` uses; otherwise the baseline is the
                paper's ``V^O_t`` (observed state at lag 0 and the previous action) and
                ``k`` only gets validated.
            **kwargs: forwarded to the constructor.

        Raises:
            WindowSizeError: ``k`` is not below the env's ``horizon`` (where the env has
                one; a batched env's shortest), before anything is built.
            ValueError: ``k`` is not an int >= 0.
        """
        template, horizon = _template_and_horizon(env)
        if horizon is not None and check_window_size(k) >= horizon:
            raise WindowSizeError(k, horizon)
        window = imitator_window(template, k, causal=causal, mode=mode, window_matched=window_matched)
        return cls(window, **kwargs)

    @classmethod
    def from_state_dict(cls, state_dict: Mapping[str, Any], prefix: str = "", **kwargs: Any) -> CausalWindowTransform:
        """Rebuilds a transform from a :meth:`state_dict` (e.g. a loaded checkpoint)."""
        try:
            state = state_dict[prefix + "_extra_state"]
        except KeyError:
            raise UnknownKeyError(f"no CausalWindowTransform state under {prefix + '_extra_state'!r}") from None
        transform = cls(
            AdjustmentWindow.from_dict(state["window"]),
            out_key=state["out_key"],
            action_key=state["action_key"],
            **kwargs,
        )
        transform.set_extra_state(state)
        return transform

    # ------------------------------------------------------------------ layout

    def feature_layout(self, shapes: Mapping[str, Sequence[int]] | None = None) -> list[FeatureSlice]:
        """The ``(variable, lag, columns)`` block of every part of the encoding, in order.

        Args:
            shapes: event shape of each window variable; defaults to the shapes learnt
                from the env's specs, the data or a loaded state dict.
        """
        if shapes is not None:
            return WindowLayout(self.window, {var: tuple(s) for var, s in shapes.items()}).features
        return self._require_layout().features

    def _require_layout(self) -> WindowLayout:
        if self._layout is None:
            if self.parent is None:
                raise InvalidStateError(
                    "the variable shapes are unknown: attach the transform to an env, encode data first, or pass shapes explicitly"
                )
            _, layout, _ = self._leaf_specs(self.parent.full_observation_spec, self.parent.full_action_spec)
            return layout
        return self._layout

    def _set_layout(self, shapes: Mapping[str, tuple[int, ...]], dtype: torch.dtype | None) -> WindowLayout:
        if self._layout is not None:
            for var, known in self._layout.shapes.items():
                if shapes[var] != known:
                    raise InvalidValueError(
                        f"shape mismatch for key {self._variable_key(var)!r}: this transform encodes "
                        f"events of shape {known}, got {shapes[var]}"
                    )
        if self._layout is None:
            self._layout = WindowLayout(self.window, shapes)
            self._ring = None
        if dtype is not None:
            self._dtype = dtype
        return self._layout

    def _variable_key(self, var: str) -> NestedKey:
        return self.action_key if var == self.window.action else var

    def _leaf_specs(self, observation_spec: Composite, action_spec: Composite) -> tuple[dict[str, TensorSpec], WindowLayout, torch.dtype]:
        """The spec of every encoded variable, validated; records (and returns) the layout and
        the encoding's dtype."""
        leaves: dict[str, TensorSpec] = {}
        for var, lags in self.window.lags.items():
            if not lags:
                continue
            key = self._variable_key(var)
            container, name = (action_spec, "action") if var == self.window.action else (observation_spec, "observation")
            if key not in container.keys(True, True):
                raise UnknownKeyError(
                    f"window variable {var!r} (key {key!r}) is missing from the env's {name} spec; "
                    f"available keys: {sorted(map(str, container.keys(True, True)))}"
                )
            leaves[var] = container[key]
        batch_ndim = observation_spec.ndim
        shapes = {var: tuple(spec.shape[batch_ndim:]) for var, spec in leaves.items()}
        dtype = _encoding_dtype(spec.dtype for spec in leaves.values())
        return leaves, self._set_layout(shapes, dtype), dtype

    # ------------------------------------------------------------------ specs

    def transform_observation_spec(self, observation_spec: Composite) -> Composite:
        leaves, layout, dtype = self._leaf_specs(observation_spec, self.parent.full_action_spec)
        batch = observation_spec.shape
        shape = (*batch, layout.num_features)
        bounds = {var: spec_bounds(spec, len(batch), dtype) for var, spec in leaves.items()}
        if all(b is None for b in bounds.values()):
            encoding_spec = Unbounded(shape=shape, dtype=dtype, device=observation_spec.device)
        else:
            filled: dict[str, tuple[torch.Tensor, torch.Tensor]] = {}
            for var, b in bounds.items():
                if b is None:
                    infinite = torch.full((*batch, layout.widths[var]), torch.inf, dtype=dtype, device=observation_spec.device)
                    b = (-infinite, infinite)
                filled[var] = b
            low, high = layout.bounds(filled)
            encoding_spec = Bounded(low=low, high=high, shape=shape, dtype=dtype, device=observation_spec.device)
        for key in self.hidden_keys:
            if key in observation_spec.keys():
                del observation_spec[key]
        observation_spec[self.out_key] = encoding_spec
        return observation_spec

    # ------------------------------------------------------------------ online

    @property
    def reset_key(self) -> NestedKey:
        reset_keys = self.parent.reset_keys
        if len(reset_keys) != 1:
            raise InvalidStateError(f"{type(self).__name__} supports envs with one reset key, got {reset_keys}")
        return reset_keys[0]

    def _reset(self, tensordict: TensorDictBase, tensordict_reset: TensorDictBase) -> TensorDictBase:
        layout = self._require_layout()
        batch = tensordict_reset.batch_size
        states = self._read_states(tensordict_reset, batch, layout)
        reset = reset_mask(self.reset_key, tensordict)
        ring = self._ring
        if ring is None or ring.batch_size != batch or bool(reset.all()):
            ring = self._ring = LagRing(layout, states.to(self._dtype))
        else:
            ring.reset(states, reset)
        tensordict_reset.set(self.out_key, self._encode(ring))
        return tensordict_reset.exclude(*self.hidden_keys, inplace=True)

    def _step(self, tensordict: TensorDictBase, next_tensordict: TensorDictBase) -> TensorDictBase:
        ring = self._ring
        if ring is None:
            raise InvalidStateError(f"{type(self).__name__}: reset the env before stepping it")
        layout = self._require_layout()
        batch = next_tensordict.batch_size
        if layout.has_action:
            action = tensordict.get(self.action_key, None)
            if action is None:
                raise UnknownKeyError(f"the action key {self.action_key!r} is missing from the step's input")
            if not layout.vector_action:
                action = action.reshape(*batch, -1)
            if action.shape != ring.action_shape:  # copy_ would broadcast a wrong shape silently
                self._raise_shape_error(tensordict, batch, (self.window.action,))
            ring.record_action(action)
        ring.advance(self._read_states(next_tensordict, batch, layout))
        next_tensordict.set(self.out_key, self._encode(ring))
        return next_tensordict.exclude(*self.hidden_keys, inplace=True)

    def _encode(self, ring: LagRing) -> torch.Tensor:
        encoding = ring.encode()
        if self.check_nan:
            self._check_nan(encoding)
        return encoding

    def _read_states(self, tensordict: TensorDictBase, batch: torch.Size, layout: WindowLayout) -> torch.Tensor:
        """``[*batch, state_width]``: the admissible state variables of one step, flattened."""
        try:
            values = [tensordict.get(var) for var in layout.state_variables]
            if layout.has_nonvector_state:
                values = [value.reshape(*batch, -1) for value in values]
            states = torch.cat(values, -1) if len(values) != 1 else values[0]
        except KeyError:
            missing = [var for var in layout.state_variables if var not in tensordict.keys()]
            raise UnknownKeyError(f"admissible keys {missing} are missing from the env's output") from None
        except RuntimeError:  # torch.cat of mismatched shapes
            self._raise_shape_error(tensordict, batch, layout.state_variables)
        if states.shape[-1] != layout.state_width:
            self._raise_shape_error(tensordict, batch, layout.state_variables)
        return states

    def _raise_shape_error(self, tensordict: TensorDictBase, batch: torch.Size, variables: Sequence[str]) -> None:
        for var in variables:
            key = self._variable_key(var)
            expected = (*batch, *self._require_layout().shapes[var])
            got = tuple(tensordict.get(key).shape)
            if got != expected:
                raise InvalidValueError(f"shape mismatch for key {key!r}: expected {expected}, got {got}")
        raise InvalidStateError(f"could not encode {list(variables)} from {tensordict}")

    def _check_frames_nan(self, frames: torch.Tensor, layout: WindowLayout) -> None:
        nan_columns = torch.isnan(frames).any(0).nonzero()
        if nan_columns.numel():
            column = int(nan_columns[0])
            var = next(v for v, offset in layout.frame_offsets.items() if offset <= column < offset + layout.widths[v])
            raise InvalidValueError(
                f"NaN in admissible key {self._variable_key(var)!r}; refusing to encode it for the policy "
                "(check_nan=False disables this check)"
            )

    def _check_nan(self, encoding: torch.Tensor) -> None:
        # One reduction per step: a NaN makes the sum NaN (so does inf - inf, hence the
        # exact look that follows before raising).
        if not math.isnan(encoding.sum()):
            return
        nan_columns = torch.isnan(encoding).reshape(-1, encoding.shape[-1]).any(0).nonzero()
        if not nan_columns.numel():
            return
        column = int(nan_columns[0])
        feature = next(f for f in self._require_layout().features if f.columns.start <= column < f.columns.stop)
        raise InvalidValueError(
            f"NaN in admissible key {self._variable_key(feature.variable)!r} at lag {feature.lag}; "
            "refusing to feed it to the policy (check_nan=False disables this check)"
        )

    # ------------------------------------------------------------------ offline

    def forward(self, tensordict: TensorDictBase) -> TensorDictBase:
        """Refuses to encode a batch whose time order it cannot know.

        A module call (what a replay buffer or ``Compose`` does with its transforms) gets
        rows without their episodes: a replay buffer's random rows, or slices whose first
        steps lack their earlier steps, would have their lags filled from unrelated rows.

        Raises:
            RuntimeError: always, naming the two correct uses.
        """
        raise InvalidStateError(
            f"{type(self).__name__} cannot encode a batch of rows on its own: a step's lags need its "
            "episode's earlier steps. For stored, time-ordered episodes call encode_trajectories(data); in "
            "a replay buffer use the transform and sample unit of make_rb_transform_and_sample_unit()"
        )

    def make_rb_transform_and_sample_unit(self, *, traj_key: NestedKey | None = None) -> tuple[EpisodeWindowEncoder, EpisodeHistory]:
        """A replay-buffer transform and sample unit that encode each sampled step correctly.

        Store raw transitions (the admissible keys, ``action_key``, ``"is_init"`` and
        ``("next", "done")``, as a demonstration dataset or an InitTracker'd collector
        gives them) in a :class:`~torchrl.data.ReplayBuffer` built with both: every
        sampled step brings its episode's ``k`` earlier steps along
        (:class:`~torchrl_causal.transforms.EpisodeHistory`) and is encoded from them
        (:class:`~torchrl_causal.transforms.EpisodeWindowEncoder`), with exactly the
        values the online transform gives it. Any anchor sampler works.

        Args:
            traj_key: the stored trajectory id that tells where each trajectory's
                earlier steps are when the storage holds pieces of trajectories side by
                side (a flattened ``[B, T]`` collector batch). Defaults to
                ``("collector", "traj_ids")`` or ``"episode"`` when stored; see
                :class:`~torchrl_causal.transforms.EpisodeHistory`.

        Examples:
            >>> from tensordict import TensorDict
            >>> from torchrl.data import LazyTensorStorage, ReplayBuffer
            >>> from torchrl_causal.graphs import AdjustmentWindow
            >>> window = AdjustmentWindow(k=1, action="X", lags={"P": (0, 1), "X": (1,)})
            >>> transform, unit = CausalWindowTransform(window).make_rb_transform_and_sample_unit()
            >>> buffer = ReplayBuffer(storage=LazyTensorStorage(10), sample_unit=unit, transform=transform)
            >>> P = torch.arange(1.0, 7.0).unsqueeze(-1)  # two 3-step episodes: P = 1, 2, 3 and 4, 5, 6
            >>> buffer.extend(TensorDict(
            ...     {"P": P, "action": 10 * P, "is_init": (P - 1) % 3 == 0,
            ...      "next": {"P": P + 1, "done": P % 3 == 0}}, [6]))
            tensor([0, 1, 2, 3, 4, 5])
            >>> batch = buffer.sample(8)
            >>> bool((batch["observation"] == torch.cat(  # [P_t, P_{t-1}, X_{t-1}] within each episode
            ...     [batch["P"], torch.where(batch["is_init"], 0, batch["P"] - 1),
            ...      torch.where(batch["is_init"], 0, 10 * (batch["P"] - 1))], -1)).all())
            True
        """
        return EpisodeWindowEncoder(self), EpisodeHistory(self.window.k, traj_key=traj_key)

    def encode_trajectories(self, trajectories: TensorDictBase, *, keys: Sequence[NestedKey] | None = None) -> TensorDictBase:
        """Encodes stored, time-ordered transitions exactly as the online transform would.

        Args:
            trajectories: a TensorDict of shape ``[N]`` (episodes concatenated in time
                order, the dataset contract) or ``[*B, T]`` (time last, e.g. a batched
                rollout; each row's first step starts an episode). It needs the
                admissible keys and ``action_key`` at the root, the admissible keys under
                ``"next"``, and either ``"is_init"`` (True at each episode's first step,
                TorchRL's ``InitTracker`` convention) or ``("next", "done")``.

        Keyword Args:
            keys: keep exactly these keys of the encoding (:func:`step_keys` of the
                transformed env gives what its collector stores), so that it extends the
                same replay buffer as, or concatenates with, collector batches. Defaults
                to every key left (the dataset's own, such as ``"is_init"`` and
                ``"episode"``, included).

        Returns:
            A new TensorDict with ``out_key`` and ``("next", out_key)`` written and the
            hidden keys (``excluded`` and ``"latent"``) removed at both levels. Step
            ``t`` of an episode reads rows ``t - lag`` of the same episode (zero before
            its start), gathered for all rows at once in chunks of ``chunk_size``.

        Raises:
            KeyError: a key of ``keys`` that the encoding lacks, named.
        """
        if trajectories.batch_dims == 0:
            raise InvalidValueError("encode_trajectories needs a time dimension, got a TensorDict with batch_size=[]")
        shape = trajectories.batch_size
        flat = trajectories.reshape(-1)
        layout = self._layout_from_data(flat)
        steps = self._episode_steps(flat, shape[-1] if len(shape) > 1 else None)
        frames = self._padded_frames(flat, layout)
        next_states = self._read_states(flat.get("next"), flat.batch_size, layout)

        if self.check_nan:
            self._check_frames_nan(frames, layout)
            self._check_frames_nan(next_states, layout)
        k, width = self.window.k, layout.frame_width
        lag, column = layout.feature_lag, layout.feature_column
        # Row i of `windows` (below) is frames i-k..i flattened, oldest first: the frame
        # `lag` steps back starts at (k - lag) * width. At t + 1 the frame `lag` steps back
        # is one row later; its lag-0 columns are the next states, copied in afterwards.
        position = (k - lag) * width + column
        next_position = (k - (lag - 1).clamp(min=0)) * width + column
        n = flat.numel()
        # zero-filled up front: first-touch page faults cost far more inside the gather
        encoding = frames.new_zeros((n, layout.num_features))
        next_encoding = frames.new_zeros((n, layout.num_features))
        for start in range(0, n, self.chunk_size):
            stop = min(start + self.chunk_size, n)
            windows = frames.view(-1)[start * width :].as_strided((stop - start, (k + 1) * width), (width, 1))
            torch.index_select(windows, 1, position, out=encoding[start:stop])
            torch.index_select(windows, 1, next_position, out=next_encoding[start:stop])
            # Only the first k steps of an episode reach back before its start: zero-pad those.
            early = (steps[start:stop] < k).nonzero().squeeze(-1) + start
            if early.numel():
                step = steps[early, None]
                encoding[early] = encoding[early].masked_fill_(step < lag, 0)
                next_encoding[early] = next_encoding[early].masked_fill_(step < lag - 1, 0)
        for feature in layout.features:
            if feature.lag == 0:
                first = layout.frame_offsets[feature.variable]
                next_encoding[:, feature.columns] = next_states[:, first : first + layout.widths[feature.variable]]

        hidden = [*self.hidden_keys, *(("next", key) for key in self.hidden_keys)]
        out = trajectories.exclude(*hidden)
        out.set(self.out_key, encoding.reshape(*shape, -1))
        out.set(("next", self.out_key), next_encoding.reshape(*shape, -1))
        if keys is None:
            return out
        missing = [key for key in keys if key not in out.keys(True, True)]
        if missing:
            raise UnknownKeyError(f"the encoded trajectories lack {missing}: the stored data does not record them")
        return out.select(*keys)

    def _layout_from_data(self, flat: TensorDictBase) -> WindowLayout:
        leaves = {}
        for var, lags in self.window.lags.items():
            if not lags:
                continue
            key = self._variable_key(var)
            value = flat.get(key, None)
            if value is None:
                raise UnknownKeyError(f"window variable {var!r} (key {key!r}) is missing from the trajectories")
            leaves[var] = value
        shapes = {var: tuple(value.shape[1:]) for var, value in leaves.items()}
        dtype = self._dtype or _encoding_dtype(value.dtype for value in leaves.values())
        return self._set_layout(shapes, dtype)

    def _episode_steps(self, flat: TensorDictBase, row_length: int | None) -> torch.Tensor:
        """``[N]`` index of each row within its episode."""
        n = flat.numel()
        is_init = flat.get("is_init", None)
        if is_init is not None:
            starts = is_init.reshape(n, -1).any(-1)
        else:
            done = flat.get(("next", "done"), None)
            if done is None:
                raise UnknownKeyError("trajectories need 'is_init' or ('next', 'done') to delimit episodes")
            starts = torch.cat([done.new_ones(1), done.reshape(n, -1).any(-1)[:-1]])
        index = torch.arange(n, device=starts.device)
        if row_length is not None:
            starts = starts | (index % row_length == 0)
        starts[0] = True
        return index - torch.cummax(torch.where(starts, index, 0), 0).values

    def _padded_frames(self, flat: TensorDictBase, layout: WindowLayout) -> torch.Tensor:
        """``[k + N, frame_width]``: every row's frame after ``k`` zero rows."""
        k, n = self.window.k, flat.numel()
        states = self._read_states(flat, flat.batch_size, layout)
        frames = torch.zeros((k + n, layout.frame_width), dtype=self._dtype, device=states.device)
        frames[k:, : layout.state_width] = states
        if layout.has_action:
            action = flat.get(self.action_key)
            try:
                frames[k:, layout.state_width :] = action.reshape(n, -1)
            except RuntimeError:
                self._raise_shape_error(flat, flat.batch_size, (self.window.action,))
        return frames

    # ------------------------------------------------------------------ serialisation

    def get_extra_state(self) -> dict[str, Any]:
        return {
            "window": self.window.to_dict(),
            "out_key": self.out_key,
            "action_key": self.action_key,
            "shapes": None if self._layout is None else {var: list(s) for var, s in self._layout.shapes.items()},
            # The lag buffers, so that a restored env continues its episodes (resume).
            "ring": None if self._ring is None else {"frames": self._ring.frames.clone(), "slot": self._ring.slot},
        }

    def set_extra_state(self, state: Mapping[str, Any]) -> None:
        saved = state["window"]
        mine = self.window.to_dict()
        differing = sorted(field for field in mine if mine[field] != saved.get(field))
        if differing or list(saved["lags"]) != list(mine["lags"]):
            raise InvalidValueError(
                f"the saved state encodes a different adjustment window (fields {differing or ['lags order']} "
                f"differ): saved {saved}, this transform {mine}; rebuild it with "
                "CausalWindowTransform.from_state_dict"
            )
        for name in ("out_key", "action_key"):
            if unravel_key(state[name]) != getattr(self, name):
                raise InvalidValueError(f"the saved state has {name}={state[name]!r}, this transform {getattr(self, name)!r}")
        if state.get("shapes") is not None:
            self._set_layout({var: tuple(s) for var, s in state["shapes"].items()}, None)
        if state.get("ring") is not None:
            frames = state["ring"]["frames"]
            layout = self._require_layout()
            self._ring = LagRing(layout, frames.new_zeros((*frames.shape[:-2], layout.state_width)))
            self._ring.restore(frames, int(state["ring"]["slot"]))

    def __repr__(self) -> str:
        lags = ", ".join(f"{var}@{list(lags)}" for var, lags in self.window.lags.items())
        return f"{type(self).__name__}(k={self.window.k}, lags=[{lags}], hidden={list(self.hidden_keys)}, out_key={self.out_key!r})"


def step_keys(env: EnvBase) -> list[NestedKey]:
    """The keys of every step a collector of ``env`` stores, its own ``("collector", ...)``
    bookkeeping aside: observations, actions and done flags at the root, observations,
    rewards and done flags under ``"next"``.

    With :meth:`CausalWindowTransform.encode_trajectories` (``keys=step_keys(env)``)
    demonstrations become transitions of exactly a collector batch's keys.

    Examples:
        >>> from torchrl.envs import TransformedEnv
        >>> from torchrl_causal.envs import RouteChoiceEnv
        >>> base = RouteChoiceEnv(batch_size=[2], seed=0)
        >>> env = TransformedEnv(base, CausalWindowTransform.from_env(base, k=0))
        >>> keys = step_keys(env)
        >>> sorted(map(str, keys)) == sorted(map(str, env.rollout(1).keys(True, True)))
        True
    """
    observations = list(env.full_observation_spec.keys(True, True))
    done = list(env.full_done_spec.keys(True, True))
    root = [*observations, *env.full_action_spec.keys(True, True), *done]
    following = [*observations, *env.full_reward_spec.keys(True, True), *done]
    return [unravel_key(key) for key in root] + [unravel_key(("next", key)) for key in following]


def imitator_window(
    template: TimeSliceTemplate,
    k: int,
    *,
    causal: bool = True,
    mode: Literal["exact", "relaxed"] = "relaxed",
    window_matched: bool = False,
) -> AdjustmentWindow:
    """The window an imitator conditions on, from a template alone (no env built).

    ``causal=True`` is the paper's windowed sequential π-backdoor adjustment
    (:func:`~torchrl_causal.graphs.windowed_adjustment`, Algorithm 1); ``causal=False`` the
    non-causal baseline, every observed variable (W included) at lag 0 and the previous
    action, or over the causal window's lags with ``window_matched``
    (:func:`~torchrl_causal.graphs.observation_window`). The arguments are those of
    :meth:`CausalWindowTransform.from_env`.

    Examples:
        >>> from torchrl_causal.envs import RouteChoiceEnv
        >>> imitator_window(RouteChoiceEnv.slice_template(), 0).lags  # Z is safe, W is not
        {'Z': (0,)}
        >>> sorted(imitator_window(RouteChoiceEnv.slice_template(), 0, causal=False).lags)  # and the previous action
        ['W', 'X', 'Z']
    """
    check_window_size(k)
    from torchrl_causal.graphs import observation_window, windowed_adjustment

    if causal:
        if window_matched:
            raise InvalidValueError("window_matched=True only applies to the non-causal baseline (causal=False)")
        return windowed_adjustment(template, k, mode=mode)
    return observation_window(template, k if window_matched else None)


def causal_template(env: EnvBase) -> TimeSliceTemplate:
    """The causal template of ``env``, of its base env, or of every sub-env of a batched env.

    A :class:`~torchrl.envs.TransformedEnv` is unwrapped to its base env. A batched env
    (:class:`~torchrl.envs.BatchedEnvBase`) that is running is asked for its sub-envs'
    templates; one that is closed or not started yet is not started for this: each
    distinct ``(create_env_fn, create_env_kwargs)`` pair builds one env, whose template is
    read before it is closed. All sub-envs must share the first one's template.

    Raises:
        AttributeError: if an env exposes no ``causal_template``.
        ValueError: if the sub-envs of a batched env disagree on it.

    Examples:
        >>> from torchrl.envs import SerialEnv
        >>> from torchrl_causal.envs import RouteChoiceEnv
        >>> causal_template(SerialEnv(2, RouteChoiceEnv)) == RouteChoiceEnv().causal_template
        True
    """
    return _template_and_horizon(env)[0]


def _as_horizon(value: object) -> int | None:
    return value if isinstance(value, int) and not isinstance(value, bool) else None


def _template_and_horizon(env: EnvBase) -> tuple[TimeSliceTemplate, int | None]:
    """:func:`causal_template` and the shortest horizon of the (sub-)envs, None where no env
    says its horizon."""
    while isinstance(env, TransformedEnv):
        env = env.base_env
    if not isinstance(env, BatchedEnvBase):
        template = getattr(env, "causal_template", None)
        if template is None:
            raise MissingAttributeError(f"{type(env).__name__} exposes no causal_template to build a window from")
        return template, _as_horizon(getattr(env, "horizon", None))
    if env.is_closed:
        facts = _unstarted_sub_env_facts(env)
    else:
        try:
            templates = list(env.causal_template)
        except AttributeError:
            raise MissingAttributeError(f"the sub-envs of {type(env).__name__} expose no causal_template to build a window from") from None
        # The horizon is not asked of running workers: a ParallelEnv worker whose env lacks the
        # attribute dies on the query (its pipe breaks) instead of answering AttributeError; the
        # k < horizon check is made where the envs are built (unstarted envs, the configs).
        facts = [(template, None) for template in templates]
    templates = [template for template, _ in facts]
    for index, template in enumerate(templates[1:], 1):
        if template != templates[0]:
            raise InvalidValueError(
                f"sub-env {index} of {type(env).__name__} has another causal template than sub-env 0: {template} != {templates[0]}"
            )
    known = [h for _, h in facts if h is not None]
    return templates[0], min(known) if known else None


def _unstarted_sub_env_facts(env: BatchedEnvBase) -> list[tuple[TimeSliceTemplate, int | None]]:
    """The template and horizon of every sub-env of a batched env that is not running, one
    env built per distinct constructor."""
    built: list[tuple[Any, Mapping[str, Any], tuple[TimeSliceTemplate, int | None]]] = []
    facts = []
    for make, kwargs in zip(env.create_env_fn, env.create_env_kwargs):
        fact = next((f for m, kw, f in built if m is make and kw == kwargs), None)
        if fact is None:
            sub_env = make(**kwargs)
            try:
                fact = _template_and_horizon(sub_env)
            finally:
                sub_env.close()
            built.append((make, kwargs, fact))
        facts.append(fact)
    return facts


def _encoding_dtype(dtypes) -> torch.dtype:
    """The common dtype of the encoded variables, floating point (actions may be integers)."""
    result = None
    for dtype in dtypes:
        result = dtype if result is None else torch.promote_types(result, dtype)
    if result is None or not result.is_floating_point:
        return torch.get_default_dtype()
    return result
