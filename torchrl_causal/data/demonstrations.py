"""Expert demonstrations on disk: collection, atomic memory-mapped storage, verified loading.

A dataset is a directory holding

* ``data/``: a memory-mapped TensorDict (:meth:`tensordict.TensorDict.memmap`) of shape
  ``[N]``: the time-ordered transitions of every episode, concatenated, with every env key
  (latent and ``scm`` ones included), a ``"next"`` sub-TensorDict as TorchRL rollouts
  produce, ``"is_init"`` (bool ``[N, 1]``, True at each episode's first step) and
  ``"episode"`` (int64 ``[N]``);
* ``metadata.json``: the format version, the env config (class, maze, horizon, strength,
  regime...), the seed, the policy that collected it (:func:`policy_record`: its class, its
  settings and a digest of its weights), the number of episodes and transitions, the
  expert's success rate and mean episode length, a manifest (shape and dtype of every key) and a SHA-256
  checksum over the data and the rest of the metadata.

Collection writes into a hidden temporary directory next to ``path`` and renames it into
place only once complete, so an interrupted collection leaves nothing at ``path``.
"""

from __future__ import annotations

import hashlib
import importlib
import json
import math
import os
import shutil
import tempfile
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any, cast

import torch
from tensordict import TensorDict, TensorDictBase
from tensordict.utils import NestedKey
from torchrl.envs import EnvBase

from torchrl_causal.errors import ExistingFileError, InvalidValueError, TorchRLCausalError
from torchrl_causal.progress import progress as progress_reporter

__all__ = [
    "FORMAT_VERSION",
    "DatasetError",
    "check_expected",
    "tensor_bytes",
    "check_manifest",
    "dataset_checksum",
    "env_config",
    "env_expectation",
    "collect_demonstrations",
    "current_class_path",
    "load_demonstrations",
    "policy_record",
    "read_metadata",
    "successful_episodes",
]

FORMAT_VERSION = 1
_DATA_DIR = "data"
_METADATA_FILE = "metadata.json"


class DatasetError(TorchRLCausalError, ValueError):
    """A demonstration dataset is missing, corrupted or not the one that was expected."""


def _key_name(key: NestedKey) -> str:
    return ".".join(key) if isinstance(key, tuple) else key


def _leaves(data: TensorDictBase) -> list[tuple[str, torch.Tensor]]:
    return sorted((_key_name(key), data.get(key)) for key in data.keys(include_nested=True, leaves_only=True))


def _manifest(data: TensorDictBase) -> dict[str, dict[str, Any]]:
    return {name: {"shape": list(value.shape), "dtype": str(value.dtype)} for name, value in _leaves(data)}


def dataset_checksum(data: TensorDictBase, metadata: Mapping[str, Any]) -> str:
    """SHA-256 over ``metadata`` (its ``"checksum"`` field aside) and every leaf of ``data``, by key."""
    digest = hashlib.sha256()
    digest.update(json.dumps({k: v for k, v in metadata.items() if k != "checksum"}, sort_keys=True).encode())
    for name, value in _leaves(data):
        digest.update(name.encode())
        digest.update(tensor_bytes(value))
    return digest.hexdigest()


def tensor_bytes(value: torch.Tensor) -> bytes:
    """The bytes of ``value``'s elements in row-major order, for digests: any shape (0-d and
    empty tensors included), any layout (a broadcast or transposed view gives its elements' bytes).

    Examples:
        >>> tensor_bytes(torch.tensor(1.0)) == tensor_bytes(torch.tensor([1.0])), tensor_bytes(torch.zeros(0))
        (True, b'')
    """
    # Flattened into a fresh row-major copy first: ``view(torch.uint8)`` refuses a 0-d tensor (the
    # humanoid skill's ``command_frame`` buffer) and a zero stride (an empty or broadcast tensor);
    # every other tensor's bytes stay as they were, so the digests already recorded still match.
    # (``contiguous()`` and ``clone()`` keep a size-1 dimension's zero stride: a fresh tensor does not).
    flat = torch.empty(value.numel(), dtype=value.dtype).copy_(value.detach().cpu().reshape(-1))
    return flat.view(torch.uint8).numpy().tobytes() if flat.numel() else b""


