"""A run's lifecycle as library functions: :func:`run` trains, selects and evaluates one
config; :func:`open_run` reopens a run directory with its evaluator and selected policy;
:func:`evaluate_run` evaluates that policy again under new settings.

The command lines (:mod:`torchrl_causal.cli`) are thin wrappers over these.

A run directory belongs to one config (a changed config is refused, naming the changed
keys) and to one process at a time (a second one is refused, naming the first);
calling :func:`run` again on the same config resumes an unfinished run from its last
checkpoint and returns a finished run's stored evaluations. SIGINT or SIGTERM finishes
the training step in flight, checkpoints, marks the run interrupted and raises
:class:`~torchrl_causal.experiment.interrupts.RunInterrupted`.
"""

from __future__ import annotations

import copy
import functools
import logging
import os
import shutil
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import cast

import torch
from hydra.utils import get_class
from omegaconf import DictConfig, OmegaConf
from tensordict.nn import TensorDictModuleBase

from torchrl_causal.data.demonstrations import DatasetError
from torchrl_causal.envs.base import REGIMES, validate_strength
from torchrl_causal.errors import InvalidValueError, MissingDependencyError
from torchrl_causal.evaluation.evaluator import Evaluator
from torchrl_causal.evaluation.metrics import EvaluationResult
from torchrl_causal.evaluation.video import VIDEO_FORMATS, check_can_record
from torchrl_causal.experiment.builders import check_demonstrations, make_env, make_window
from torchrl_causal.experiment.config import register_resolvers
from torchrl_causal.experiment.device import resolve_device
from torchrl_causal.experiment.expert_body import ExpertBodyError, expert_weights_file, recorded_body, resolve_expert_body
from torchrl_causal.experiment.interrupts import RunInterrupted, signals_raise
from torchrl_causal.experiment.memory import check_run_fits
from torchrl_causal.experiment.provenance import AttemptClock, attempt_identity
from torchrl_causal.experiment.run_directory import EXPERT_BODY_KEY, VIDEO_DIR, CheckpointError, RunDirectory
from torchrl_causal.experiment.schema import ConfigValueError, validate_config
from torchrl_causal.experiment.timing import timed
from torchrl_causal.extras import missing_extra
from torchrl_causal.graphs.window import AdjustmentWindow
from torchrl_causal.trainers.base import Trainer
from torchrl_causal.trainers.telemetry import open_run_logger

__all__ = [
    "DEFAULT_THREADS",
    "EVALUATED_DIR",
    "PACKAGE_RESULTS",
    "REGIMES",
    "VIDEO_DIR",
    "evaluate_run",
    "evaluation_home",
    "evaluation_record",
    "evaluation_videos",
    "open_run",
    "record_settings",
    "run",
    "settle_expert_body",
]

log = logging.getLogger("torchrl_causal")

register_resolvers()


@contextmanager
def _run_log(run: RunDirectory) -> Iterator[None]:
    """Copies the package's log records (INFO and up) to ``<run_dir>/train.log``."""
    handler = logging.FileHandler(run.train_log)
    handler.setFormatter(logging.Formatter("[%(asctime)s][%(name)s][%(levelname)s] %(message)s"))
    level = log.level
    log.addHandler(handler)
    if log.getEffectiveLevel() > logging.INFO:
        log.setLevel(logging.INFO)
    try:
        yield
    finally:
        log.removeHandler(handler)
        log.setLevel(level)
        handler.close()


def _first_missing(path: Path) -> Path | None:
    """The outermost folder of ``path`` that does not exist yet (``None``: it exists)."""
    missing = None
    for folder in (path, *path.parents):
        if folder.exists():
            break
        missing = folder
    return missing


def _stored_results(run: RunDirectory) -> dict[str, EvaluationResult]:
    return {
        regime: EvaluationResult.from_dict(run.read_json(run.eval_path(regime))) for regime in REGIMES if run.eval_path(regime).is_file()
    }


