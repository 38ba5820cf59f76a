"""What a walking skill's training run shares, whichever learner trains it: its folder, its
resume state, its evaluation and save schedule, its logs, its export and its command line.

The SAC trainer (:mod:`torchrl_causal.experts.locomotion`) and the PPO trainer
(:mod:`torchrl_causal.experts.locomotion_ppo`) differ in their learner and their updates; the
rest of a run is the same and lives here:

* :class:`SkillRunDirectory`: the run folder. It follows the package's rule of ownership
  (:func:`~torchrl_causal.experiment.run_directory.foreign_entries`): a run writes and removes
  only the entries it writes, in a folder whose config file it wrote, and refuses any other
  non-empty folder in one line (:class:`~torchrl_causal.experiment.run_directory.ForeignFilesError`)
  before anything is written. A run directory belongs to one config (:func:`check_same_config`).
* :func:`read_skill_state`: a resume state of the right learner and skill, or one line.
* :func:`skill_collector` collects in the trainer's process; :func:`parallel_skill_collector`
  in ``workers`` spawned processes (TorchRL's :class:`~torchrl.collectors.MultiSyncCollector`),
  each on its own simulations with its own :func:`worker_seeds`, one thread each.
* :class:`SkillLoop`: after each collected batch, evaluate (every ``eval_every`` env steps and at
  the end; the best :func:`upright_speed` keeps its body) or save (every ``checkpoint_minutes``),
  log the scalars and move the progress bar.
* :func:`skill_parser` and :func:`run_skill_command`: the trainers' ``--flags``, parsed by
  :class:`~torchrl_causal.cli.arguments.OneLineParser` with bounded types, and their refusals
  in one line.

Examples:
    >>> import tempfile
    >>> from dataclasses import dataclass
    >>> @dataclass(frozen=True)
    ... class Config:
    ...     lr: float = 3e-4
    ...     total_steps: int = 10
    >>> run = SkillRunDirectory(tempfile.mkdtemp(), "demo_config.json")
    >>> run.open(Config())
    >>> run.write_config(Config())
    >>> run.open(Config(total_steps=20))  # the budget is bookkeeping: a run may extend it
    >>> run.open(Config(lr=1e-3))  # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    torchrl_causal.errors.InvalidValueError: ... was trained with another config (changed: ['lr']); ...
"""

from __future__ import annotations

import argparse
import json
import logging
import math
import os
import shutil
import sys
import time
from collections.abc import Callable, Collection, Iterable, Iterator, Mapping, MutableMapping, Sequence
from contextlib import contextmanager
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np
import torch
from torch import nn
from torchrl.collectors import Collector, MultiSyncCollector
from torchrl.envs import EnvBase
from torchrl.record.loggers.csv import CSVLogger

from torchrl_causal.command_line import OneLineParser, count, non_negative, one_line_errors
from torchrl_causal.errors import InvalidValueError, TorchRLCausalError
from torchrl_causal.experiment.interrupts import RunInterrupted, ignored_signals
from torchrl_causal.experiment.run_directory import (
    EntryPath,
    atomic_save,
    atomic_write_text,
    check_owned,
    foreign_entries,
    load_checkpoint,
)
from torchrl_causal.progress import progress

__all__ = [
    "BEST_BODY",
    "BOOKKEEPING",
    "EXPORT",
    "RESUME_STATE",
    "SeededEnvMaker",
    "SkillLoop",
    "SkillRunDirectory",
    "WorkerSeeds",
    "add_output_argument",
    "check_same_config",
    "finish_skill_run",
    "parallel_skill_collector",
    "read_skill_state",
    "require_positive",
    "run_skill_command",
    "skill_collector",
    "skill_parser",
    "upright_speed",
    "worker_seeds",
]

log = logging.getLogger(__name__)

#: Fields a continued run may change: the budget, when and how much it evaluates and saves, and
#: how many processes collect (each attempt draws fresh episodes from fresh seeds anyway).
BOOKKEEPING = frozenset({"total_steps", "eval_every", "eval_envs", "eval_steps", "checkpoint_minutes", "collector_workers"})

