"""Demonstrations as Minari datasets: export ours, train from one (``pip install 'torchrl-causal[minari]'``).

A `Minari <https://minari.farama.org>`_ dataset stores episodes, each with ``T + 1``
observations and ``T`` actions, rewards, terminations and truncations. Exported from a
set of :mod:`~torchrl_causal.data.demonstrations`:

* ``observations`` is a ``Dict`` space holding every variable the env emits, in its
  TensorDict nesting: the admissible ones, the excluded collider, the ``"latent"`` ones
  and the confounder under ``"scm"`` (so a causal template can be applied again, or
  another adjustment chosen); a boolean variable is stored as ``uint8`` in ``[0, 1]``
  (Minari's and TorchRL's space converters know no boolean ``Box``);
* ``action_space`` is a ``Box`` of the env's real action bounds, read from its action spec
  (:func:`action_space`): ``[-1, 1]`` for the rover, the actuators' control ranges for the
  MuJoCo agents, ``[0, 1]`` for a binary action;
* the dataset metadata gets a ``"torchrl_causal"`` entry: the env config and regime the
  set was recorded in, the manifest (shape and dtype of every key) and the SHA-256
  checksum of :func:`~torchrl_causal.data.load_demonstrations`, so a Minari dataset is
  refused for the same reasons (wrong env, missing key, corrupted data).

Loading reads the episodes with Minari's reader (no network), lays them out as TorchRL's
:class:`~torchrl.data.datasets.MinariExperienceReplay` does (``("observation", <key>)``,
``("next", "observation", <key>)``; :func:`~torchrl_causal.data.minari_format.replay_layout`) and maps that back to ours
(:func:`from_minari_replay`, which takes ``MinariExperienceReplay``'s output alike).
A dataset made elsewhere can be loaded too when its metadata carries that entry (the
``"env"`` config and the ``"manifest"``; the ``"checksum"`` is verified when present).
"""

from __future__ import annotations

import json
import os
import shutil
import tempfile
import warnings
from collections.abc import Iterable, Iterator, Mapping
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import numpy as np
import torch
from hydra.utils import get_class
from tensordict import TensorDict, TensorDictBase
from torchrl.data import Categorical, OneHot, TensorSpec
from torchrl.envs import EnvBase

from torchrl_causal.data.demonstrations import (
    DatasetError,
    check_expected,
    check_manifest,
    dataset_checksum,
    env_expectation,
    load_demonstrations,
    read_metadata,
)
from torchrl_causal.errors import ExistingFileError, InvalidValueError
from torchrl_causal.extras import require_extra

__all__ = [
    "METADATA_KEY",
    "action_space",
    "export_minari",
    "from_minari_replay",
    "load_minari_demonstrations",
    "minari_dataset_dir",
    "read_minari_metadata",
    "replay_layout",
]

METADATA_KEY = "torchrl_causal"
# Keys of our layout that are not observations: Minari has a field for each, or they are
# rebuilt from the episode boundaries.
_STEP_KEYS = ("action", "done", "terminated", "truncated", "is_init", "episode")
_NEXT_ONLY_KEYS = ("reward", "done", "terminated", "truncated")


def _import_minari() -> Any:
    require_extra("Minari datasets", "h5py")  # Minari's HDF5 storage
    return require_extra("Minari datasets", "minari")


@contextmanager
def _datasets_path(root: Path) -> Iterator[None]:
    """Points Minari (which reads ``MINARI_DATASETS_PATH``) at ``root`` for the block."""
    previous = os.environ.get("MINARI_DATASETS_PATH")
    os.environ["MINARI_DATASETS_PATH"] = str(root)
    try:
        yield
    finally:
        if previous is None:
            os.environ.pop("MINARI_DATASETS_PATH", None)
        else:
            os.environ["MINARI_DATASETS_PATH"] = previous


def _default_root() -> Path:
    return Path(os.environ.get("MINARI_DATASETS_PATH", Path.home() / ".minari" / "datasets"))


