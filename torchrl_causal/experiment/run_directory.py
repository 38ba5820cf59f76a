"""A run's directory: its layout, status, atomic writes, checkpoints and config identity.

A run directory (``cfg.run_dir``) holds::

    config.yaml              the full resolved config of the run
    window.json              the adjustment window the policy was trained on
    status.json              {"status": "running" | "interrupted" | "failed" | "complete", counters}
    code.json                every attempt's code, data, runtime and cost (:mod:`~torchrl_causal.experiment.provenance`)
                             (read as "killed" when it says running and no process holds .lock)
    train.log                the run's log lines (progress, evaluations, resume, errors)
    checkpoints/last.pt      networks, optimisers, schedulers, RNG states and counters (resume)
    checkpoints/best.pt      the policy with the best train-regime evaluation return
    checkpoints/best.json    digests of best.pt's weights and of the config and window it was
                             trained under (:meth:`RunDirectory.check_policy_identity`)
    .lock                    held (``flock``) by the process running the run; names its pid
    replay/                  the policy replay buffer, memory-mapped (off-policy runs)
    logs/scalars/...csv      TorchRL CSVLogger scalars (``eval/train_return`` = training curve)
    eval/train.json          final evaluation of the best policy in each regime
    eval/deploy.json         (``EvaluationResult`` records); ``python -m torchrl_causal.evaluate``
                             writes its records beside them under names carrying its settings

Every file is written atomically (temporary file in the same folder, then rename), and
checkpoints are read with ``torch.load(..., weights_only=True)``.

A run only ever writes over or removes what it can prove is its own: the entries above
(:data:`RUN_ENTRIES`) of a folder whose ``config.yaml`` is a run's config. A folder that
holds anything else (a user's files, or a ``config.yaml`` that is not a run's) is refused by
:meth:`RunDirectory.check_owned`, naming what it found, before anything is written there:
``resume=false`` then discards nothing, and ``resume=true`` adds no run files among them.

A run directory belongs to one config. :meth:`RunDirectory.claim` compares the config
that determines the result (everything but :data:`RUNTIME_KEYS` and an extendable
budget) with the one stored in ``config.yaml`` and refuses a different one, naming the
changed keys, before anything is written. One process at a time runs it:
:meth:`RunDirectory.lock` refuses a second one (two writers would interleave checkpoints
and replay data), and the operating system releases the lock when its holder exits, so a
killed run leaves no stale lock behind.
"""

from __future__ import annotations

import errno
import fcntl
import hashlib
import json
import math
import os
import re
import shutil
import socket
from collections.abc import Callable, Collection, Iterable, Iterator, Mapping, Sequence
from contextlib import contextmanager
from pathlib import Path
from typing import Any, cast, overload

import torch
from omegaconf import DictConfig, ListConfig, OmegaConf

from torchrl_causal.algorithms import Row
from torchrl_causal.data.demonstrations import tensor_bytes
from torchrl_causal.errors import InvalidValueError, MissingAttributeError, MissingFileError, TorchRLCausalError

__all__ = [
    "CONFIG_FILE",
    "WINDOW_FILE",
    "STATUS_FILE",
    "CODE_FILE",
    "TRAIN_LOG",
    "EVAL_DIR",
    "LOG_DIR",
    "VIDEO_DIR",
    "VIDEO_INDEX",
    "PERIODIC_VIDEOS",
    "TRAIN_CURVE",
    "SUCCESS_CURVE",
    "RUNTIME_KEYS",
    "EXPERT_BODY_KEY",
    "RECORDED_KEYS",
    "RUN_ENTRIES",
    "CheckpointError",
    "CheckpointWriteError",
    "EntryPath",
    "ConfigMismatchError",
    "ForeignFilesError",
    "RunFileError",
    "RunDirectory",
    "RunInUseError",
    "atomic_save",
    "atomic_write_text",
    "carry_runs",
    "check_copy_targets",
    "check_owned",
    "foreign_entries",
    "copy_folders",
    "MOVED_KEYS",
    "MOVED_TARGETS",
    "changed_keys",
    "is_run_config",
    "load_checkpoint",
    "migrate_config",
    "config_digest",
    "policy_digest",
    "run_label",
]

CONFIG_FILE = "config.yaml"
WINDOW_FILE = "window.json"
STATUS_FILE = "status.json"
CODE_FILE = "code.json"
TRAIN_LOG = "train.log"
EVAL_DIR = "eval"
LOG_DIR = "logs"
VIDEO_DIR = "videos"  # below LOG_DIR: evaluation videos (eval.video, evaluate video=N)
VIDEO_INDEX = "videos.csv"  # below LOG_DIR: the CSV logger's record of the videos (step,tag,path rows)
PERIODIC_VIDEOS = "periodic"  # below VIDEO_DIR: the periodic evaluations' videos (eval.video_periodic)
CHECKPOINT_DIR = "checkpoints"
REPLAY_DIR = "replay"
LOCK_FILE = ".lock"
WANDB_DIR = "wandb"  # logger=wandb writes its offline runs here
POLICY_DIGEST_FILE = "best.json"  # beside checkpoints/best.pt: what it was trained under (digests)
TRAIN_CURVE = "eval/train_return"  # scalar logged at every periodic train-regime evaluation
#: the success rate of a periodic evaluation in a regime (``eval/train_success`` is logged
#: beside the training curve; a deploy one where a trainer evaluates in that regime too)
SUCCESS_CURVE = "eval/{regime}_success"