#: Where a skill run keeps the body of its best evaluation, in its run directory.
BEST_BODY = "best_body.pt"

#: The few MB a run needs to continue on another machine (``--resume-from``).
RESUME_STATE = "resume_state.pt"

#: The command lines' default export, in the run directory; only a named ``--output`` replaces
#: the package's weights (a short trial run must not).
EXPORT = "export.pt"

_RESULT = "result.json"
_LOGS = "logs"


def require_positive(config: Any, names: Iterable[str]) -> None:
    """Refuses a config whose ``names`` fields are not all >= 1, naming the first that is not."""
    for name in names:
        if getattr(config, name) < 1:
            raise InvalidValueError(f"{name} must be >= 1, got {getattr(config, name)}")


def _as_json(value: Any) -> Any:
    """``value`` as a JSON file reads it back (a tuple is a list there), so saved and live configs compare."""
    return json.loads(json.dumps(value))


def check_same_config(saved: dict[str, Any], config: Any, where: str | Path) -> None:
    """Refuses to continue a run made with another config (its learning settings, not its
    :data:`BOOKKEEPING`); ``config`` is a dataclass, and fields added since the run started
    keep their default."""
    defaults = asdict(type(config)())
    changed = sorted(k for k, v in asdict(config).items() if k not in BOOKKEEPING and _as_json(saved.get(k, defaults[k])) != _as_json(v))
    if changed:
        raise InvalidValueError(f"{where} was trained with another config (changed: {changed}); use a new --run-dir or the same settings")


def upright_speed(result: Mapping[str, float]) -> float:
    """The score that selects a skill run's best evaluation: speed along the command times the
    fraction of envs that never fell.

    Speed alone prefers a policy that lunges along the command and falls (a fall moves the torso
    fast) to one that stands or walks slowly without falling; the maze expert needs the latter.

    Examples:
        >>> upright_speed({"speed": 0.13, "fall_rate": 1.0}), upright_speed({"speed": 0.8, "fall_rate": 0.25})
        (0.0, 0.6000000000000001)
    """
    return result["speed"] * (1.0 - result["fall_rate"])


def finish_skill_run(run_dir: Path, output: str | Path | None, record: dict[str, Any]) -> dict[str, Any]:
    """Exports the run's best body to ``output`` (unless ``None`` or there is none yet), writes
    ``record`` (with ``"exported"``) to ``<run_dir>/result.json`` and returns it."""
    if output is not None and (run_dir / BEST_BODY).exists():
        output = Path(output)
        output.parent.mkdir(parents=True, exist_ok=True)
        atomic_save(torch.load(run_dir / BEST_BODY, weights_only=True), output)
        record["exported"] = str(output)
    atomic_write_text(run_dir / _RESULT, json.dumps(record, indent=2))
    return record


def _is_json_object(path: Path) -> bool:
    try:
        return isinstance(json.loads(path.read_text()), dict)
    except (OSError, ValueError):  # missing, unreadable or not JSON: not provably the run's
        return False