def _space(value: torch.Tensor) -> Any:
    import gymnasium as gym

    shape = tuple(value.shape[1:])
    if value.dtype == torch.bool:
        return gym.spaces.Box(0, 1, shape=shape, dtype=np.uint8)
    if value.dtype.is_floating_point:
        return gym.spaces.Box(-np.inf, np.inf, shape=shape, dtype=np.float32 if value.dtype == torch.float32 else np.float64)
    info = np.iinfo(np.int64)
    return gym.spaces.Box(info.min, info.max, shape=shape, dtype=np.int64)


def action_space(spec: TensorSpec, action_shape: tuple[int, ...], dtype: torch.dtype) -> Any:
    """The gymnasium ``Box`` of the actions an env with action ``spec`` takes, for actions
    stored with ``action_shape`` (one step, batch dimensions left out) and ``dtype``.

    A bounded spec gives its bounds (the loosest over the env's batch), a categorical or
    binary one ``[0, n - 1]``, a one-hot one ``[0, 1]``, any other ``(-inf, inf)``; a boolean
    action is stored as ``uint8`` (as every boolean variable is).

    Raises:
        DatasetError: the spec's action shape is not ``action_shape``.

    Examples:
        >>> from torchrl.data import Binary, Bounded
        >>> action_space(Bounded(-2.0, 3.0, shape=(4, 2)), (2,), torch.float32)
        Box(-2.0, 3.0, (2,), float32)
        >>> action_space(Binary(n=1, shape=(4, 1), dtype=torch.float32), (1,), torch.float32)
        Box(0.0, 1.0, (1,), float32)
    """
    import gymnasium as gym

    if tuple(spec.shape[len(spec.shape) - len(action_shape) :]) != action_shape:
        raise DatasetError(f"the env's action spec has shape {tuple(spec.shape)}, the stored actions {action_shape} per step")
    numpy_dtype = np.uint8 if dtype == torch.bool else torch.empty((), dtype=dtype).numpy().dtype
    low = np.full(action_shape, -np.inf)
    high = np.full(action_shape, np.inf)
    space = spec.space
    if isinstance(spec, OneHot):
        low, high = np.zeros(action_shape), np.ones(action_shape)
    elif isinstance(spec, Categorical):  # Binary included
        low, high = np.zeros(action_shape), np.full(action_shape, float(space.n - 1))
    elif hasattr(space, "low") and hasattr(space, "high"):
        low = space.low.reshape(-1, *action_shape).amin(0).cpu().double().numpy()
        high = space.high.reshape(-1, *action_shape).amax(0).cpu().double().numpy()
    if not np.issubdtype(numpy_dtype, np.floating):
        info = np.iinfo(numpy_dtype)
        low, high = np.clip(low, info.min, info.max), np.clip(high, info.min, info.max)
    return gym.spaces.Box(low.astype(numpy_dtype), high.astype(numpy_dtype), shape=action_shape, dtype=numpy_dtype)


def _rebuilt_env(config: Mapping[str, Any]) -> EnvBase:
    """The env a set records, of batch size 1, by its class's ``from_config`` (every
    :class:`~torchrl_causal.envs.ConfoundedEnv` has one; the class is looked up by name, as
    this data layer sits below the envs)."""
    name = str(config.get("class", ""))
    try:
        from_config = getattr(get_class(name), "from_config", None)
    except (ImportError, ValueError, AttributeError):
        from_config = None
    if not callable(from_config):
        raise InvalidValueError(f"env class {name!r} is not importable or has no from_config")
    return from_config(config, batch_size=(1,))