def run(cfg: DictConfig) -> dict[str, EvaluationResult]:
    """Trains, selects and evaluates one run of ``cfg``; returns the final evaluation of
    the selected policy in each regime (written to ``eval/<regime>.json``).

    Raises:
        ConfigValueError: a value out of range (nothing is written).
        RenderingUnavailable: ``eval.video`` asks for videos of an env this machine cannot draw (nothing is written).
        DatasetError: demonstrations of another env, missing keys or corrupted (nothing is written).
        ConfigMismatchError: ``cfg.run_dir`` holds a run of another config (nothing is written).
        ForeignFilesError: ``cfg.run_dir`` holds files no run wrote (nothing is written or removed).
        RunInUseError: another process is running ``cfg.run_dir`` (nothing is written).
        RunInterrupted: on SIGINT/SIGTERM/SIGUSR2, after checkpointing and marking the run interrupted.
    """
    clock = AttemptClock()  # the attempt's cost counts from here: window and demonstration checks included
    validate_config(cfg)
    _check_run_root(Path(cfg.run_dir))
    RunDirectory(cfg.run_dir).check_owned()  # a folder of the user's own files is neither cleared nor written into
    trainer_class: type[Trainer] | None = get_class(cfg.algo.trainer) if cfg.algo.trainer else None
    # The run's one window, built on first use (by the memory check when window.k is small, which
    # refuses a run too large before a long window is built) and handed to the trainer and the evaluator.
    run_window = functools.cache(lambda: make_window(cfg))
    check_run_fits(cfg, run_window if trainer_class else None)
    window = run_window() if trainer_class else None
    if cfg.eval.video:
        _check_videos(cfg)  # before training: a machine that cannot draw the env refuses now, not hours later
    total = trainer_class.budget(cfg) if trainer_class else 0
    # The skill body the expert walks, recorded in config.yaml: what re-evaluating the expert row
    # rebuilds, whatever body is the default then (a missing weights file is refused here, before anything is written).
    body = resolve_expert_body(cfg.env.expert)
    run_dir = RunDirectory(cfg.run_dir)
    created = _first_missing(run_dir.path)  # what a failure before any checkpoint removes
    if trainer_class is not None and created is not None:
        # A new run refuses bad demonstrations before its directory exists; an existing one
        # was checked when it started (a changed config is refused by claim, naming the keys).
        check_demonstrations(cfg)
    killed = run_dir.read_status().get("status") == "killed"
    with run_dir.lock():
        if killed and cfg.resume:
            log.warning("%s: its last attempt was killed before it could record its stop; resuming from its last checkpoint", run_dir.path)
        if not cfg.resume:
            run_dir.discard()
            created = created or run_dir.path
        return _claim_and_run(cfg, run_dir, trainer_class, window, total, created, clock, body.to_record())


def _check_videos(cfg: DictConfig) -> None:
    """Draws one small frame of the run's env (``eval.video`` asks for videos).

    Raises:
        RenderingUnavailable: the env has no renderer, or no GL context opens for it.
    """
    env = make_env(cfg, "train", 1, 0)
    try:
        check_can_record(env)
    finally:
        env.close()


def _remove_new_run(run_dir: RunDirectory, created: Path) -> None:
    """Removes what this attempt made of a run that failed before its first checkpoint: the
    run's own entries, then each folder from the run directory up to ``created`` (the
    outermost one it made) that is left empty. Anything else found there stays."""
    run_dir.discard(keep_lock=False)
    for folder in (run_dir.path, *run_dir.path.parents):
        try:
            folder.rmdir()
        except OSError:  # not empty (something that is not the run's), or gone already
            break
        if folder == created:
            break