class SkillRunDirectory:
    """A skill run's folder: the entries it writes and the config file that proves it the run's.

    Args:
        path: the run directory (``--run-dir``); nothing is created before :meth:`open`.
        config_name: the trainer's config file (``locomotion_config.json``, ``ppo_config.json``).
        entries: the trainer's own entries besides the shared ones (its config, :data:`BEST_BODY`,
            :data:`RESUME_STATE`, :data:`EXPORT`, ``result.json``, ``logs``).
    """

    def __init__(self, path: str | Path, config_name: str, entries: Collection[str] = ()) -> None:
        self.path = Path(path)
        self.config_file = self.path / config_name
        self.entries = frozenset({config_name, BEST_BODY, RESUME_STATE, EXPORT, _RESULT, _LOGS, *entries})

    def __repr__(self) -> str:
        return f"SkillRunDirectory({str(self.path)!r})"

    best_body = EntryPath(BEST_BODY)
    resume_state = EntryPath(RESUME_STATE)

    def foreign_entries(self) -> list[Path]:
        """What the folder holds that no run of this trainer wrote (empty for a missing or empty folder).

        Examples:
            >>> import tempfile
            >>> run = SkillRunDirectory(tempfile.mkdtemp(), "ppo_config.json")
            >>> _ = (run.path / "thesis.tex").write_text("...")
            >>> [p.name for p in run.foreign_entries()]
            ['thesis.tex']
        """
        return foreign_entries(self.path, self.entries, self.config_file, _is_json_object)

    def open(self, config: Any) -> None:
        """Makes the folder for a run of ``config`` (a dataclass), after refusing one that holds
        anything the run did not write, or a run of another config.

        Raises:
            ForeignFilesError: the folder holds files no run wrote (nothing is written or removed).
            InvalidValueError: the folder holds a run of another config (:func:`check_same_config`).
        """
        check_owned(self.path, self.foreign_entries, "use a new --run-dir (a missing or empty folder)")
        if self.config_file.exists():
            check_same_config(json.loads(self.config_file.read_text()), config, self.path)
        self.path.mkdir(parents=True, exist_ok=True)

    def write_config(self, config: Any) -> None:
        atomic_write_text(self.config_file, json.dumps(asdict(config), indent=2))

    def adopt_best(self, state: Mapping[str, Any]) -> None:
        """Keeps a resume state's best body as this run's (the best policy so far travels with the state)."""
        if "best_body" in state:
            atomic_save(state["best_body"], self.best_body)

    def keep_if_best(self, counters: MutableMapping[str, Any], body: nn.Module, result: Mapping[str, float]) -> float:
        """Saves ``body`` as the best when the evaluation ``result`` beats ``counters["best_score"]``
        (:func:`upright_speed`, which it returns)."""
        score = upright_speed(result)
        if score > counters["best_score"]:
            counters["best_score"] = score
            atomic_save(body.state_dict(), self.best_body)
        return score

    def save_resume_state(self, learner: Mapping[str, Any]) -> None:
        """Writes ``learner`` with the best body so far as :data:`RESUME_STATE` (atomically)."""
        best = {"best_body": torch.load(self.best_body, weights_only=True)} if self.best_body.exists() else {}
        atomic_save({**learner, **best}, self.resume_state)

    def replace_folder(self, name: str, write: Callable[[Path], None]) -> None:
        """Replaces the run's folder ``name`` by what ``write(folder)`` writes, so that a kill at any
        point leaves the old or the new one (written to ``<name>.tmp``, swapped through ``<name>.old``;
        all three are the run's own entries)."""
        if not {name, f"{name}.tmp", f"{name}.old"} <= self.entries:
            raise InvalidValueError(f"{name!r} is not one of {self.path}'s own entries: a run replaces only what it writes")
        target, tmp, old = self.path / name, self.path / f"{name}.tmp", self.path / f"{name}.old"
        shutil.rmtree(tmp, ignore_errors=True)
        write(tmp)
        shutil.rmtree(old, ignore_errors=True)
        if target.exists():
            target.rename(old)
        tmp.rename(target)
        shutil.rmtree(old, ignore_errors=True)

    def finish(self, output: str | Path | None, record: dict[str, Any]) -> dict[str, Any]:
        """:func:`finish_skill_run` of this run."""
        return finish_skill_run(self.path, output, record)


def read_skill_state(path: str | Path, skill: str, algorithm: str) -> dict[str, Any]:
    """The resume state at ``path``, refused in one line unless it holds ``algorithm``'s learner
    of ``skill`` (a SAC state written before states named their algorithm counts as SAC's)."""
    state = load_checkpoint(Path(path))
    found = state.get("algorithm", "sac")
    if state.get("skill") != skill or found != algorithm:
        raise InvalidValueError(f"{path} holds a {found.upper()} {state.get('skill')!r} skill, not {algorithm.upper()}'s {skill!r}")
    return state