#: Every entry a run writes at the top of its directory, all that ``resume=false`` ever removes.
RUN_ENTRIES: frozenset[str] = frozenset(
    {CONFIG_FILE, WINDOW_FILE, STATUS_FILE, CODE_FILE, TRAIN_LOG, EVAL_DIR, LOG_DIR, CHECKPOINT_DIR, REPLAY_DIR, LOCK_FILE, WANDB_DIR}
)
#: The keys every run's ``config.yaml`` has — what tells it from another program's config.yaml.
_RUN_CONFIG_KEYS = ("algo", "env", "seed", "run_dir")
_TEMPORARY = re.compile(r"^\..+\.tmp\d+$")  # what an atomic write killed midway leaves behind

#: Config keys that change how a run executes or where it writes, never its numbers; they
#: may differ between the attempts of one run (a resume on another machine, more threads).
RUNTIME_KEYS: tuple[str, ...] = (
    "resume",
    "progress_bar",
    "threads",
    "device",
    "compile",
    "log_every",
    "checkpoint_every_s",
    "max_memory_gb",
    "logger",
    "run_root",
    "run_name",
    "run_dir",
    "demos.path",
    # videos of the evaluations: their records are the same with or without them
    "eval.video",
    "eval.video_format",
    "eval.video_every",
    "eval.video_periodic",
)

#: Where a run's ``config.yaml`` records the weights file its expert walks and that file's digest
#: (:mod:`~torchrl_causal.experiment.expert_body`).
EXPERT_BODY_KEY = "env.expert_body"
#: Config keys a run writes of what it resolved from its config, never given by the user (the
#: expert's body). :meth:`RunDirectory.claim` compares them on their own (a run started before
#: they existed records none) and :func:`config_digest` leaves them out, so that a run resumed
#: across their introduction keeps its selected policy's identity; their own digests guard them.
RECORDED_KEYS: tuple[str, ...] = (EXPERT_BODY_KEY,)

#: ``{old dotted key: new dotted key}`` for every config key an earlier layout of the
#: configs wrote under another name. :meth:`RunDirectory.read_config` renames them, so runs
#: on disk and the records archived under ``results/runs`` keep resuming, evaluating and
#: reporting after a move.
MOVED_KEYS: dict[str, str] = {
    # The window's k went paper family -> env.window_k -> window.k; window.k now reads the
    # family's value directly (Route Choice overrides it there), one hop like the others.
    "env.window_k": "env.paper.window_k",
}

#: ``{old dotted path: new dotted path}`` of the code a config names (``_target_``) that moved:
#: the experts left ``envs`` for ``experts``. The old paths still import (archived configs load
#: as they are); :func:`migrate_config` writes the new ones, so a run that a config with the old
#: path started resumes under the shipped config that names the new one.
MOVED_TARGETS: dict[str, str] = {
    **{f"torchrl_causal.envs.{name}": f"torchrl_causal.experts.{name}" for name in ("AntMazeExpert", "HumanoidMazeExpert", "RoverExpert")},
    **{
        f"torchrl_causal.envs.experts.{name}": f"torchrl_causal.experts.{name}"
        for name in ("AntMazeExpert", "HumanoidMazeExpert", "RouteChoiceExpert", "RoverExpert")
    },
    "torchrl_causal.envs.RouteChoiceExpert": "torchrl_causal.experts.RouteChoiceExpert",
}


def migrate_config(
    config: DictConfig, moved: Mapping[str, str] = MOVED_KEYS, moved_targets: Mapping[str, str] = MOVED_TARGETS
) -> DictConfig:
    """``config`` with each key of ``moved`` renamed to its new place and each ``_target_``
    of ``moved_targets`` replaced by its new path (in place; a config without them is left as
    it is). The old key's value wins over one already at the new place: it is the value the
    run used.

    Examples:
        >>> old = OmegaConf.create({"env": {"window_k": 0, "paper": {"window_k": 10}}, "window": {"k": 0}})
        >>> OmegaConf.to_container(migrate_config(old))
        {'env': {'paper': {'window_k': 0}}, 'window': {'k': 0}}
        >>> OmegaConf.to_container(migrate_config(OmegaConf.create({"env": {"paper": {"window_k": 2}}})))
        {'env': {'paper': {'window_k': 2}}}
        >>> old = OmegaConf.create({"env": {"expert": {"_target_": "torchrl_causal.envs.AntMazeExpert", "lookahead": 3}}})
        >>> OmegaConf.to_container(migrate_config(old))
        {'env': {'expert': {'_target_': 'torchrl_causal.experts.AntMazeExpert', 'lookahead': 3}}}
    """
    for old, new in moved.items():
        parent_key, _, leaf = old.rpartition(".")
        parent = OmegaConf.select(config, parent_key) if parent_key else config
        if isinstance(parent, DictConfig) and leaf in parent:
            value = parent[leaf]
            del parent[leaf]
            OmegaConf.update(config, new, value, merge=False, force_add=True)
    _rename_targets(config, moved_targets)
    return config


def _rename_targets(node: object, moved: Mapping[str, str]) -> None:
    """Replaces, in place, every ``_target_`` of the config tree ``node`` that ``moved`` names."""
    if isinstance(node, DictConfig):
        for key, value in node.items_ex(resolve=False):
            if key == "_target_" and isinstance(value, str) and value in moved:
                node[key] = moved[value]
            else:
                _rename_targets(value, moved)
    elif isinstance(node, ListConfig):
        for value in node:
            _rename_targets(value, moved)


class CheckpointError(TorchRLCausalError, RuntimeError):
    """A checkpoint that cannot be read or does not belong to this run."""


class CheckpointWriteError(TorchRLCausalError, OSError):
    """A checkpoint that cannot be written (a full disk, a file size limit): an ``OSError``
    whose ``filename`` is the checkpoint's path, so a command's one line names it."""