def policy_record(policy: Callable[[TensorDictBase], TensorDictBase]) -> dict[str, Any]:
    """What a dataset records of the policy that collected it, and what a run compares before
    it reuses a set: ``"policy"`` (its class), ``"policy_settings"`` (the public ``settings``
    mapping the experts keep: planner clearance, action noise...; empty where a policy has
    none) and ``"policy_weights"`` (a SHA-256 over its parameters and buffers by name, ``None``
    for a policy that is not a :class:`torch.nn.Module`).

    The weights matter as much as the class: a retrained skill shipped under the same expert
    class walks another path, and its old demonstrations must not be reused silently.

    Examples:
        >>> from torchrl_causal.envs import RoverMazeEnv
        >>> from torchrl_causal.experts import RoverExpert
        >>> record = policy_record(RoverExpert(RoverMazeEnv(maze="u"), noise_std=0.1, seed=0))
        >>> record["policy"], record["policy_settings"]["noise_std"], record["policy_weights"] is not None
        ('torchrl_causal.experts.policies.RoverExpert', 0.1, True)
    """
    weights = None
    if isinstance(policy, torch.nn.Module):
        digest = hashlib.sha256()
        for name, value in sorted(policy.state_dict().items()):
            digest.update(f"{name}:{value.dtype}:{tuple(value.shape)}".encode())
            digest.update(tensor_bytes(value))
        weights = digest.hexdigest()
    settings = dict(getattr(policy, "settings", {}))
    return {"policy": f"{type(policy).__module__}.{type(policy).__qualname__}", "policy_settings": settings, "policy_weights": weights}


def env_expectation(env: EnvBase) -> dict[str, Any]:
    """The metadata a set collected in ``env`` must have (its config, batch size aside), as
    :func:`load_demonstrations`'s ``expected`` reads it."""
    return {"env": {k: v for k, v in env_config(env).items() if k != "batch_size"}}


def env_config(env: EnvBase) -> dict[str, Any]:
    """What a dataset records of the env it was collected in (``env.config()`` where the env has one)."""
    config = getattr(env, "config", None)
    if callable(config):
        return config()
    return {"class": f"{type(env).__module__}.{type(env).__qualname__}", "batch_size": list(env.batch_size)}


@torch.no_grad()
def _rollout_episodes(
    env: EnvBase, policy: Callable[[TensorDictBase], TensorDictBase], episodes: int, progress: bool
) -> list[TensorDictBase]:
    """Steps ``env`` (auto-resetting finished sub-envs) until ``episodes`` episodes completed.

    Returns the completed episodes, each a ``[T]`` TensorDict, in order of completion
    (ties broken by batch index); episodes still running at the end are dropped so that
    no truncated-by-collection episode enters the dataset. Completion order favours short
    episodes: when ``episodes`` is a few times the batch size, long ones (on goal-terminated
    tasks, the failures) are under-represented, so the stored success rate is the set's,
    not the policy's (Confounded AntMaze-Medium: 98.5% in 200 episodes from 64 envs,
    against the expert's 87%).
    """
    if env.batch_size == ():
        raise InvalidValueError("collect_demonstrations needs a batched env (batch_size (B,) or larger)")
    n_envs = env.batch_size.numel()
    steps: list[TensorDictBase] = []
    finished: list[tuple[int, int, int]] = []  # (end step, env index, start step)
    starts = torch.zeros(n_envs, dtype=torch.long)
    td = env.reset()
    with progress_reporter(episodes, "demonstrations", "episodes", enabled=progress) as bar:
        while len(finished) < episodes:
            td = policy(td)
            transition, td = env.step_and_maybe_reset(td)
            steps.append(transition.reshape(-1))
            t = len(steps) - 1
            done = transition.get(("next", "done")).reshape(n_envs)
            for index in done.nonzero().flatten().tolist():
                finished.append((t, index, int(starts[index])))
                starts[index] = t + 1
            bar.update(min(int(done.sum()), episodes - bar.n))
    trajectories = torch.stack(steps, dim=1)  # [n_envs, T]
    return [trajectories[index, start : end + 1] for end, index, start in sorted(finished)[:episodes]]