def skill_collector(env: EnvBase, actor: nn.Module, frames_per_batch: int, steps: int, random_steps: int = 0) -> Collector:
    """A CPU collector of at least ``steps`` env steps in whole batches, the first
    ``random_steps`` (rounded up to whole batches) uniformly random."""
    return Collector(
        env,
        actor,
        frames_per_batch=frames_per_batch,
        total_frames=math.ceil(steps / frames_per_batch) * frames_per_batch,
        init_random_frames=math.ceil(random_steps / frames_per_batch) * frames_per_batch,
        device="cpu",
        auto_register_policy_transforms=False,
    )


@dataclass(frozen=True)
class WorkerSeeds:
    """The seeds of one collector worker: its env's generator and its process's torch generator
    (the policy's sampled actions). Two, so the env and the policy never draw the same stream."""

    env: int
    policy: int


def worker_seeds(run_seed: int, collect_seed: int, workers: int) -> list[WorkerSeeds]:
    """The seeds of ``workers`` collector processes in the attempt of a run (seeded ``run_seed``)
    that collects under ``collect_seed`` (a run's counter, one more at each attempt).

    Each is drawn by NumPy's :class:`~numpy.random.SeedSequence` from ``(run_seed, collect_seed)``
    and the worker's index: 63-bit seeds that no other worker, attempt or run shares (two
    different keys collide with probability ~1e-19), where consecutive small integers would
    give a run seeded 1 the streams of a run seeded 0's next attempt.

    Examples:
        >>> seeds = worker_seeds(0, 1, 2)
        >>> len({seed for pair in seeds for seed in (pair.env, pair.policy)})
        4
        >>> worker_seeds(0, 1, 2) == seeds  # a function of its arguments
        True
    """
    if workers < 1:
        raise InvalidValueError(f"workers must be >= 1, got {workers}")
    children = np.random.SeedSequence([run_seed, collect_seed]).spawn(workers)
    pairs = [child.generate_state(2, np.uint64) >> np.uint64(1) for child in children]  # < 2**63: any torch seed
    return [WorkerSeeds(env=int(env), policy=int(policy)) for env, policy in pairs]


@dataclass(frozen=True)
class SeededEnvMaker:
    """Builds one collector worker's env, in that worker: seeds the worker's torch generator
    (its policy's sampled actions) with ``seeds.policy``, then returns ``make_env(seeds.env)``.

    TorchRL pickles it (with cloudpickle) into the spawned worker, so ``make_env`` may be a closure.

    Examples:
        >>> maker = SeededEnvMaker(lambda seed: seed, WorkerSeeds(env=7, policy=3))
        >>> with torch.random.fork_rng():  # as in a worker, which owns its generator
        ...     maker(), torch.initial_seed()
        (7, 3)
    """

    make_env: Callable[[int], Any]
    seeds: WorkerSeeds

    def __call__(self) -> Any:
        torch.manual_seed(self.seeds.policy)
        return self.make_env(self.seeds.env)


#: Thread pools a spawned worker would size to the machine at start-up (OpenMP, MKL, OpenBLAS).
_THREAD_VARIABLES = ("OMP_NUM_THREADS", "MKL_NUM_THREADS", "OPENBLAS_NUM_THREADS")


@contextmanager
def _single_threaded_children() -> Iterator[None]:
    """Processes started in the block inherit one-thread pools (their environment is copied at
    start) and ignore the stop signals (their parent shuts them down); this process's
    environment and handlers are restored after."""
    saved = {name: os.environ.get(name) for name in _THREAD_VARIABLES}
    os.environ.update(dict.fromkeys(_THREAD_VARIABLES, "1"))
    try:
        with ignored_signals():
            yield
    finally:
        for name, value in saved.items():
            if value is None:
                os.environ.pop(name, None)
            else:
                os.environ[name] = value


#: Seconds ``shutdown()`` waits for the workers to exit before it kills them (TorchRL's default,
#: 10, is short on a loaded machine; the workers ignore SIGTERM, so TorchRL's terminate step is moot).
WORKER_SHUTDOWN_SECONDS = 60.0