def _recorded_action_space(metadata: Mapping[str, Any], action: torch.Tensor, env: EnvBase | None, dataset: Path) -> Any:
    """:func:`action_space` of ``env`` (checked to be the env the set records), or of the env
    rebuilt from the set's record when no ``env`` is given."""
    if env is not None:
        check_expected(metadata, env_expectation(env), "")
        return action_space(env.action_spec, tuple(action.shape[1:]), action.dtype)
    try:
        rebuilt = _rebuilt_env(metadata["env"])
    except (KeyError, TypeError, ValueError) as error:
        raise DatasetError(
            f"the env of {dataset} cannot be rebuilt from its record ({error}) to read its action bounds: "
            "pass env=<the env it was collected in>"
        ) from error
    try:
        return action_space(rebuilt.action_spec, tuple(action.shape[1:]), action.dtype)
    finally:
        rebuilt.close()


def _numpy(value: torch.Tensor) -> np.ndarray:
    return (value.to(torch.uint8) if value.dtype == torch.bool else value).cpu().numpy()


def _dict_space(data: TensorDictBase) -> Any:
    import gymnasium as gym

    return gym.spaces.Dict({key: _dict_space(value) if isinstance(value, TensorDictBase) else _space(value) for key, value in data.items()})


def _nested_numpy(data: TensorDictBase) -> dict[str, Any]:
    return {key: _nested_numpy(value) if isinstance(value, TensorDictBase) else _numpy(value) for key, value in data.items()}


def _observations(data: TensorDictBase) -> TensorDictBase:
    return data.exclude(*_STEP_KEYS, "next")


def _check_chained(observations: TensorDictBase, next_observations: TensorDictBase, episode: int) -> None:
    """Minari stores one observation per step plus the last one: that is only our data if
    each step's next observation is the following step's observation."""
    for key in observations.keys(include_nested=True, leaves_only=True):
        if not torch.equal(next_observations.get(key)[:-1], observations.get(key)[1:]):
            name = ".".join(key) if isinstance(key, tuple) else key
            raise DatasetError(
                f"episode {episode}: ('next', {name!r}) differs from the next step's {name!r}; "
                "Minari's one-observation-per-step layout cannot store it"
            )


def _episode_buffers(data: TensorDictBase) -> Iterator[Any]:
    from minari.data_collector import EpisodeBuffer

    observation_keys = set(_observations(data).keys(include_nested=True, leaves_only=True))
    next_keys = set(data.get("next").keys(include_nested=True, leaves_only=True))
    if extra := sorted(map(str, next_keys - observation_keys - set(_NEXT_ONLY_KEYS))):
        raise DatasetError(f"next-step keys {extra} have no current-step counterpart; Minari cannot store them")
    episode_index = data.get("episode")
    boundaries = torch.nonzero(torch.diff(episode_index)).flatten() + 1
    starts = [0, *boundaries.tolist()]
    ends = [*boundaries.tolist(), data.shape[0]]
    for number, (start, end) in enumerate(zip(starts, ends)):
        episode = data[start:end]
        observations = _observations(episode)
        next_observations = episode.get("next").select(*observations.keys(include_nested=True, leaves_only=True))
        _check_chained(observations, next_observations, number)
        chained = torch.cat([observations.to_tensordict(), next_observations[-1:].to_tensordict()], 0)
        yield EpisodeBuffer(
            id=number,
            observations=_nested_numpy(chained),
            actions=_numpy(episode.get("action")),
            rewards=episode.get(("next", "reward")).reshape(-1).cpu().numpy(),
            terminations=episode.get(("next", "terminated")).reshape(-1).cpu().numpy(),
            truncations=episode.get(("next", "truncated")).reshape(-1).cpu().numpy(),
            infos={},
        )