def _check_run_root(run_dir: Path) -> None:
    """Refuses, before anything is made, a run directory below a file (``run_root=<a file>``),
    below a folder this user cannot write to, or on a file system that holds no files
    (``/proc``, ``/sys``: they report 0 bytes in all, so no disk estimate can be compared)."""
    for folder in (run_dir, *run_dir.parents):
        if folder.exists():
            if not folder.is_dir():
                raise ConfigValueError(
                    f"run_root / run_dir {run_dir} lies below {folder}, which is a file, not a folder: choose another run_root"
                )
            if shutil.disk_usage(folder).total == 0:
                raise ConfigValueError(
                    f"run_root / run_dir {run_dir} lies below {folder}, on a file system that stores no files "
                    "(as /proc and /sys): choose another run_root"
                )
            if not os.access(folder, os.W_OK | os.X_OK):
                raise ConfigValueError(
                    f"run_root / run_dir {run_dir} lies below {folder}, which this user cannot write to: choose another run_root"
                )
            return


def _claim_and_run(
    cfg: DictConfig,
    run_dir: RunDirectory,
    trainer_class: type[Trainer] | None,
    window: AdjustmentWindow | None,
    total: int,
    created: Path | None,
    clock: AttemptClock,
    body: dict[str, str | None],
) -> dict[str, EvaluationResult]:
    extendable = trainer_class is not None and trainer_class.extendable_budget(cfg)
    run_dir.claim(
        cfg, ignored=(trainer_class.budget_key,) if trainer_class is not None and extendable else (), recorded={EXPERT_BODY_KEY: body}
    )
    # The run's config as config.yaml holds it, the body it records included: what the loggers log
    # (on a copy: the caller's config stays as it was composed, valid for its schema).
    cfg = copy.deepcopy(cfg)
    OmegaConf.update(cfg, EXPERT_BODY_KEY, body, merge=False, force_add=True)
    status = run_dir.read_status()
    if status.get("status") == "complete" and status.get("total") == total:
        log.info("%s is complete: its stored evaluations are returned", run_dir.path)
        return _stored_results(run_dir)
    attempt = len(run_dir.read_attempts())  # the index of the attempt this call records
    with _run_log(run_dir), signals_raise():
        try:
            return _train_and_evaluate(cfg, run_dir, trainer_class, window, total)
        except RunInterrupted:
            if run_dir.read_status().get("status") != "interrupted":  # stopped outside the training loop
                run_dir.update_status("interrupted")
            raise
        except (CheckpointError, DatasetError):
            # a file to fix before the run can go on: the run stays as it was (a new one is removed)
            if created is not None and not run_dir.last_checkpoint.is_file():
                _remove_new_run(run_dir, created)
            raise
        except Exception as error:
            if created is not None and not run_dir.last_checkpoint.is_file():
                _remove_new_run(run_dir, created)  # leave no half-made run directory behind
            else:
                run_dir.update_status("failed", error=f"{type(error).__name__}: {error}")
            raise
        finally:  # completed, interrupted or failed (a removed run directory has no attempt left to record it in)
            run_dir.record_attempt_cost(attempt, clock.cost())


def _train_and_evaluate(
    cfg: DictConfig, run_dir: RunDirectory, trainer_class: type[Trainer] | None, window: AdjustmentWindow | None, total: int
) -> dict[str, EvaluationResult]:
    torch.manual_seed(cfg.seed)
    torch.set_num_threads(cfg.threads)
    device = resolve_device(cfg.device)  # once: the trainer and the evaluator share it
    evaluator = Evaluator(cfg, window, progress=cfg.progress_bar, device=device)
    policy = None  # the env's expert
    if trainer_class is None:  # what the trainer records for a trained run: code, packages, CPU, threads
        run_dir.record_attempt(attempt_identity(None, cfg.compile, device), progress=0)
    else:
        window = cast(AdjustmentWindow, window)  # run() makes the window of every trained run
        run_dir.write_json(run_dir.window_file, window.to_dict())
        trainer = trainer_class(cfg, run_dir, window, evaluator.periodic, device=device)
        trainer.fit()
        policy = trainer.best_policy()
    with timed("evaluation"):
        results = _final_evaluation(cfg, run_dir, evaluator, policy, progress=0 if trainer_class is None else trainer.progress)
    for regime, result in results.items():
        run_dir.write_json(run_dir.eval_path(regime), evaluator.record(result))
        log.info(
            "%s [%s] success %.1f%% ± %.1f, E[Y] %.1f ± %.1f, episodes %d",
            cfg.run_dir,
            regime,
            100 * result.success_rate,
            100 * result.success_se,
            result.return_mean,
            result.return_std,
            result.n_episodes,
        )
    run_dir.update_status("complete", total=total, progress=total if trainer_class is None else trainer.progress)
    if trainer_class is not None:
        trainer.finish()
    return results