class RunFileError(TorchRLCausalError, ValueError):
    """A file of a run directory that does not parse (truncated, edited, or not the run's)."""


def _first_line(error: BaseException, limit: int = 100) -> str:
    text = " ".join(str(error).split()) or type(error).__name__
    return text if len(text) <= limit else text[:limit] + "..."


class ConfigMismatchError(TorchRLCausalError, ValueError):
    """A run directory holds a run of a different config."""


class RunInUseError(TorchRLCausalError, RuntimeError):
    """Another process is running this run directory."""


class ForeignFilesError(TorchRLCausalError, ValueError):
    """A folder holds files that no run of this package wrote: they are never written over or removed."""


def is_run_config(path: str | os.PathLike) -> bool:
    """Whether ``path`` is a run's ``config.yaml``: a YAML mapping with the keys every run's
    config has (``algo``, ``env``, ``seed``, ``run_dir``). A ``config.yaml`` of another program
    (or a corrupted one) is not, and nothing beside it is a run's to remove.

    Examples:
        >>> import tempfile, pathlib
        >>> path = pathlib.Path(tempfile.mkdtemp()) / "config.yaml"
        >>> _ = path.write_text("algo: {name: bc}\\nenv: {name: u}\\nseed: 0\\nrun_dir: runs/x")
        >>> is_run_config(path)
        True
        >>> _ = path.write_text("model: resnet50")
        >>> is_run_config(path)
        False
    """
    try:
        config = OmegaConf.load(Path(path))
    except Exception:  # noqa: BLE001 -- unreadable or not YAML: not provably a run's
        return False
    return isinstance(config, DictConfig) and all(key in config for key in _RUN_CONFIG_KEYS)


def _digest(record: Any) -> str:
    return hashlib.sha256(json.dumps(record, sort_keys=True, default=str).encode()).hexdigest()


def config_digest(config: Mapping[str, Any], ignored: Iterable[str] = ()) -> str:
    """SHA-256 of the part of ``config`` that determines a run's result (:data:`RUNTIME_KEYS`
    and ``ignored`` aside; a key set to an off value counts as absent, as in :func:`changed_keys`).

    Examples:
        >>> config_digest({"seed": 0, "resume": True}) == config_digest({"seed": 0, "drop": [], "resume": False})
        True
        >>> config_digest({"seed": 0}) == config_digest({"seed": 1})
        False
    """

    def off(value: Any) -> bool:
        return value is None or value is False or (isinstance(value, (list, dict)) and not value)

    return _digest({key: value for key, value in _identity(config, (*RUNTIME_KEYS, *RECORDED_KEYS, *ignored)).items() if not off(value)})


def policy_digest(policy_state: Mapping[str, Any]) -> str:
    """SHA-256 over a policy's state dict (names, dtypes, shapes and bytes), independent of the
    file that holds it: a copy of ``best.pt`` (an archive re-saves it) keeps its digest.

    Examples:
        >>> a = {"w": torch.zeros(2, 3)}
        >>> policy_digest(a) == policy_digest({"w": torch.zeros(2, 3)}), policy_digest(a) == policy_digest({"w": torch.ones(2, 3)})
        (True, False)
    """
    digest = hashlib.sha256()
    for name, value in sorted(policy_state.items()):
        digest.update(f"{name}:{value.dtype}:{tuple(value.shape)}".encode())
        digest.update(tensor_bytes(value))
    return digest.hexdigest()


def run_label(algorithm: str, causal: bool, window_matched: bool = False, drop: Sequence[str] = ()) -> str:
    """The algorithm's name in tables and run directories: ``c_sqil``, ``sqil``, ``expert``.

    A window with variables dropped (``window.drop``, an ablation) ends in ``_no-`` and
    their names, so that its runs never share a directory with the full window's.

    Examples:
        >>> run_label("iq_learn", True), run_label("bc", False), run_label("expert", False)
        ('c_iq_learn', 'bc', 'expert')
        >>> run_label("sqil", False, window_matched=True), run_label("bc", True, drop=["X"])
        ('sqil_wm', 'c_bc_no-X')
    """
    if causal and window_matched and algorithm != "expert":
        raise InvalidValueError("window.window_matched=true is a non-causal baseline: use it with causal=false")
    return Row(algorithm, causal, window_matched, tuple(drop)).name


def _temporary(path: Path) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    return path.with_name(f".{path.name}.tmp{os.getpid()}")


def atomic_write_text(path: Path, text: str) -> None:
    """Writes ``text`` to a temporary file beside ``path``, then renames it over ``path``."""
    tmp = _temporary(path)
    tmp.write_text(text)
    os.replace(tmp, path)


def atomic_save(obj: Any, path: Path) -> None:
    """``torch.save`` to a temporary file in the same folder, then rename over ``path``:
    an interrupted save leaves the previous checkpoint intact.

    Raises:
        CheckpointWriteError: naming ``path``, when the file cannot be written (a full disk,
            a file size limit): torch reports those as a ``RuntimeError`` that names no file.
    """
    tmp = _temporary(path)
    try:
        torch.save(obj, tmp)
    except (OSError, RuntimeError) as error:
        tmp.unlink(missing_ok=True)
        reason = (str(error).splitlines() or [type(error).__name__])[0]
        message = f"cannot write this checkpoint (a full disk or a file size limit?): {reason}"
        raise CheckpointWriteError(errno.EIO, message, str(path)) from error
    os.replace(tmp, path)


