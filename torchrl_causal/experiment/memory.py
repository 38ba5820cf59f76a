"""What a run will hold in memory and on disk, estimated before anything is allocated.

Every size a config controls multiplies into arrays: the window's ``k`` widens every
encoded observation (one copy of the admissible state per lag), ``demos.episodes`` and
``env.horizon`` bound the demonstration transitions, ``algo.buffer_size`` the policy
replay buffer, ``algo.num_envs``, ``algo.frames_per_batch``, GAIL's rollouts and
``eval.num_envs`` the batches in flight. A config whose product exceeds the machine does
not fail cleanly by itself: it grows until the kernel kills it (``window.k=100000`` on
RoverMaze-U reached 24 GB in 99 s). So :func:`run_footprint` adds up the dominant arrays
of a run from the sizes of its specs (one env of batch size 1 is built, nothing else),
and :func:`check_footprint` refuses a run that would not fit, naming the biggest items
and the keys that set them, before its run directory exists.

The estimate counts what scales with the config, each array at its stored size (measured
against the tensors themselves in ``tests/test_memory.py``), plus the libraries' fixed
cost; the networks (a few MB at Appendix E's widths) are left out. The libraries' allowance
(0.5 GB against 0.39 GB measured after the imports) carries a run's fixed costs: on a BC run
of 8,000 transitions at k = 50 the estimate was 544 MB against a measured peak of 447 MB
(``tests/test_memory.py`` holds it within a factor 2 above the peak).

Examples:
    >>> footprint = Footprint(ram={"encoded demonstrations (demos.episodes x env.horizon)": 3 * GB,
    ...                            "libraries": LIBRARIES_BYTES}, disk={})
    >>> check_footprint(footprint, available_ram=8 * GB, free_disk=GB)  # fits
    >>> check_footprint(footprint, available_ram=2 * GB, free_disk=GB)  # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    torchrl_causal.experiment.schema.ConfigValueError: this run needs an estimated 3.5 GB of memory ...
"""

from __future__ import annotations

import dataclasses
import math
import os
import shutil
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import torch  # noqa: F401  (the docstring examples use it)
from omegaconf import DictConfig, OmegaConf
from torchrl.data import Composite, TensorSpec

from torchrl_causal.available import available_memory
from torchrl_causal.experiment.builders import make_env, make_imitator_env, make_window
from torchrl_causal.experiment.schema import EVAL_VIDEO_SIZE, ConfigValueError, GAILConfig, OffPolicyConfig, algo_schema_of
from torchrl_causal.graphs.window import AdjustmentWindow

__all__ = [
    "GB",
    "LIBRARIES_BYTES",
    "Footprint",
    "available_memory",
    "check_footprint",
    "check_run_fits",
    "disk_size",
    "encoded_transition_bytes",
    "free_disk",
    "measured_transition_bytes",
    "run_footprint",
    "spec_bytes",
    "transition_bytes",
]

GB = 1 << 30
#: Resident memory of a process that imported the package (torch, TorchRL, MuJoCo):
#: 0.47 GB measured with ``/usr/bin/time -f %M python -c "import torchrl_causal.train"``.
LIBRARIES_BYTES = GB // 2
#: Windows up to this many lags are measured; a longer one is extrapolated from two probes
#: of ``EXACT_K // 2`` and ``EXACT_K`` lags, so that a window too large to fit is refused
#: before it is built.
EXACT_K = 16


@dataclass(frozen=True)
class Footprint:
    """Estimated bytes per item, in memory (``ram``) and on disk (``disk``); each item's
    name says which config keys set it."""

    ram: dict[str, int]
    disk: dict[str, int]
    #: files created at their full size but written only as they fill (the replay buffer's
    #: memory maps): they need no free disk up front, but cannot outgrow the file system
    reserved: dict[str, int] = dataclasses.field(default_factory=dict)

    @property
    def ram_bytes(self) -> int:
        return sum(self.ram.values())

    @property
    def disk_bytes(self) -> int:
        return sum(self.disk.values())


def spec_bytes(spec: TensorSpec) -> int:
    """Bytes of one sample of ``spec`` (every leaf of a composite one).

    Examples:
        >>> from torchrl.data import Composite, Unbounded
        >>> spec_bytes(Composite(a=Unbounded((3,)), b=Unbounded((2, 2), dtype=torch.float64)))
        44
    """
    if isinstance(spec, Composite):
        return sum(spec_bytes(leaf) for leaf in spec.values(True, True))
    return math.prod(spec.shape) * spec.dtype.itemsize