class _PatientMultiSyncCollector(MultiSyncCollector):
    """A :class:`~torchrl.collectors.MultiSyncCollector` whose ``shutdown()`` waits
    :data:`WORKER_SHUTDOWN_SECONDS` for its workers unless told otherwise, and leaves this
    process the torch thread count it had when the collector was built (TorchRL's sets it to
    its own guess: 1 after an ``OMP_NUM_THREADS=1`` start)."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        self._owner_threads = torch.get_num_threads()
        super().__init__(*args, **kwargs)

    def shutdown(self, timeout: float | None = None, close_env: bool = True, raise_on_error: bool = True) -> None:
        try:
            super().shutdown(WORKER_SHUTDOWN_SECONDS if timeout is None else timeout, close_env, raise_on_error)
        finally:
            torch.set_num_threads(self._owner_threads)


def parallel_skill_collector(
    make_env: Callable[[int], EnvBase], seeds: Sequence[WorkerSeeds], actor: nn.Module, frames_per_batch: int, steps: int
) -> MultiSyncCollector:
    """:func:`skill_collector`'s batches from ``len(seeds)`` spawned processes, in lockstep.

    Worker ``i`` builds ``make_env(seeds[i].env)`` (its share of the simulations) after seeding its
    torch generator with ``seeds[i].policy``, and collects ``frames_per_batch / len(seeds)``
    steps per batch; the shares are concatenated along the env dimension, so a batch has the
    same ``[envs, time]`` shape as :func:`skill_collector`'s over all the simulations. The
    workers run one thread each and ignore SIGINT/SIGTERM (this process stops them: call
    ``shutdown()``); this process keeps its thread count. ``actor``'s parameters and buffers
    reach the workers at construction and at each ``update_policy_weights_()``.
    """
    workers = len(seeds)
    if workers < 2 or frames_per_batch % workers:
        raise InvalidValueError(f"need >= 2 workers that divide frames_per_batch ({frames_per_batch}), got {workers}")
    threads = torch.get_num_threads()  # TorchRL would give this process (cores - workers) threads
    with _single_threaded_children():
        return _PatientMultiSyncCollector(
            [SeededEnvMaker(make_env, pair) for pair in seeds],
            actor,
            frames_per_batch=frames_per_batch,
            total_frames=math.ceil(steps / frames_per_batch) * frames_per_batch,
            device="cpu",
            cat_results=0,  # [envs of worker 0; envs of worker 1; ...] x time
            use_buffers=True,
            num_threads=threads,
            num_sub_threads=1,
            auto_register_policy_transforms=False,
        )


class SkillLoop:
    """The bookkeeping after each collected batch of a skill run.

    An evaluation (and a save) follows the batch that crosses a multiple of ``config.eval_every``
    env steps and the last one; otherwise a save follows once ``config.checkpoint_minutes`` have
    passed since the last. The batch's scalars go to a TorchRL CSV logger in the run's ``logs``
    and those named by ``shown`` to the progress bar.

    Args:
        run: the run's folder.
        name: the progress bar's name.
        log_name: the CSV logger's experiment name (the folder below ``logs``).
        config: a skill config (``total_steps``, ``eval_every``, ``checkpoint_minutes``).
        frames_per_batch: env steps per collected batch.
        steps: env steps done before this attempt.
        save: writes the run's checkpoint.
        shown: the scalars the progress bar shows.
        progress_bar: whether to show it.
    """

    def __init__(
        self,
        run: SkillRunDirectory,
        name: str,
        log_name: str,
        config: Any,
        frames_per_batch: int,
        steps: int,
        save: Callable[[], None],
        shown: Collection[str] = ("train_reward", "eval_speed", "eval_fall_rate"),
        progress_bar: bool = True,
    ) -> None:
        self.eval_every, self.total_steps, self.frames_per_batch = config.eval_every, config.total_steps, frames_per_batch
        self.save_seconds = 60 * config.checkpoint_minutes
        self.save, self.shown = save, shown
        self.logger = CSVLogger(exp_name=log_name, log_dir=str(run.path / _LOGS))
        self.bar = progress(config.total_steps, name, "env steps", enabled=progress_bar, initial=steps)
        self.last_save = time.monotonic()

    def after_batch(self, steps: int, done: int, metrics: dict[str, float], evaluate: Callable[[], Mapping[str, float]]) -> bool:
        """Evaluates (adding ``eval_*`` to ``metrics``) or saves as due, logs ``metrics`` at
        ``steps`` and advances the bar by ``done``; returns whether the budget is spent."""
        if steps % self.eval_every < self.frames_per_batch or steps >= self.total_steps:
            metrics.update({f"eval_{name}": value for name, value in evaluate().items()})
            self._save()
        elif time.monotonic() - self.last_save > self.save_seconds:
            self._save()
        for name, value in metrics.items():
            self.logger.log_scalar(name, value, step=steps)
        self.bar.update(done)
        self.bar.set_postfix({k: f"{v:.3g}" for k, v in metrics.items() if k in self.shown})
        return steps >= self.total_steps

    def _save(self) -> None:
        self.save()
        self.last_save = time.monotonic()

    def close(self) -> None:
        """Closes the bar and saves (the last batches since the last save)."""
        self.bar.close()
        self._save()


def add_output_argument(parser: OneLineParser) -> None:
    """The skill command lines' ``--output``: unset, they export to ``<run-dir>/``:data:`EXPORT`."""
    parser.add_argument(
        "--output",
        default=None,
        help="where the best policy body is exported (default: <run-dir>/export.pt; the package's weights only when named)",
    )