def _checkpoint_remedy(path: Path) -> str:
    if path.name == "best.pt":
        return (
            "nothing was changed; it is the run's selected policy, which only training selects again: train the "
            "run again with its command and resume=false"
        )
    return (
        "nothing was changed; delete it and rerun the run's command with resume=false to train it again from "
        "the start (best.pt holds the selected policy only, which cannot resume training)"
    )


def load_checkpoint(path: Path, map_location: str | torch.device = "cpu") -> dict[str, Any]:
    """``torch.load(..., weights_only=True)`` onto ``map_location``, with an error that
    names the file. A checkpoint written on a GPU loads on a machine without one; a missing file
    is refused as missing (``FileNotFoundError``), not as corrupted."""
    if not Path(path).is_file():
        raise MissingFileError(f"no checkpoint at {path}")
    try:
        state = torch.load(path, map_location=map_location, weights_only=True)
    except Exception as err:  # pickle, zip and unpickler errors all mean the same here
        raise CheckpointError(
            f"checkpoint {path} is corrupted or not a torchrl-causal checkpoint ({type(err).__name__}): {_checkpoint_remedy(path)}"
        ) from err
    if not isinstance(state, dict) or "progress" not in state:
        raise CheckpointError(f"checkpoint {path} lacks the 'progress' entry of a torchrl-causal checkpoint: {_checkpoint_remedy(path)}")
    return state


def _flatten(node: Any, prefix: str = "") -> dict[str, Any]:
    if isinstance(node, Mapping):
        flat: dict[str, Any] = {}
        for key, value in node.items():
            flat.update(_flatten(value, f"{prefix}{key}."))
        return flat
    return {prefix[:-1]: node}


def _identity(config: Mapping[str, Any], ignored: Iterable[str]) -> dict[str, Any]:
    ignored = tuple(ignored)
    return {key: value for key, value in _flatten(config).items() if not any(key == skip or key.startswith(f"{skip}.") for skip in ignored)}


def changed_keys(old: Mapping[str, Any], new: Mapping[str, Any], ignored: Iterable[str] = RUNTIME_KEYS) -> dict[str, tuple[Any, Any]]:
    """``{key: (old value, new value)}`` for every leaf that differs, ``ignored`` keys aside
    (a key absent on one side shows as ``<absent>``).

    A key absent on one side and off on the other (``None``, ``[]``, ``{}``, ``False``) is no
    change: an option added to the configs later (``window.drop``, ``demos.successful_only``)
    is off exactly when it does what its absence did, so run directories made before it
    existed stay resumable.

    Examples:
        >>> changed_keys({"algo": {"lr": 0.1, "n": 2}, "resume": True},
        ...              {"algo": {"lr": 0.2, "n": 2, "new": 1}, "resume": False})
        {'algo.lr': (0.1, 0.2), 'algo.new': ('<absent>', 1)}
        >>> changed_keys({"window": {"k": 2}}, {"window": {"k": 2, "drop": []}, "demos": {"successful_only": False}})
        {}
        >>> changed_keys({"seed": 0}, {"seed": 0, "demos": {"successful_only": True}, "n": 0})
        {'demos.successful_only': ('<absent>', True), 'n': ('<absent>', 0)}
    """
    before, after = _identity(old, ignored), _identity(new, ignored)
    absent = "<absent>"

    def off(value: Any) -> bool:
        # `is False`: 0 == False, and a new numeric key set to 0 is a change
        return value is None or value is False or (isinstance(value, (list, dict)) and not value)

    def same(a: Any, b: Any) -> bool:
        return a == b or (a is absent and off(b)) or (b is absent and off(a))

    pairs = {key: (before.get(key, absent), after.get(key, absent)) for key in sorted(set(before) | set(after))}
    return {key: pair for key, pair in pairs.items() if not same(*pair)}


def _json_remedy(path: Path) -> str:
    if path.name == STATUS_FILE:
        return "delete it and rerun the run's command: it resumes from its last checkpoint"
    if path.name == WINDOW_FILE:
        return "delete it and rerun the run's command (resume=true rewrites it), or restore it from an archive"
    return "delete it and rerun the command that wrote it (evaluate, or the run's own command), or restore it from an archive"


def foreign_entries(
    folder: Path, entries: Collection[str], marker: Path, is_marker: Callable[[Path], bool], inert: Collection[str] = ()
) -> list[Path]:
    """What ``folder`` holds that its program did not write: the package's one rule of ownership,
    shared by run directories and the skill trainers' run folders.

    A program owns the top-level ``entries`` it writes (and the temporaries an atomic write
    killed midway leaves), and only in a folder whose ``marker`` file it wrote (``is_marker``
    tells its own from another program's file of that name). Everything is foreign in a
    folder that holds more than the ``inert`` entries (a lock) without such a marker: nothing
    proves it the program's. A missing folder holds nothing foreign.

    Examples:
        >>> import tempfile
        >>> folder = Path(tempfile.mkdtemp())
        >>> _ = (folder / "log.txt").write_text("..."); _ = (folder / "notes.md").write_text("...")
        >>> [p.name for p in foreign_entries(folder, {"log.txt", "config.json"}, folder / "config.json", Path.is_file)]
        ['notes.md']
        >>> (folder / "notes.md").unlink()
        >>> [p.name for p in foreign_entries(folder, {"log.txt", "config.json"}, folder / "config.json", Path.is_file)]
        ['log.txt']
    """
    if not folder.is_dir():
        return []
    found = sorted(folder.iterdir())
    foreign = [entry for entry in found if entry.name not in entries and not _TEMPORARY.match(entry.name)]
    if foreign:
        return foreign
    written = [entry for entry in found if entry.name not in inert and not _TEMPORARY.match(entry.name)]
    return written if written and not is_marker(marker) else []