def transition_bytes(observation: TensorSpec, action: TensorSpec) -> int:
    """Bytes of one replay transition as the losses read it (``observation``, ``action``,
    ``("next", "observation")``, float32 reward, bool done / terminated and expert flags),
    from the imitator env's encoded ``observation`` spec and its action spec."""
    return 2 * spec_bytes(observation) + spec_bytes(action) + 4 + 3


def _demonstration_transitions(cfg: DictConfig) -> int:
    """The stored set's transition count when it exists, else its bound (every episode
    as long as the horizon)."""
    from torchrl_causal.data.demonstrations import DatasetError, read_metadata

    try:
        return int(read_metadata(cfg.demos.path)["transitions"])
    except (DatasetError, KeyError, TypeError, ValueError):
        return cfg.demos.episodes * cfg.env.horizon


def measured_transition_bytes(cfg: DictConfig, k: int) -> int:
    """:func:`transition_bytes` of the imitator env of ``cfg`` with a window of ``k`` lags."""
    small = cfg.copy()
    small.window.k = k
    return _imitator_transition_bytes(small, make_window(small))


def encoded_transition_bytes(cfg: DictConfig, window: Callable[[], AdjustmentWindow] | None = None) -> int:
    """:func:`transition_bytes` of the run's imitator env.

    ``window`` gives the run's window (the lifecycle builds it once, cached, and hands the
    same one to the trainer and the evaluator; built from ``cfg`` when not given). It is
    asked for only when ``window.k`` is at most :data:`EXACT_K`: past the first few lags every
    lag holds the same variables, so the width grows linearly in ``k`` and a longer window's
    is extrapolated exactly from two small probes, and a run whose window would not fit is
    refused before that window is allocated.
    """
    k = cfg.window.k
    if k <= EXACT_K:
        return _imitator_transition_bytes(cfg, make_window(cfg) if window is None else window())
    low, high = measured_transition_bytes(cfg, EXACT_K // 2), measured_transition_bytes(cfg, EXACT_K)
    return high + (high - low) * (k - EXACT_K) // (EXACT_K - EXACT_K // 2)


def _imitator_transition_bytes(cfg: DictConfig, window: AdjustmentWindow) -> int:
    env = make_imitator_env(cfg, window, "train", 1, cfg.seed)
    try:
        return transition_bytes(env.observation_spec["observation"], env.full_action_spec["action"])
    finally:
        env.close()


def _video_bytes(cfg: DictConfig) -> dict[str, int]:
    """The frames of the evaluations' videos, held until each episode ends (twice while one
    is written): the episodes of one round of the final evaluation (or of a periodic one,
    with ``eval.video_periodic``), every ``eval.video_every``-th step."""
    episodes = cfg.eval.final_episodes
    if OmegaConf.select(cfg, "eval.video_periodic", default=False):
        episodes = max(episodes, cfg.eval.episodes)
    count = min(int(OmegaConf.select(cfg, "eval.video", default=0) or 0), cfg.eval.num_envs, episodes)
    if not count:
        return {}
    frames = cfg.env.horizon // int(OmegaConf.select(cfg, "eval.video_every", default=1)) + 2
    return {"evaluation videos (eval.video x env.horizon / eval.video_every frames)": 2 * count * frames * EVAL_VIDEO_SIZE**2 * 3}


def run_footprint(cfg: DictConfig, window: Callable[[], AdjustmentWindow] | None = None) -> Footprint:
    """The dominant arrays of a run of ``cfg`` (validated) over its ``window`` (see
    :func:`encoded_transition_bytes`; the expert row has none)."""
    base = make_env(cfg, "train", 1, cfg.seed)
    try:
        raw_step = 2 * spec_bytes(base.full_observation_spec) + spec_bytes(base.full_action_spec)
    finally:
        base.close()
    if not cfg.algo.trainer:  # the expert row only evaluates
        ram = {"libraries": LIBRARIES_BYTES, "evaluation envs (eval.num_envs)": 4 * cfg.eval.num_envs * raw_step}
        return Footprint(ram={**ram, **_video_bytes(cfg)}, disk={})
    step = encoded_transition_bytes(cfg, window)
    algo, schema = cfg.algo, algo_schema_of(cfg)
    demos = _demonstration_transitions(cfg)
    ram = {
        "libraries": LIBRARIES_BYTES,
        # the raw set while it is collected; encoded, then copied once into the expert buffer / BC's split
        "demonstrations (demos.episodes x env.horizon)": demos * raw_step,
        "encoded demonstrations (demos.episodes x env.horizon x window.k)": 2 * demos * step,
        # the env's step and the window's lag ring, a few copies per step
        "evaluation envs (eval.num_envs x window.k)": 4 * cfg.eval.num_envs * step,
        **_video_bytes(cfg),
    }
    disk = {} if Path(cfg.demos.path).exists() else {"demonstration set (demos.episodes x env.horizon)": demos * raw_step}
    if issubclass(schema, OffPolicyConfig):
        ram["collector batches (algo.frames_per_batch x window.k)"] = 2 * algo.frames_per_batch * step
        disk["policy replay buffer (algo.buffer_size x window.k)"] = min(algo.buffer_size, algo.total_steps) * step
        reserved = {f"policy replay buffer files (algo.buffer_size={algo.buffer_size} x window.k)": algo.buffer_size * step}
        return Footprint(ram=ram, disk=disk, reserved=reserved)
    elif schema is GAILConfig:
        ram["GAIL rollouts (algo.episodes_per_round x env.horizon x window.k)"] = 2 * algo.episodes_per_round * cfg.env.horizon * step
    return Footprint(ram=ram, disk=disk)


def _existing_folder(path: str | os.PathLike) -> Path:
    folder = Path(path).absolute()
    while not folder.exists():
        folder = folder.parent
    return folder


def disk_size(path: str | os.PathLike) -> int:
    """Total bytes of the file system that will hold ``path``."""
    return shutil.disk_usage(_existing_folder(path)).total


def free_disk(path: str | os.PathLike) -> int:
    """Free bytes on the file system that will hold ``path`` (its first existing folder)."""
    return shutil.disk_usage(_existing_folder(path)).free


def _size(count: int) -> str:
    # a small estimate in kB: "0.0 MB" would read as nothing at all
    if count >= GB // 10:
        return f"{count / GB:.1f} GB"
    return f"{count / (1 << 20):.1f} MB" if count >= (1 << 20) // 10 else f"{count / 1024:.1f} kB"


def _largest(items: dict[str, int], count: int = 3) -> str:
    biggest = sorted(items.items(), key=lambda item: -item[1])[:count]
    return ", ".join(f"{name} {_size(value)}" for name, value in biggest)


def check_footprint(footprint: Footprint, *, available_ram: int, free_disk: int, disk_size: int | None = None) -> None:
    """Refuses a run whose estimated memory or disk exceeds what is available, or whose
    reserved files exceed the whole file system (``disk_size``, when given).

    Raises:
        ConfigValueError: naming the estimate, its largest items (and the keys that set
            them) and what is available.
    """
    if footprint.ram_bytes > available_ram:
        raise ConfigValueError(
            f"this run needs an estimated {_size(footprint.ram_bytes)} of memory ({_largest(footprint.ram)}) "
            f"and {_size(available_ram)} are available: lower the keys named (a smaller window.k, fewer "
            "demos.episodes or envs), or raise max_memory_gb if this machine has more to give"
        )
    reserved = sum(footprint.reserved.values())
    if disk_size is not None and reserved > disk_size:
        raise ConfigValueError(
            f"this run would create files of {_size(reserved)} ({_largest(footprint.reserved)}) on a file system of "
            f"{_size(disk_size)}: the buffer never holds more than algo.total_steps transitions, so lower algo.buffer_size"
        )
    if footprint.disk_bytes > free_disk:
        raise ConfigValueError(
            f"this run needs an estimated {_size(footprint.disk_bytes)} of disk ({_largest(footprint.disk)}) "
            f"and the run root's file system has {_size(free_disk)} free: lower the keys named, or choose "
            "another run_root"
        )


def check_run_fits(cfg: DictConfig, window: Callable[[], AdjustmentWindow] | None = None) -> Footprint:
    """:func:`check_footprint` of :func:`run_footprint` (over the run's ``window``) against this
    machine (its available memory, or ``cfg.max_memory_gb`` when set, and the free disk below
    ``cfg.run_dir``)."""
    footprint = run_footprint(cfg, window)
    limit = OmegaConf.select(cfg, "max_memory_gb")
    ram = available_memory() if limit is None else int(float(limit) * GB)
    check_footprint(footprint, available_ram=ram, free_disk=free_disk(cfg.run_dir), disk_size=disk_size(cfg.run_dir))
    return footprint