def _final_evaluation(
    cfg: DictConfig, run_dir: RunDirectory, evaluator: Evaluator, policy: TensorDictModuleBase | None, progress: int
) -> dict[str, EvaluationResult]:
    """The final evaluation; with ``eval.video``, its videos in ``<run_dir>/logs/videos/<regime>/``
    and in the run's logger (opened again: training closed its own), at the run's ``progress``."""
    if not cfg.eval.video:
        return evaluator.final(policy)
    logger = open_run_logger(cfg, run_dir)
    try:
        return evaluator.final(policy, run_dir.video_dir, logger=logger, step=progress)
    finally:
        logger.close()  # flushes TensorBoard's file; W&B finishes the run


DEFAULT_THREADS = 1


def record_settings(episodes: int, seed: int, num_envs: int, confounding_strength: float | None) -> str:
    """The part of a record's name that tells its settings apart.

    Examples:
        >>> record_settings(1000, 30000, 100, None), record_settings(6, 1, 3, 0.5)
        ('n1000-seed30000-envs100', 'n6-seed1-envs3-cs0.5')
    """
    name = f"n{episodes}-seed{seed}-envs{num_envs}"
    return name if confounding_strength is None else f"{name}-cs{confounding_strength:g}"


def open_run(
    run_dir: str | Path,
    *,
    confounding_strength: float | None = None,
    device: str | None = None,
    expert_weights: str | Path | None = None,
) -> tuple[RunDirectory, Evaluator, TensorDictModuleBase | None]:
    """The run directory, an :class:`~torchrl_causal.evaluation.evaluator.Evaluator` of its config and its selected policy
    (``checkpoints/best.pt``; ``None`` for the expert row, which the evaluator rebuilds
    from each env with the skill body its config records: :func:`settle_expert_body`).

    Raises:
        ValueError: naming ``device`` when it is given and this machine lacks it.
        ExpertBodyError: the expert row records no body and ``expert_weights`` names none, or names another.
    """
    run = RunDirectory(run_dir)
    cfg = run.read_config()
    if not cfg.algo.trainer:  # the expert row: the evaluator rebuilds its expert
        settle_expert_body(run, cfg, expert_weights)
    if confounding_strength is not None:
        cfg.env.confounding_strength = float(confounding_strength)
    if device is not None:
        resolved = resolve_device(str(device))
        cfg.device = str(device)
    else:
        try:
            resolved = resolve_device(cfg.device)
        except ValueError:
            cfg.device, resolved = "cpu", torch.device("cpu")
    window = AdjustmentWindow.from_dict(run.read_json(run.window_file)) if cfg.algo.trainer else None
    if window is not None:
        _check_window(run, cfg, window)
    evaluator = Evaluator(cfg, window, progress=True, device=resolved)
    evaluator.check_records(run)
    return run, evaluator, evaluator.load_best_policy(run) if window is not None else None