def check_owned(folder: Path, foreign: Callable[[], list[Path]], remedy: str) -> None:
    """Refuses ``folder`` when it is a file or ``foreign()`` (its :func:`foreign_entries`)
    names anything, naming up to three of them and ``remedy`` (what to do instead).

    Raises:
        ForeignFilesError: before anything is written or removed.
    """
    if folder.exists() and not folder.is_dir():
        raise ForeignFilesError(f"{folder} is a file, not a run directory: nothing was changed; {remedy}")
    found = foreign()
    if found:
        shown = ", ".join(entry.name for entry in found[:3]) + (f" and {len(found) - 3} more" if len(found) > 3 else "")
        raise ForeignFilesError(f"{folder} is not a run directory (it holds {shown}, which no run wrote): nothing was changed; {remedy}")


class EntryPath:
    """A read-only attribute of a run folder: ``EntryPath("a", "b")`` reads ``self.path / "a" / "b"``.

    One declaration per entry, so that each folder class names its files in one line each
    (:class:`RunDirectory`, :class:`~torchrl_causal.experts.skill_run.SkillRunDirectory`).
    The owner keeps its folder in ``self.path``.

    Examples:
        >>> class Folder:
        ...     log = EntryPath("logs", "train.log")
        ...     def __init__(self, path):
        ...         self.path = Path(path)
        >>> Folder("runs/x").log.as_posix()
        'runs/x/logs/train.log'
        >>> Folder("runs/x").log = "elsewhere"
        Traceback (most recent call last):
        ...
        torchrl_causal.errors.MissingAttributeError: log is the path of an entry below the folder; it cannot be set
    """

    def __init__(self, *parts: str) -> None:
        self.parts = parts
        self.name = "/".join(parts)

    def __set_name__(self, owner: type, name: str) -> None:
        self.name = name

    @overload
    def __get__(self, instance: None, owner: type | None = None) -> EntryPath: ...
    @overload
    def __get__(self, instance: object, owner: type | None = None) -> Path: ...
    def __get__(self, instance: Any, owner: type | None = None) -> Path | EntryPath:
        if instance is None:
            return self
        return Path(instance.path).joinpath(*self.parts)

    def __set__(self, instance: object, value: object) -> None:
        # A data descriptor, so that an assignment is refused as a property's would be.
        raise MissingAttributeError(f"{self.name} is the path of an entry below the folder; it cannot be set")


