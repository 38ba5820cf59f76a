"""What a run tells its logger beside its losses: the resolved config, once, and its speed.

:func:`open_run_logger` opens the run's TorchRL logger (``cfg.logger``) in its directory:
for training, and again for the final evaluation's videos.

:func:`log_config` hands the run's resolved config to TorchRL's ``Logger.log_hparams``,
flattened to ``"algo.actor.hidden": 256``-style keys with scalar values (what TensorBoard's
hparams accept): the CSV logger writes it to ``logs/texts/hparams0.txt`` (``key: value``
lines), TensorBoard as its hparams, W&B as the run's config.

:class:`SpeedMeter` measures the training throughput the loop logs at each periodic
evaluation under ``speed/``: env steps and gradient updates per second of time spent in
training steps (evaluation and checkpoints left out), and the run's wall time in seconds
since its first start, attempts before a resume included. These are measurements of the
machine, not results: unlike every other scalar they differ between two runs of the same
config.

The wall time is not the attempts' cost that ``code.json`` records
(:class:`~torchrl_causal.experiment.provenance.AttemptClock`: each ended attempt's whole
wall and CPU time, none for one killed outright): it is the time the run took to reach the
progress it stands at. ``status.json`` holds it as of the last checkpoint, so a resumed run
goes on from the time of the checkpoint it resumed from, and the work an interrupted
attempt did after that checkpoint, lost with it, is not counted.

Examples:
    >>> from omegaconf import OmegaConf
    >>> flat_config(OmegaConf.create({"algo": {"name": "bc", "lr": 1e-3, "drop": [], "x": None}, "seed": 0}))
    {'algo.drop': '[]', 'algo.lr': 0.001, 'algo.name': 'bc', 'algo.x': 'null', 'seed': 0}
    >>> ticks = iter([0.0, 2.0, 10.0])
    >>> meter = SpeedMeter(wall_time_s=100.0, clock=lambda: next(ticks))
    >>> meter.add(seconds=2.0, env_steps=500, updates=40)
    >>> meter.read()
    {'speed/env_steps_per_s': 250.0, 'speed/updates_per_s': 20.0, 'speed/wall_time_s': 102.0}
    >>> meter.wall_time_s
    110.0
"""

from __future__ import annotations

import json
import time
from collections.abc import Callable
from typing import Any

from hydra.utils import instantiate
from omegaconf import DictConfig, OmegaConf
from torchrl.record.loggers import Logger

from torchrl_causal.experiment.run_directory import RunDirectory

__all__ = ["SPEED_PREFIX", "SpeedMeter", "flat_config", "log_config", "open_run_logger"]

#: The prefix of the speed scalars (measurements that differ from run to run).
SPEED_PREFIX = "speed/"


def flat_config(cfg: DictConfig) -> dict[str, int | float | str | bool]:
    """``cfg`` resolved, as ``{"dotted.key": value}`` sorted by key; a value that is not an
    int, float, str or bool (a list, ``None``) is written as its JSON text."""
    flat: dict[str, int | float | str | bool] = {}

    def visit(prefix: str, node: Any) -> None:
        if isinstance(node, dict) and node:
            for key, value in node.items():
                visit(f"{prefix}.{key}" if prefix else str(key), value)
        elif isinstance(node, (bool, int, float, str)):
            flat[prefix] = node
        else:
            flat[prefix] = json.dumps(node)

    visit("", OmegaConf.to_container(cfg, resolve=True, enum_to_str=True))
    return dict(sorted(flat.items()))


def open_run_logger(cfg: DictConfig, run: RunDirectory) -> Logger:
    """The run's logger, ``cfg.logger`` with the run directory as its ``log_dir``: the CSV
    logger's and TensorBoard's files go to ``<run_dir>/logs``, W&B's offline runs to
    ``<run_dir>/wandb`` (a logger opened again logs to the same W&B run: its id is the run's)."""
    return instantiate(cfg.logger)(log_dir=str(run.path))


def log_config(logger: Logger, cfg: DictConfig) -> None:
    """Logs the resolved ``cfg`` through ``logger.log_hparams`` (see the module docstring)."""
    logger.log_hparams(flat_config(cfg))


class SpeedMeter:
    """Throughput over the training time between two :meth:`read` s, and the run's wall time.

    Args:
        wall_time_s: the wall time of the run's earlier attempts (0 for a fresh run).
        clock: seconds, monotonic (a test passes its own).
    """

    def __init__(self, wall_time_s: float = 0.0, clock: Callable[[], float] = time.monotonic) -> None:
        self._clock = clock
        self._earlier = float(wall_time_s)
        self._start = clock()
        self._seconds = 0.0
        self._env_steps = 0
        self._updates = 0

    @property
    def wall_time_s(self) -> float:
        """Seconds since the run first started, counting only the time its attempts ran."""
        return self._earlier + self._clock() - self._start

    def add(self, seconds: float, env_steps: int, updates: int) -> None:
        """Counts one training step: how long it took, the env steps and updates it made."""
        self._seconds += seconds
        self._env_steps += env_steps
        self._updates += updates

    def read(self) -> dict[str, float]:
        """The ``speed/`` scalars since the last read (a rate only when training time passed
        and, for env steps, when the trainer steps envs at all); starts the next interval."""
        scalars: dict[str, float] = {}
        if self._seconds > 0:
            if self._env_steps:
                scalars[f"{SPEED_PREFIX}env_steps_per_s"] = self._env_steps / self._seconds
            scalars[f"{SPEED_PREFIX}updates_per_s"] = self._updates / self._seconds
        scalars[f"{SPEED_PREFIX}wall_time_s"] = self.wall_time_s
        self._seconds, self._env_steps, self._updates = 0.0, 0, 0
        return scalars