def _flatten(episodes: list[TensorDictBase]) -> TensorDictBase:
    # torch.cat hands tensordicts to tensordict's own cat (__torch_function__), which torch's
    # annotations cannot see.
    data = cast(TensorDictBase, torch.cat([episode.to_tensordict() for episode in episodes], dim=0))
    lengths = torch.tensor([episode.shape[0] for episode in episodes])
    is_init = torch.zeros(data.shape[0], 1, dtype=torch.bool)
    is_init[torch.cumsum(lengths, 0) - lengths] = True
    data.set("is_init", is_init)
    data.set("episode", torch.repeat_interleave(torch.arange(len(episodes)), lengths))
    return data


def collect_demonstrations(
    env: EnvBase,
    policy: Callable[[TensorDictBase], TensorDictBase],
    episodes: int,
    path: str | os.PathLike,
    *,
    seed: int | None = None,
    overwrite: bool = False,
    progress: bool = True,
) -> TensorDictBase:
    """Rolls ``policy`` out in ``env`` for ``episodes`` complete episodes and stores them at ``path``.

    Args:
        env: a batched env (its sub-envs run episodes in parallel and auto-reset).
        policy: a TensorDict policy (e.g. :class:`~torchrl_causal.experts.RoverExpert`).
        episodes: number of complete episodes to store.
        path: dataset directory to create.
        seed: seeds ``env`` before collecting (recorded in the metadata).
        overwrite: replace an existing dataset at ``path`` (else a :class:`FileExistsError`).
        progress: report progress (a bar on a terminal, else periodic log lines).

    Returns:
        The stored dataset, memory-mapped from ``path`` (as :func:`load_demonstrations` gives).

    Examples:
        >>> import tempfile
        >>> from torchrl_causal.envs import RoverMazeEnv
        >>> from torchrl_causal.experts import RoverExpert
        >>> env = RoverMazeEnv(maze="u", batch_size=(8,))
        >>> path = Path(tempfile.mkdtemp()) / "u_demos"
        >>> data = collect_demonstrations(env, RoverExpert(env), 8, path, seed=0, progress=False)
        >>> int(data["is_init"].sum()), read_metadata(path)["expert_success_rate"]
        (8, 1.0)
        >>> load_demonstrations(path, expected={"env": {"maze": "u"}, "regime": "train"}).shape == data.shape
        True
    """
    if not isinstance(episodes, int) or episodes < 1:
        raise InvalidValueError(f"episodes must be a positive int, got {episodes!r}")
    path = Path(path)
    if path.exists() and not overwrite:
        raise ExistingFileError(f"a dataset already exists at {path} (pass overwrite=True to replace it)")
    if path.exists() and not (path / _METADATA_FILE).is_file():
        # overwrite replaces a set this package wrote, never a file or folder of anything else
        raise ExistingFileError(
            f"{path} exists and is not a demonstration set (no {_METADATA_FILE}): nothing was changed; choose another path"
        )
    if seed is not None:
        env.set_seed(seed)
    data = _flatten(_rollout_episodes(env, policy, episodes, progress))
    last_steps = data.get(("next", "done")).squeeze(-1)
    success = data.get(("next", "success"))[last_steps] if ("next", "success") in data.keys(True) else None
    metadata: dict[str, Any] = {
        "format_version": FORMAT_VERSION,
        "env": env_config(env),
        "regime": getattr(env, "regime", None),
        "seed": seed,
        **policy_record(policy),
        "episodes": episodes,
        "transitions": data.shape[0],
        "expert_success_rate": None if success is None else success.float().mean().item(),
        "mean_episode_length": data.shape[0] / episodes,
        "manifest": _manifest(data),
    }
    metadata["checksum"] = dataset_checksum(data, metadata)
    _write_atomically(data, metadata, path, overwrite)
    return load_demonstrations(path)


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def _write_atomically(data: TensorDictBase, metadata: Mapping[str, Any], path: Path, overwrite: bool) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    staging = Path(tempfile.mkdtemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent))
    # mkdtemp creates 0700; the dataset gets the mode any new directory would (shared sets).
    staging.chmod(0o777 & ~_umask())
    try:
        data.memmap(staging / _DATA_DIR)
        (staging / _METADATA_FILE).write_text(json.dumps(metadata, indent=2, sort_keys=True))
        if overwrite and path.exists():
            # Move the old dataset aside first: a rename cannot replace a non-empty directory.
            retired = Path(tempfile.mkdtemp(prefix=f".{path.name}.", suffix=".old", dir=path.parent))
            os.replace(path, retired / path.name)
            os.replace(staging, path)
            shutil.rmtree(retired, ignore_errors=True)
        else:
            os.replace(staging, path)
    finally:
        shutil.rmtree(staging, ignore_errors=True)