def export_minari(
    dataset: str | os.PathLike, dataset_id: str, *, root: str | os.PathLike | None = None, env: EnvBase | None = None
) -> Path:
    """Writes the demonstration set at ``dataset`` as the Minari dataset ``dataset_id``.

    Args:
        dataset: a directory written by :func:`~torchrl_causal.data.collect_demonstrations`
            (verified as :func:`~torchrl_causal.data.load_demonstrations` does).
        dataset_id: a Minari id, ``[namespace/]name-v<version>``, e.g. ``"causal/rovermaze-u-v0"``.
        root: the Minari datasets folder (default: ``$MINARI_DATASETS_PATH`` or
            ``~/.minari/datasets``, where ``minari.load_dataset`` looks).
        env: the env the set was collected in (its config is checked against the record),
            whose action spec gives the dataset's ``action_space``; by default the env is
            rebuilt from the set's record (its class's ``from_config``, e.g. :meth:`~torchrl_causal.envs.ConfoundedEnv.from_config`).

    Returns:
        The dataset's directory, ``<root>/<dataset_id>`` (what ``demos.source=minari:<path>`` takes).

    Raises:
        FileExistsError: a dataset with this id already exists under ``root``.
        DatasetError: ``env`` is not the env the set records, or no ``env`` is given and
            the recorded one cannot be rebuilt.

    Examples:
        >>> import tempfile
        >>> from torchrl_causal.data import collect_demonstrations
        >>> from torchrl_causal.envs import RoverMazeEnv
        >>> from torchrl_causal.experts import RoverExpert
        >>> env = RoverMazeEnv(maze="u", batch_size=(2,))
        >>> folder = Path(tempfile.mkdtemp())
        >>> ours = collect_demonstrations(env, RoverExpert(env), 2, folder / "ours", seed=0, progress=False)
        >>> exported = export_minari(folder / "ours", "causal/rovermaze-u-v0", root=folder / "minari")
        >>> import minari
        >>> with _datasets_path(folder / "minari"):
        ...     minari_set = minari.load_dataset("causal/rovermaze-u-v0")
        >>> minari_set.total_episodes, minari_set.total_steps == ours.shape[0]
        (2, True)
        >>> sorted(minari_set.observation_space.spaces)
        ['L', 'P', 'W', 'latent', 'scm', 'success']
        >>> minari_set.action_space  # the rover's throttle and turn, each in [-1, 1]
        Box(-1.0, 1.0, (2,), float32)
        >>> load_minari_demonstrations(exported, expected=env).shape == ours.shape
        True
    """
    minari = _import_minari()
    data = load_demonstrations(dataset)
    metadata = read_metadata(dataset)
    root = Path(root) if root is not None else _default_root()
    target = root / dataset_id
    if target.exists():
        raise ExistingFileError(f"a Minari dataset {dataset_id!r} already exists at {target}")
    minari.dataset.minari_dataset.parse_dataset_id(dataset_id)  # a malformed id fails before any work
    actions = _recorded_action_space(metadata, data.get("action"), env, Path(dataset))
    # Written in a staging folder and moved into place whole: an interrupted export leaves nothing at target.
    root.mkdir(parents=True, exist_ok=True)
    staging = Path(tempfile.mkdtemp(prefix=".minari-export.", dir=root))
    try:
        with _datasets_path(staging), warnings.catch_warnings():
            # Minari warns that no gymnasium env spec is recorded: these envs are TorchRL envs,
            # recorded by their config in the metadata instead.
            warnings.filterwarnings("ignore", category=UserWarning, module="minari")
            minari.create_dataset_from_buffers(
                dataset_id,
                list(_episode_buffers(data)),
                observation_space=_dict_space(_observations(data[:1])),
                action_space=actions,
                algorithm_name=str(metadata.get("policy")),
                author="torchrl-causal",
                author_email="n/a",
                code_permalink="https://github.com/pytorch/rl",
                description=f"torchrl-causal demonstrations: {json.dumps(metadata['env'], sort_keys=True)}",
            ).storage.update_metadata({METADATA_KEY: {k: v for k, v in metadata.items()}})
        target.parent.mkdir(parents=True, exist_ok=True)
        os.replace(staging / dataset_id, target)
    finally:
        shutil.rmtree(staging, ignore_errors=True)
    return target