def skill_parser(doc: str, skills: Iterable[str], default_skill: str, *, run_dir: str, resume_from: str, steps: str) -> OneLineParser:
    """The options every skill trainer takes: ``--skill``, ``--run-dir``, ``--resume-from``,
    ``--steps``, ``--eval-every``, ``--seed``, ``--output`` and ``--threads`` (``run_dir``,
    ``resume_from`` and ``steps`` are their help lines); each number typed with its bounds."""
    example = "examples:" + doc.rsplit("::", 1)[1] if "::" in doc else None  # the docstring's closing commands
    parser = OneLineParser(description=doc.split("\n\n")[0], epilog=example, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--skill", choices=sorted(skills), default=default_skill)
    parser.add_argument("--run-dir", default=None, help=run_dir)
    parser.add_argument("--resume-from", default=None, help=resume_from)
    parser.add_argument("--steps", type=count, default=None, help=steps)
    parser.add_argument("--eval-every", type=count, default=None, help="env steps between evaluations (and checkpoints)")
    parser.add_argument("--seed", type=non_negative, default=None)
    add_output_argument(parser)
    parser.add_argument("--threads", type=count, default=1, help="torch threads (one is fastest on small CPUs)")
    return parser


@contextmanager
def skill_command(threads: int) -> Iterator[None]:
    """The setting of a skill command's run: its log lines on standard error, ``threads`` torch
    threads, every refusal (a bad value, a foreign folder, a state of another run) in one line,
    and a run stopped by a signal (:class:`~torchrl_causal.experiment.interrupts.RunInterrupted`,
    after it saved its state) in one line with the signal's exit status."""
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(message)s")
    torch.set_num_threads(threads)
    try:
        with one_line_errors(TorchRLCausalError):
            yield
    except RunInterrupted as stop:
        print(f"{stop}: the run saved its state; the same command resumes it", file=sys.stderr)
        raise SystemExit(stop.exit_code) from None


def run_skill_command(threads: int, run_dir: Path, output: str | None, train: Callable[[Path, str | Path], dict[str, Any]]) -> None:
    """Runs ``train(run_dir, output)`` in :func:`skill_command`'s setting, the export going to
    ``<run_dir>/``:data:`EXPORT` unless ``output`` is named, and prints its record as JSON."""
    with skill_command(threads):
        record = train(run_dir, output or run_dir / EXPORT)
    print(json.dumps(record))