def read_metadata(path: str | os.PathLike) -> dict[str, Any]:
    """The metadata of the dataset at ``path`` (not verified; :func:`load_demonstrations` verifies)."""
    file = Path(path) / _METADATA_FILE
    if not file.is_file():
        raise DatasetError(f"{path} is not a demonstration dataset: {_METADATA_FILE} is missing")
    try:
        return json.loads(file.read_text())
    except json.JSONDecodeError as error:
        raise DatasetError(f"{file} is corrupted: {error}") from error


def _check_file_sizes(path: Path, manifest: Mapping[str, Mapping[str, Any]]) -> None:
    # Checked before mapping: a memory map shorter than its recorded shape would read
    # past the end of the file instead of failing.
    for name, entry in manifest.items():
        file = path / _DATA_DIR / Path(*name.split(".")).with_suffix(".memmap")
        if not file.is_file():
            raise DatasetError(f"dataset {path} is missing key {name!r} (no file {file.name})")
        dtype = getattr(torch, entry["dtype"].removeprefix("torch."))
        expected = math.prod(entry["shape"]) * dtype.itemsize
        if file.stat().st_size != expected:
            raise DatasetError(f"dataset {path} key {name!r} is truncated or padded: {file.stat().st_size} bytes, expected {expected}")


def check_manifest(data: TensorDictBase, manifest: Mapping[str, Mapping[str, Any]], path: str | os.PathLike) -> None:
    """Refuses ``data`` unless its keys, shapes and dtypes are exactly the ``manifest``'s."""
    found = _manifest(data)
    for name, entry in manifest.items():
        if name not in found:
            raise DatasetError(f"dataset {path} is missing key {name!r}")
        if found[name] != entry:
            raise DatasetError(f"dataset {path} key {name!r} is {found[name]}, the manifest records {entry}")
    if extra := sorted(set(found) - set(manifest)):
        raise DatasetError(f"dataset {path} has keys absent from its manifest: {extra}")


def check_expected(actual: Any, expected: Any, where: str) -> None:
    """Refuses metadata ``actual`` unless every field of ``expected`` (nested) has its value."""
    if isinstance(expected, Mapping):
        if not isinstance(actual, Mapping):
            raise DatasetError(f"dataset metadata {where or 'root'} is {actual!r}, expected a mapping")
        for field, value in expected.items():
            name = f"{where}.{field}" if where else str(field)
            if field not in actual:
                raise DatasetError(f"dataset metadata has no field {name!r} (expected {value!r})")
            check_expected(actual[field], value, name)
    elif actual != expected and not (where == "policy" and current_class_path(actual) == expected):
        raise DatasetError(f"dataset metadata field {where!r} is {actual!r}, expected {expected!r}")


def current_class_path(path: Any) -> Any:
    """The dotted path by which the class at ``path`` (one of this package's) names itself now:
    a set recorded by an expert before it moved (``torchrl_causal.envs.experts.RoverExpert``, an
    old path kept importable) is the same expert's. Anything else is returned as it is.

    Examples:
        >>> current_class_path("torchrl_causal.envs.experts.RoverExpert")
        'torchrl_causal.experts.policies.RoverExpert'
        >>> current_class_path("torchrl_causal.no_such_module.Expert")
        'torchrl_causal.no_such_module.Expert'
    """
    if not isinstance(path, str) or not path.startswith("torchrl_causal."):
        return path  # imports only this package's modules, never one a file names
    module, _, name = path.rpartition(".")
    try:
        found = getattr(importlib.import_module(module), name)
    except (ImportError, AttributeError):
        return path
    return f"{found.__module__}.{found.__qualname__}" if isinstance(found, type) else path