def minari_dataset_dir(source: str | os.PathLike) -> Path:
    """The directory of a Minari dataset given by path or by id (under ``$MINARI_DATASETS_PATH``
    or ``~/.minari/datasets``).

    Raises:
        DatasetError: neither a path nor an id of a Minari dataset.
    """
    for candidate in (Path(source), _default_root() / str(source)):
        if (candidate / "data" / "metadata.json").is_file():
            return candidate
    raise DatasetError(
        f"no Minari dataset {str(source)!r}: neither a folder holding data/metadata.json nor an id "
        f"under {_default_root()} (set MINARI_DATASETS_PATH or give the path)"
    )


def read_minari_metadata(source: str | os.PathLike) -> dict[str, Any]:
    """The metadata of the Minari dataset at ``source`` (a path or an id), as written on disk."""
    file = minari_dataset_dir(source) / "data" / "metadata.json"
    try:
        return json.loads(file.read_text())
    except json.JSONDecodeError as error:
        raise DatasetError(f"{file} is corrupted: {error}") from error


def _ours(metadata: Mapping[str, Any], where: Path) -> dict[str, Any]:
    ours = metadata.get(METADATA_KEY)
    if not isinstance(ours, Mapping) or "env" not in ours or "manifest" not in ours:
        raise DatasetError(
            f"Minari dataset {where} has no {METADATA_KEY!r} metadata with the env config and manifest: "
            "export it with torchrl_causal.data.export_minari, or add that entry to its metadata"
        )
    return dict(ours)


def _tensors(value: Any, rows: slice) -> Any:
    if isinstance(value, Mapping):
        return {key: _tensors(item, rows) for key, item in value.items()}
    return torch.as_tensor(np.asarray(value)[rows])


def replay_layout(episodes: Iterable[Any]) -> TensorDict:
    """Minari episodes (``minari.EpisodeData``) as the transitions
    :class:`~torchrl.data.datasets.MinariExperienceReplay` lays them out: ``("observation", <key>)``
    and ``("next", "observation", <key>)`` from the ``T + 1`` observations, ``"action"``,
    ``("next", "reward" | "terminated" | "truncated" | "done")`` (``[T, 1]``) and ``"episode"``.

    TorchRL 0.14.1's ``MinariExperienceReplay`` fills its tensors in memory and then
    writes them with ``memmap_like``, which copies shapes, not contents: every value it
    returns is zero. Until that is fixed the episodes are read with Minari's own reader
    and laid out here (``tests/test_minari.py`` watches for the fix).
    """
    steps = []
    for episode in episodes:
        length = len(episode)
        terminated = torch.as_tensor(episode.terminations).reshape(length, 1).bool()
        truncated = torch.as_tensor(episode.truncations).reshape(length, 1).bool()
        steps.append(
            TensorDict(
                {
                    "observation": _tensors(episode.observations, slice(0, length)),
                    "action": _tensors(episode.actions, slice(0, length)),
                    "episode": torch.full((length,), int(episode.id), dtype=torch.int64),
                    "next": {
                        "observation": _tensors(episode.observations, slice(1, length + 1)),
                        "reward": torch.as_tensor(episode.rewards).reshape(length, 1),
                        "terminated": terminated,
                        "truncated": truncated,
                        "done": terminated | truncated,
                    },
                },
                batch_size=[length],
            )
        )
    if not steps:
        raise DatasetError("the Minari dataset holds no episode")
    return torch.cat(steps, 0)