class RunDirectory:
    """The files of one run (see the module docstring).

    Args:
        path: the run directory (``cfg.run_dir``); nothing is created until a write.
    """

    def __init__(self, path: str | os.PathLike) -> None:
        self.path = Path(path)

    def __repr__(self) -> str:
        return f"RunDirectory({str(self.path)!r})"

    # ------------------------------------------------------------------ paths

    config_file = EntryPath(CONFIG_FILE)
    window_file = EntryPath(WINDOW_FILE)
    status_file = EntryPath(STATUS_FILE)
    code_file = EntryPath(CODE_FILE)
    train_log = EntryPath(TRAIN_LOG)
    log_dir = EntryPath(LOG_DIR)
    replay_dir = EntryPath(REPLAY_DIR)
    lock_file = EntryPath(LOCK_FILE)
    policy_identity_file = EntryPath(CHECKPOINT_DIR, POLICY_DIGEST_FILE)
    train_curve_file = EntryPath(LOG_DIR, "scalars", f"{TRAIN_CURVE}.csv")
    last_checkpoint = EntryPath(CHECKPOINT_DIR, "last.pt")
    best_checkpoint = EntryPath(CHECKPOINT_DIR, "best.pt")

    @property
    def video_dir(self) -> Path:
        """Evaluation videos: ``<regime>/`` (the final evaluation), ``periodic/step_<n>/``,
        ``evaluated/<regime>-<settings>/`` (``python -m torchrl_causal.evaluate video=N``)."""
        return self.log_dir / VIDEO_DIR

    def periodic_video_dir(self, step: int) -> Path:
        """The videos of the periodic evaluation at ``step`` (``eval.video_periodic``)."""
        return self.video_dir / PERIODIC_VIDEOS / f"step_{step}"

    def success_curve_file(self, regime: str) -> Path:
        """The periodic evaluations' success rates in ``regime`` (a CSVLogger scalar file)."""
        return self.log_dir / "scalars" / f"{SUCCESS_CURVE.format(regime=regime)}.csv"

    def eval_path(self, regime: str, settings: str | None = None) -> Path:
        """Where an evaluation record lives: ``eval/<regime>.json`` for the final evaluation
        of training, ``eval/<regime>-<settings>.json`` for any other."""
        return self.path / EVAL_DIR / (f"{regime}.json" if settings is None else f"{regime}-{settings}.json")

    def record_files(self) -> list[Path]:
        """The files that exist of the run's record: config, window, status, every
        evaluation record and the periodic evaluations' scalars (the training curve among
        them); what reports read back, without the checkpoints, replay data and training
        logs that training and re-evaluation need."""
        files = [
            self.config_file,
            self.window_file,
            self.status_file,
            self.code_file,
            *sorted((self.path / EVAL_DIR).glob("*.json")),
            *sorted(self.train_curve_file.parent.glob("*.csv")),
        ]
        return [path for path in files if path.is_file()]

    # ------------------------------------------------------------------ config

    def read_config(self) -> DictConfig:
        """``config.yaml``, in the current layout of the configs (:func:`migrate_config`).

        Raises:
            FileNotFoundError: the directory holds no run.
            ~torchrl_causal.experiment.run_directory.RunFileError: ``config.yaml`` does not parse.
        """
        if not self.config_file.is_file():
            raise MissingFileError(f"{self.path} is not a run directory: {CONFIG_FILE} is missing")
        try:
            config = OmegaConf.load(self.config_file)
        except Exception as error:  # YAML scanner and parser errors, OmegaConf's own
            raise RunFileError(
                f"{self.config_file} is corrupted ({_first_line(error)}): restore it (an archive "
                "under results/runs keeps a copy) or train the run again"
            ) from None
        if not isinstance(config, DictConfig):
            raise RunFileError(f"{self.config_file} is corrupted (not a mapping): restore it or train the run again")
        return migrate_config(config)

    def claim(self, cfg: DictConfig, ignored: Iterable[str] = (), recorded: Mapping[str, Any] | None = None) -> None:
        """Makes this directory the run of ``cfg``, refusing another run's directory.

        Compares ``cfg`` (resolved) with ``config.yaml``, :data:`RUNTIME_KEYS`, :data:`RECORDED_KEYS`
        and ``ignored`` aside, and writes ``config.yaml`` only when they agree or none exists.
        ``recorded`` (``{dotted key of RECORDED_KEYS: value}``) is what the run resolved from
        ``cfg`` (its expert's body): a stored config that records another value is refused; one
        that records none gets it, unless the run is complete (a finished run was made with
        files of its day, which today's need not be: it stays without the record).

        Raises:
            ConfigMismatchError: naming every key whose value differs.
        """
        # The containers of DictConfigs are dicts keyed by the config's (string) keys.
        resolved = cast(dict[str, Any], OmegaConf.to_container(cfg, resolve=True, enum_to_str=True))
        recorded = dict(recorded or {})
        if unknown := sorted(set(recorded) - set(RECORDED_KEYS)):
            raise InvalidValueError(f"claim(recorded=...) names {unknown[0]!r}, which is not one of RECORDED_KEYS {RECORDED_KEYS}")
        if self.config_file.is_file():
            stored_config = self.read_config()
            stored = cast(dict[str, Any], OmegaConf.to_container(stored_config))
            changes = changed_keys(stored, resolved, (*RUNTIME_KEYS, *RECORDED_KEYS, *ignored))
            complete = self.read_status().get("status") == "complete"
            for key, value in list(recorded.items()):
                before = OmegaConf.select(stored_config, key)
                before = OmegaConf.to_container(before) if isinstance(before, DictConfig) else before
                if before is None and complete:
                    del recorded[key]
                elif before is not None and before != value:
                    changes[key] = (before, value)
            if changes:
                listed = "; ".join(f"{key}: {old!r} -> {new!r}" for key, (old, new) in changes.items())
                raise ConfigMismatchError(
                    f"{self.path} holds a run of another config ({listed}). Nothing was changed: choose another "
                    "run_root or run_name, or pass resume=false to discard that run and start this one there."
                )
        config = OmegaConf.create(resolved)
        for key, value in recorded.items():
            OmegaConf.update(config, key, value, merge=False, force_add=True)
        atomic_write_text(self.config_file, OmegaConf.to_yaml(config))

    def _ours(self, entry: Path) -> bool:
        return entry.name in RUN_ENTRIES or bool(_TEMPORARY.match(entry.name))

    def foreign_entries(self) -> list[Path]:
        """What this folder holds that no run wrote (empty for a run directory, a missing or
        an empty folder, or one a killed run left with its lock alone): :func:`foreign_entries`
        of :data:`RUN_ENTRIES`, proven by a run's ``config.yaml`` (:func:`is_run_config`).

        Examples:
            >>> import tempfile
            >>> run = RunDirectory(tempfile.mkdtemp())
            >>> _ = (run.path / "thesis.tex").write_text("...")
            >>> [p.name for p in run.foreign_entries()]
            ['thesis.tex']
        """
        return foreign_entries(self.path, RUN_ENTRIES, self.config_file, is_run_config, inert=(LOCK_FILE,))

    def check_owned(self, remedy: str = "choose another run_root or run_name (a missing or empty folder)") -> None:
        """Refuses a folder that holds anything no run wrote (:meth:`foreign_entries`), naming
        it and ``remedy`` (what to do instead).

        Raises:
            ForeignFilesError: before anything is written or removed.
        """
        check_owned(self.path, self.foreign_entries, remedy)

    def discard(self, keep_lock: bool = True) -> None:
        """Removes everything a previous attempt wrote (``resume=false``), the lock file aside
        unless ``keep_lock`` is false; only the run's own entries (:data:`RUN_ENTRIES`), and only
        in a folder :meth:`check_owned` accepts.

        Raises:
            ForeignFilesError: the folder holds anything else (nothing is removed).
        """
        if not self.path.is_dir():
            return
        self.check_owned()
        for entry in self.path.iterdir():
            if (entry.name == LOCK_FILE and keep_lock) or not self._ours(entry):
                continue
            if entry.is_dir() and not entry.is_symlink():
                shutil.rmtree(entry)
            else:
                entry.unlink()

    @contextmanager
    def lock(self) -> Iterator[None]:
        """Holds the run for this process: a second process that asks for it is refused.

        An exclusive ``flock`` on ``<run_dir>/.lock`` (which records the holder's pid and
        host); the kernel drops it when the holder exits, however it exits. On a network
        file system this is only as reliable as the file system's ``flock``.

        Raises:
            RunInUseError: another process holds the lock (named in the message).

        Examples:
            >>> import tempfile
            >>> run = RunDirectory(tempfile.mkdtemp())
            >>> with run.lock():
            ...     try:
            ...         with run.lock():
            ...             pass
            ...     except RunInUseError as error:
            ...         print("refused")
            refused
        """
        self.path.mkdir(parents=True, exist_ok=True)
        handle = open(self.lock_file, "a+")
        try:
            fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            handle.seek(0)
            holder = handle.read().strip() or "a process that did not record itself"
            handle.close()
            raise RunInUseError(
                f"{self.path} is being run by {holder}. Wait for it to finish, or stop it (it checkpoints on "
                "SIGTERM), then rerun this command to resume."
            ) from None
        try:
            handle.truncate(0)
            handle.write(f"pid {os.getpid()} on {socket.gethostname()}\n")
            handle.flush()
            yield
        finally:
            fcntl.flock(handle, fcntl.LOCK_UN)
            handle.close()

    # ------------------------------------------------------------------ status

    def is_held(self) -> bool:
        """Whether a process (this one included) holds :meth:`lock` now.

        Examples:
            >>> import tempfile
            >>> run = RunDirectory(tempfile.mkdtemp())
            >>> with run.lock():
            ...     print(run.is_held())
            True
            >>> run.is_held()
            False
        """
        if not (self.path / LOCK_FILE).is_file():
            return False
        with open(self.path / LOCK_FILE) as handle:
            try:
                fcntl.flock(handle, fcntl.LOCK_SH | fcntl.LOCK_NB)
            except BlockingIOError:
                return True
            fcntl.flock(handle, fcntl.LOCK_UN)
            return False

    def read_status(self) -> dict[str, Any]:
        """``status.json`` (``{}`` before the first write), told apart from a dead writer.

        A run whose process was killed outright (SIGKILL, a machine that stopped) never
        records its stop, so its file still says ``"running"``; when no process holds the
        lock, the status read here is ``"killed"`` instead, and a rerun resumes it from its
        last checkpoint.

        Examples:
            >>> import tempfile
            >>> run = RunDirectory(tempfile.mkdtemp())
            >>> run.write_status("running", progress=40)
            >>> run.read_status()
            {'status': 'killed', 'progress': 40}
            >>> with run.lock():
            ...     print(run.read_status()["status"])
            running
        """
        status = self.read_json(self.status_file) if self.status_file.is_file() else {}
        if status.get("status") == "running" and not self.is_held():
            status["status"] = "killed"
        return status

    def write_status(self, status: str, **fields: Any) -> None:
        """Replaces ``status.json`` with ``status`` and ``fields`` (infinite floats become null)."""
        fields = {k: None if isinstance(v, float) and math.isinf(v) else v for k, v in fields.items()}
        atomic_write_text(self.status_file, json.dumps({"status": status, **fields}, indent=2))

    def update_status(self, status: str, **fields: Any) -> None:
        """Like :meth:`write_status`, keeping the fields already recorded."""
        self.write_status(status, **{**{k: v for k, v in self.read_status().items() if k != "status"}, **fields})

    def read_attempts(self) -> list[dict[str, Any]]:
        """Every attempt recorded by :meth:`record_attempt`, oldest first."""
        return self.read_json(self.code_file)["attempts"] if self.code_file.is_file() else []

    def record_attempt(self, identity: Mapping[str, Any], progress: int) -> dict[str, Any] | None:
        """Appends an attempt that starts at ``progress`` under ``identity`` (what
        :func:`~torchrl_causal.experiment.provenance.attempt_identity` returns) to ``code.json``;
        returns the attempt before it, ``None`` for the first.

        Examples:
            >>> import tempfile
            >>> run = RunDirectory(tempfile.mkdtemp())
            >>> run.record_attempt({"source": "a"}, progress=0) is None
            True
            >>> run.record_attempt({"source": "b"}, progress=40)
            {'progress': 0, 'source': 'a'}
        """
        attempts = self.read_attempts()
        self.write_json(self.code_file, {"attempts": [*attempts, {"progress": progress, **identity}]})
        return attempts[-1] if attempts else None

    def record_attempt_cost(self, index: int, cost: Mapping[str, float]) -> bool:
        """Adds ``cost`` (what :meth:`~torchrl_causal.experiment.provenance.AttemptClock.cost`
        returns) to the attempt ``index`` of ``code.json`` (0 for the first); returns
        ``False``, writing nothing, when there is no such attempt (a run that failed before
        it recorded one, or whose directory was removed).

        Examples:
            >>> import tempfile
            >>> run = RunDirectory(tempfile.mkdtemp())
            >>> run.record_attempt_cost(0, {"wall_s": 2.0, "cpu_s": 1.5})
            False
            >>> _ = run.record_attempt({"source": "a"}, progress=0)
            >>> run.record_attempt_cost(0, {"wall_s": 2.0, "cpu_s": 1.5})
            True
            >>> run.read_attempts()
            [{'progress': 0, 'source': 'a', 'wall_s': 2.0, 'cpu_s': 1.5}]
        """
        attempts = self.read_attempts()
        if not 0 <= index < len(attempts):
            return False
        attempts[index] = {**attempts[index], **cost}
        self.write_json(self.code_file, {"attempts": attempts})
        return True

    # ------------------------------------------------------------------ records

    def write_json(self, path: Path, record: Mapping[str, Any]) -> None:
        atomic_write_text(path, json.dumps(record))

    def read_json(self, path: Path) -> dict[str, Any]:
        """A JSON record of the run (``status.json``, ``window.json``, ``eval/*.json``...).

        Raises:
            ~torchrl_causal.experiment.run_directory.RunFileError: naming the file, when it does not parse or is not an object.
        """
        try:
            record = json.loads(path.read_text())
        except (json.JSONDecodeError, UnicodeDecodeError) as error:
            raise RunFileError(f"{path} is corrupted ({_first_line(error)}): {_json_remedy(path)}") from None
        if not isinstance(record, dict):
            raise RunFileError(f"{path} is corrupted (not a JSON object): {_json_remedy(path)}")
        return record

    # ------------------------------------------------------------------ checkpoints

    def save_checkpoint(self, state: Mapping[str, Any], best: bool = False, ignored: Iterable[str] = ()) -> None:
        """Writes the last checkpoint, or with ``best`` the selected policy and its identity
        (:meth:`policy_identity`, ``ignored`` naming the config keys a longer budget may change)."""
        atomic_save(dict(state), self.best_checkpoint if best else self.last_checkpoint)
        if best and self.config_file.is_file():  # a trainer driven without a run's config records no identity
            self.write_json(self.policy_identity_file, self.policy_identity(state["policy"], ignored))

    def policy_identity(self, policy_state: Mapping[str, Any], ignored: Iterable[str] = ()) -> dict[str, Any]:
        """Digests of a policy's weights and of the config and window of this directory
        (:func:`policy_digest`, :func:`config_digest`): what ``checkpoints/best.json`` records."""
        ignored = sorted(ignored)
        return {
            "policy": policy_digest(policy_state),
            # The file as written, not migrated (read_config's layout): a move of a class the config
            # names changes the layout, not the config the policy was selected under.
            "config": config_digest(cast(dict[str, Any], OmegaConf.to_container(OmegaConf.load(self.config_file))), ignored),
            "window": _digest(self.read_json(self.window_file)) if self.window_file.is_file() else None,
            "config_ignored": ignored,
        }

    def check_policy_identity(self, policy_state: Mapping[str, Any]) -> None:
        """Refuses a selected policy whose weights, config or window differ from those
        ``checkpoints/best.json`` recorded when it was selected (a run without that file,
        trained before it existed, passes).

        Raises:
            CheckpointError: naming what changed.
        """
        if not self.policy_identity_file.is_file():
            return
        recorded = self.read_json(self.policy_identity_file)
        current = self.policy_identity(policy_state, recorded.get("config_ignored", ()))
        changed = [
            {"policy": str(self.best_checkpoint.relative_to(self.path)), "config": CONFIG_FILE, "window": WINDOW_FILE}[key]
            for key in ("policy", "config", "window")
            if recorded.get(key) != current[key]
        ]
        if changed:
            raise CheckpointError(
                f"{self.path}: {' and '.join(changed)} changed since its policy was selected (the digests in "
                f"{self.policy_identity_file.relative_to(self.path)} differ): nothing was evaluated; restore the run's "
                "files (an archive keeps a copy) or train the run again"
            )

    def load_checkpoint(self, best: bool = False, map_location: str | torch.device = "cpu") -> dict[str, Any] | None:
        """The last (or best) checkpoint loaded onto ``map_location``, ``None`` when there is none."""
        path = self.best_checkpoint if best else self.last_checkpoint
        return load_checkpoint(path, map_location) if path.is_file() else None