def load_demonstrations(
    path: str | os.PathLike,
    expected: Mapping[str, Any] | EnvBase | None = None,
    *,
    verify_checksum: bool = True,
) -> TensorDictBase:
    """Loads a dataset written by :func:`collect_demonstrations`, refusing a bad one.

    Args:
        path: the dataset directory.
        expected: metadata the dataset must match: a (nested) mapping of fields, e.g.
            ``{"regime": "train", "env": {"maze": "medium"}}``, or an env whose config
            (batch size aside) must be the recorded one.
        verify_checksum: recompute the SHA-256 checksum (reads every byte once).

    Returns:
        The memory-mapped TensorDict of shape ``[N]``.

    Raises:
        DatasetError: a missing or unreadable file, a format version this code cannot
            read, a missing key or a shape/dtype differing from the manifest, a checksum
            mismatch (edited data or metadata), or metadata that differs from ``expected``.
    """
    path = Path(path)
    metadata = read_metadata(path)
    version = metadata.get("format_version")
    if version != FORMAT_VERSION:
        raise DatasetError(f"dataset {path} has format_version {version!r}; this code reads {FORMAT_VERSION}")
    manifest = metadata.get("manifest", {})
    _check_file_sizes(path, manifest)
    try:
        data = TensorDict.load_memmap(path / _DATA_DIR)
    except Exception as error:  # tensordict raises a variety of errors on truncated or missing files
        raise DatasetError(f"dataset {path} cannot be read (truncated or missing file?): {error}") from error
    check_manifest(data, manifest, path)
    if verify_checksum and dataset_checksum(data, metadata) != metadata.get("checksum"):
        raise DatasetError(f"dataset {path} fails its checksum: its data or metadata were modified")
    if isinstance(expected, EnvBase):
        expected = env_expectation(expected)
    if expected is not None:
        check_expected(metadata, expected, "")
    return data


def successful_episodes(data: TensorDictBase) -> TensorDictBase:
    """The episodes of a dataset whose last transition reached the goal (``("next", "success")``).

    Imitation losses that label every expert transition alike (SQIL's reward 1, IQ-Learn's
    expert occupancy) also imitate the expert's failures: on Confounded AntMaze those are
    flips, hundreds of steps of an upside-down ant per failed episode. Keeping whole
    successful episodes leaves ``"is_init"`` and ``"episode"`` valid.

    Args:
        data: a dataset of shape ``[N]`` as :func:`load_demonstrations` returns it.

    Returns:
        A new TensorDict with the transitions of the successful episodes, in their order.

    Raises:
        DatasetError: the dataset has no ``("next", "success")`` key, or no episode succeeded.

    Examples:
        >>> from tensordict import TensorDict
        >>> episode = torch.tensor([0, 0, 1, 1, 1, 2])
        >>> data = TensorDict({"episode": episode,
        ...                    "next": {"success": torch.tensor([[False], [True], [False], [False], [False], [True]])}},
        ...                   batch_size=[6])
        >>> successful_episodes(data)["episode"].tolist()
        [0, 0, 2]
    """
    if ("next", "success") not in data.keys(True):
        raise DatasetError("cannot select successful episodes: the dataset has no ('next', 'success') key")
    episode = data.get("episode")
    success = data.get(("next", "success")).reshape(-1)
    # An episode ends at success, so any successful step marks its episode as successful.
    succeeded = torch.zeros(int(episode.max()) + 1, dtype=torch.bool).index_put_((episode,), success, accumulate=True)
    keep = succeeded[episode]
    if not keep.any():
        raise DatasetError(f"no episode of the {int(episode.unique().numel())} in the dataset reached the goal")
    return data[keep].to_tensordict()