def settle_expert_body(run: RunDirectory, cfg: DictConfig, expert_weights: str | Path | None = None) -> None:
    """Makes ``cfg`` (``run``'s stored config, in place) record the skill body its expert row
    walked, which :func:`~torchrl_causal.experiment.builders.make_expert` then rebuilds and checks.

    A run that records its body keeps it (``expert_weights``, when given, must name the same
    body). A run made before runs recorded their body (no ``env.expert_body``) is settled only
    where that is certain: an expert that walks no weights file (RoverMaze's) has no body to
    choose; any other is refused unless ``expert_weights`` names the body it walked (a shipped
    body's name, e.g. ``steady``, or a weights file): today's default need not be that run's.

    Raises:
        ExpertBodyError: in one line, naming the field and the override.
    """
    recorded = recorded_body(cfg)
    if expert_weights is not None:
        given = resolve_expert_body(cfg.env.expert, expert_weights)
        if recorded is not None and recorded.sha256 != given.sha256:
            raise ExpertBodyError(
                f"expert_weights={expert_weights} is another body (sha256 {given.sha256}) than the one {run.config_file} "
                f"records ({EXPERT_BODY_KEY}: {recorded.weights}, sha256 {recorded.sha256}): nothing was evaluated; "
                "leave expert_weights out"
            )
        OmegaConf.update(cfg, EXPERT_BODY_KEY, given.to_record(), merge=False, force_add=True)
        return
    if recorded is not None:
        return
    if expert_weights_file(cfg.env.expert) is None:  # a scripted expert: no body to choose, none to record
        OmegaConf.update(cfg, EXPERT_BODY_KEY, {"weights": None, "sha256": None}, merge=False, force_add=True)
        return
    raise ExpertBodyError(
        f"{run.config_file} records no expert body ({EXPERT_BODY_KEY}: the run predates the record), and "
        f"{cfg.env.expert._target_} walks a weights file whose default today need not be the run's: nothing was evaluated; "
        "say which body the run walked with expert_weights=<a shipped body's name, e.g. steady, or a weights file>, "
        f"or add {EXPERT_BODY_KEY} (weights, sha256) to that config.yaml"
    )


def _check_window(run: RunDirectory, cfg: DictConfig, window: AdjustmentWindow) -> None:
    """Refuses a ``window.json`` other than the window the run's config gives (an edited
    window, or a config edited to another env or ``window.k``): the policy reads its inputs
    through that window."""
    try:
        expected = make_window(cfg)
    except ConfigValueError as error:
        raise CheckpointError(f"{run.config_file} no longer gives a window ({error}): it was edited; nothing was evaluated") from None
    if expected.to_dict() != window.to_dict():
        raise CheckpointError(
            f"{run.window_file} is not the window that {run.config_file} gives (window.k {cfg.window.k}, env.name "
            f"{cfg.env.name!r}): one of them was edited; nothing was evaluated; restore the run's files (an archive keeps a copy) "
            "or train the run again"
        )


def _check_evaluation(
    regime: str, episodes: int, num_envs: int | None, trajectories: int, confounding_strength: float | None, video: int = 0
) -> None:
    if regime not in REGIMES:
        raise InvalidValueError(f"regime={regime!r} must be one of {', '.join(REGIMES)}")
    for name, value, least in (
        ("episodes", episodes, 1),
        ("num_envs", num_envs, 1),
        ("trajectories", trajectories, 0),
        ("video", video, 0),
    ):
        if value is not None and int(value) < least:
            raise InvalidValueError(f"{name}={value} is out of range: it must be >= {least}")
    if int(video) > int(episodes):
        raise InvalidValueError(f"video={video} asks for more videos than episodes={episodes}: one video per episode at most")
    if confounding_strength is not None:
        validate_strength(confounding_strength)