def copy_folders(root: str | Path, out: str | Path) -> tuple[Path, Path]:
    """``root`` (runs to copy) and ``out`` (where to), resolved; refused when ``root`` is
    missing (``FileNotFoundError``) or one contains the other, equal folders included (``ValueError``)."""
    root, out = Path(root).resolve(), Path(out).resolve()
    if not root.exists():
        raise MissingFileError(f"runs folder {root} does not exist")
    if out.is_relative_to(root) or root.is_relative_to(out):
        raise InvalidValueError(f"copy folder {out} and runs folder {root} must not contain one another")
    return root, out


def check_copy_targets(targets: Iterable[Path]) -> None:
    """Refuses a copy (an archive, a carry) whose target run directories hold anything no
    run wrote (:meth:`RunDirectory.check_owned`), before the first file is copied: a copy
    writes over, and removes, only a run's own files.

    Raises:
        ForeignFilesError: naming the target and what it holds.
    """
    for target in targets:
        RunDirectory(target).check_owned("nothing was copied: choose another out (a missing folder, or one holding runs only)")


def carry_runs(root: str | Path, out: str | Path) -> list[Path]:
    """Copies every run below ``root`` that has a checkpoint, complete or not, to the same
    relative path below ``out``, all of it but its replay buffer and lock, and returns the copies.

    That is what continues a run on another machine: its config, record, logs and
    ``checkpoints/`` (the networks, optimisers and counters, a few MB at ``scale=cpu_ant``),
    without ``replay/`` (gigabytes) or ``.lock`` (it names this machine's process). Copy the
    carried runs back below the ``run_root`` of the same ``train`` command there: the
    off-policy imitators resume from ``checkpoints/last.pt``, refill their replay buffer from
    the current policy first and record the refill. A complete run whose budget can grow is
    carried the same way, to be continued with a larger budget.

    Raises:
        FileNotFoundError: ``root`` does not exist.
        ValueError: one of ``root`` and ``out`` lies inside the other.
    """
    root, out = copy_folders(root, out)
    runs = [RunDirectory(config_file.parent) for config_file in sorted(root.rglob(CONFIG_FILE))]
    runs = [run for run in runs if run.last_checkpoint.is_file()]
    check_copy_targets([out / run.path.relative_to(root) for run in runs])
    carried = []
    for run in runs:
        left_behind = (run.replay_dir, run.lock_file)
        target = out / run.path.relative_to(root)
        shutil.copytree(
            run.path, target, ignore=lambda folder, names: [n for n in names if Path(folder) / n in left_behind], dirs_exist_ok=True
        )
        carried.append(target)
    return carried