def from_minari_replay(replay_data: TensorDictBase, metadata: Mapping[str, Any]) -> TensorDict:
    """Maps transitions read by :class:`~torchrl.data.datasets.MinariExperienceReplay` to our layout.

    Args:
        replay_data: every transition of the dataset, in order (``replay[:]``), with
            ``("observation", <key>)``, ``("next", "observation", <key>)``, ``"action"``,
            ``("next", "reward" | "terminated" | "truncated" | "done")`` and ``"episode"``.
        metadata: the ``"torchrl_causal"`` entry of the dataset metadata; its manifest
            gives each key's dtype (booleans come back from ``uint8``).

    Returns:
        The ``[N]`` TensorDict :func:`~torchrl_causal.data.load_demonstrations` would give.
    """
    observation = replay_data.get("observation")
    next_step = replay_data.get("next")
    out = observation.to_tensordict()
    out.set("action", replay_data.get("action"))
    out.set("next", next_step.get("observation").to_tensordict())
    for key in _NEXT_ONLY_KEYS:
        out.set(("next", key), next_step.get(key))
    episode = replay_data.get("episode").reshape(-1)
    is_init = torch.ones_like(episode, dtype=torch.bool)
    is_init[1:] = episode[1:] != episode[:-1]
    for key in ("done", "terminated", "truncated"):  # flags of a step that follows a step of its episode
        out.set(key, torch.zeros_like(next_step.get(key)))
    out.set("is_init", is_init.unsqueeze(-1))
    out.set("episode", episode.to(torch.int64))
    for name, entry in metadata["manifest"].items():
        nested = tuple(name.split("."))
        if nested in out.keys(include_nested=True, leaves_only=True):
            out.set(nested, out.get(nested).to(getattr(torch, entry["dtype"].removeprefix("torch."))))
    return out


def load_minari_demonstrations(
    source: str | os.PathLike,
    expected: Mapping[str, Any] | EnvBase | None = None,
    *,
    verify_checksum: bool = True,
) -> TensorDict:
    """Loads a Minari dataset (a path or an id), refusing it for the reasons
    :func:`~torchrl_causal.data.load_demonstrations` refuses ours.

    The episodes are read with Minari's own reader (``minari.MinariDataset(...).iterate_episodes()``,
    no network), laid out as TorchRL's ``MinariExperienceReplay`` lays them out
    (:func:`~torchrl_causal.data.minari_format.replay_layout`) and mapped to our layout (:func:`from_minari_replay`).
    ``MinariExperienceReplay`` itself is not used: in TorchRL 0.14.1 every value it returns
    is zero (see :func:`~torchrl_causal.data.minari_format.replay_layout`); ``from_minari_replay`` takes its output once fixed.

    Args:
        source: the dataset's directory, or its id under ``$MINARI_DATASETS_PATH`` /
            ``~/.minari/datasets``. Nothing is downloaded.
        expected: metadata fields the recorded ``"torchrl_causal"`` entry must have, or
            an env whose config (batch size aside) must be the recorded one.
        verify_checksum: recompute the checksum recorded at export (when there is one).

    Returns:
        The ``[N]`` TensorDict in our layout (in memory).

    Raises:
        DatasetError: no such dataset, no ``"torchrl_causal"`` metadata, an env config
            differing from ``expected``, a key of the manifest missing or of another
            shape/dtype, an unreadable (corrupted) file, or a checksum mismatch.
        ImportError: minari is not installed (naming the extra to install).
    """
    minari = _import_minari()
    directory = minari_dataset_dir(source)
    ours = _ours(read_minari_metadata(directory), directory)
    if isinstance(expected, EnvBase):
        expected = env_expectation(expected)
    if expected is not None:
        check_expected(ours, expected, "")
    try:
        dataset = minari.MinariDataset(directory / "data")
        data = from_minari_replay(replay_layout(dataset.iterate_episodes()), ours)
    except (OSError, RuntimeError, KeyError, ValueError, TypeError, AssertionError) as error:
        first_line = str(error).splitlines()[0] if str(error) else type(error).__name__
        raise DatasetError(f"Minari dataset {directory} cannot be read (corrupted or truncated?): {first_line}") from error
    check_manifest(data, ours["manifest"], directory)
    if verify_checksum and "checksum" in ours and dataset_checksum(data, ours) != ours["checksum"]:
        raise DatasetError(f"Minari dataset {directory} fails its checksum: its data or metadata were modified")
    return data