def _check_evaluation_videos(video: int, video_format: str, video_every: int, reuse: bool) -> None:
    """``evaluate_run``'s video settings, refused before anything is read or evaluated."""
    if video_format not in VIDEO_FORMATS:
        raise InvalidValueError(f"video_format={video_format!r} must be one of {', '.join(VIDEO_FORMATS)}")
    if int(video_every) < 1:
        raise InvalidValueError(f"video_every={video_every} is out of range: it must be >= 1")
    if reuse:
        raise InvalidValueError(f"video={video} records the episodes of a new evaluation, but reuse=true reads a stored one back: drop one")
    if message := missing_extra(f"video={video} ({video_format})", "imageio", *(("av",) if video_format == "mp4" else ())):
        raise MissingDependencyError(message)


#: The package's own results tree (a git checkout's ``results/``): shipped runs and policies, never written by a command.
PACKAGE_RESULTS = Path(__file__).resolve().parent.parent / "results"
#: Below a run root, where evaluations of runs that are not ours to write into are kept.
EVALUATED_DIR = "evaluated"


def evaluation_home(run_dir: str | Path, run_root: str | Path = "runs") -> Path:
    """The folder whose ``eval/`` receives :func:`evaluate_run`'s records of ``run_dir``.

    The run directory itself when it is ours to write into: writable, holding nothing a
    run did not write (:meth:`~torchrl_causal.experiment.RunDirectory.foreign_entries`) and
    outside the package's results tree. A shipped policy (``results/policies/...``) or a run
    directory of someone else's is read only: its records go below the user's
    ``run_root``, at ``<run_root>/evaluated/<its path below results/>`` or
    ``<run_root>/evaluated/<its run_name>``.

    Examples:
        >>> str(evaluation_home(PACKAGE_RESULTS / "policies/antmaze_medium/h1000-cs1.0-k10/sqil/seed0", "runs"))
        'runs/evaluated/policies/antmaze_medium/h1000-cs1.0-k10/sqil/seed0'
    """
    path = Path(run_dir)
    resolved = path.resolve()
    if resolved.is_relative_to(PACKAGE_RESULTS):
        return Path(run_root) / EVALUATED_DIR / resolved.relative_to(PACKAGE_RESULTS)
    run = RunDirectory(path)
    writable = os.access(path, os.W_OK) and (not (path / "eval").exists() or os.access(path / "eval", os.W_OK))
    if writable and not run.foreign_entries():
        return path
    return Path(run_root) / EVALUATED_DIR / str(run.read_config().run_name)


def _evaluation_settings(
    stored: RunDirectory, episodes: int, num_envs: int | None, seed: int, confounding_strength: float | None
) -> tuple[int, str]:
    """The batch an evaluation of ``stored`` runs at once (``num_envs``, else the run's
    ``eval.num_envs``, at most ``episodes``) and the :func:`record_settings` naming it."""
    batch = min(int(stored.read_config().eval.num_envs if num_envs is None else num_envs), int(episodes))
    return batch, record_settings(int(episodes), int(seed), batch, confounding_strength)


def evaluation_videos(
    run_dir: str | Path,
    regime: str = "deploy",
    episodes: int = 1000,
    *,
    num_envs: int | None = None,
    seed: int = 30_000,
    confounding_strength: float | None = None,
    run_root: str | Path = "runs",
) -> Path:
    """Where :func:`evaluate_run` with these settings and ``video=N`` writes its videos:
    ``logs/videos/<regime>-<settings>/episode_<i>.<format>`` of :func:`evaluation_home`
    (below ``run_root`` for a shipped policy), named as its record is."""
    _, settings = _evaluation_settings(RunDirectory(run_dir), episodes, num_envs, seed, confounding_strength)
    return RunDirectory(evaluation_home(run_dir, run_root)).video_dir / f"{regime}-{settings}"


def evaluation_record(
    run_dir: str | Path,
    regime: str = "deploy",
    episodes: int = 1000,
    *,
    num_envs: int | None = None,
    seed: int = 30_000,
    confounding_strength: float | None = None,
    run_root: str | Path = "runs",
) -> Path:
    """Where :func:`evaluate_run` with these settings writes its record (see :func:`evaluation_home`)."""
    _, settings = _evaluation_settings(RunDirectory(run_dir), episodes, num_envs, seed, confounding_strength)
    return RunDirectory(evaluation_home(run_dir, run_root)).eval_path(regime, settings)


def evaluate_run(
    run_dir: str | Path,
    regime: str = "deploy",
    episodes: int = 1000,
    *,
    num_envs: int | None = None,
    seed: int = 30_000,
    confounding_strength: float | None = None,
    trajectories: int = 0,
    save: bool = True,
    reuse: bool = False,
    device: str | None = None,
    run_root: str | Path = "runs",
    video: int = 0,
    video_format: str | None = None,
    video_every: int | None = None,
    expert_weights: str | Path | None = None,
) -> EvaluationResult:
    """Evaluates the selected policy of ``run_dir`` (see the module docstring); with
    ``reuse=True`` a stored record of the same settings is returned instead. The record is
    written to :func:`evaluation_record` (below ``run_root`` for a shipped policy).

    ``video=N`` records the first ``N`` episodes to :func:`evaluation_videos`, as
    ``video_format`` (default: the run's ``eval.video_format``, else mp4) with a frame every
    ``video_every`` steps (default: the run's ``eval.video_every``, else 1); the result is
    the same with or without them.

    Before evaluating, the run's config, window, weights and final records are checked
    against each other (and against the digests of ``checkpoints/best.json`` when the run
    recorded them): an edited file is refused, not evaluated under the run's name. The expert
    row walks the skill body its config records (``expert_weights``: :func:`settle_expert_body`).

    Raises:
        ValueError: naming ``device`` when it is given and this machine lacks it, or a
            value out of range (``regime``, ``episodes``, ``num_envs``, ``trajectories``,
            ``confounding_strength``, ``video`` above ``episodes``, ``video_format``,
            ``video_every``), or ``video`` with ``reuse=True``.
        MissingDependencyError: ``video`` without the ``[video]`` extra.
        RenderingUnavailable: ``video`` of an env this machine cannot draw.
        CheckpointError: the run's files do not agree with each other.
        ExpertBodyError: the expert row's skill body is not the one it recorded, or it records none.
    """
    _check_evaluation(regime, episodes, num_envs, trajectories, confounding_strength, video)
    stored = RunDirectory(run_dir)
    if video:
        run_eval = stored.read_config().eval
        video_format = str(OmegaConf.select(run_eval, "video_format", default="mp4")) if video_format is None else video_format
        video_every = int(OmegaConf.select(run_eval, "video_every", default=1)) if video_every is None else video_every
        _check_evaluation_videos(video, video_format, video_every, reuse)
    num_envs, settings = _evaluation_settings(stored, episodes, num_envs, seed, confounding_strength)
    record = evaluation_record(
        run_dir, regime, episodes, num_envs=num_envs, seed=seed, confounding_strength=confounding_strength, run_root=run_root
    )
    if reuse:
        for found in (stored.eval_path(regime, settings), record):  # the run's own record first (an archive's)
            if found.is_file():
                return EvaluationResult.from_dict(stored.read_json(found))
    run, evaluator, policy = open_run(run_dir, confounding_strength=confounding_strength, device=device, expert_weights=expert_weights)
    videos = None
    if video:
        _check_videos(evaluator.cfg)  # before evaluating: an env this machine cannot draw is refused now
        folder = evaluation_videos(
            run_dir, regime, episodes, num_envs=num_envs, seed=seed, confounding_strength=confounding_strength, run_root=run_root
        )
        videos = evaluator.videos(folder, count=int(video), fmt=video_format, every=video_every)
    result = evaluator.evaluate(
        policy, regime, int(episodes), int(seed), trajectories=int(trajectories), num_envs=num_envs, observer=videos
    )
    if save:
        run.write_json(record, evaluator.record(result))
    return result
