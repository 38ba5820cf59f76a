"""The expert's body: which skill weights a run's expert walks, recorded with the run and checked.

A maze expert steers a trained walking skill, a weights file: one expert class with one set of
settings walks as many ways as there are bodies. HumanoidMaze's two shipped bodies differ by 30
points of success on Medium (``results/humanoidmaze_expert.md``), and a record that names only
the class is re-evaluated with whichever body is the default that day: the archived
HumanoidMaze-Medium expert row, made with the steady body (85.2% deploy), gave 54% when
re-evaluated with the fast one after the default changed (issue 57).

So every run writes into its ``config.yaml``, beside ``env.expert``, the body it resolved to,
``env.expert_body`` (:data:`EXPERT_BODY_KEY`)::

    expert_body:
      weights: torchrl_causal/envs/assets/humanoid_locomotion_steady.pt   # null: a scripted expert
      sha256: 74ff654b...                                                  # of the file's tensors

``weights`` is relative to the package's parent folder for a shipped body (a checkout or an
install finds it there) and absolute otherwise. ``sha256`` is :func:`weights_digest`, a digest
of the file's tensors by name, dtype and shape, not of its bytes: a body exported again from its
PPO state is the same body (the steady file and the one shipped at ``ea36bff`` differ in bytes
and hold equal tensors). Building the expert of a config that records its body
(:func:`~torchrl_causal.experiment.builders.make_expert`) walks that file and refuses, in one line,
a file that is missing or holds other tensors.

An expert class says which file it walks with a classmethod ``weights_file(weights=None)``
(``None``: its default body; :class:`~torchrl_causal.experts.HumanoidMazeExpert` resolves the
shipped bodies' names); a class without one walks no file (a scripted expert:
:class:`~torchrl_causal.experts.RoverExpert`), and its record says so (``weights: null``).
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any, cast

import torch
from hydra.utils import get_class
from omegaconf import DictConfig, OmegaConf

from torchrl_causal.errors import InvalidStateError, MissingFileError, TorchRLCausalError
from torchrl_causal.experiment.run_directory import EXPERT_BODY_KEY, policy_digest

__all__ = [
    "EXPERT_BODY_KEY",
    "ExpertBody",
    "ExpertBodyError",
    "expert_weights_file",
    "recorded_body",
    "resolve_expert_body",
    "weights_digest",
]

#: Where the package's shipped files are found from: a recorded path relative to it is a shipped body.
_PACKAGE_PARENT = Path(__file__).resolve().parents[2]


class ExpertBodyError(TorchRLCausalError, ValueError):
    """An expert's body that is not the one its run recorded, or a run that records none."""


def weights_digest(path: str | os.PathLike) -> str:
    """SHA-256 of the tensors of the state dict at ``path`` (:func:`policy_digest`: by name, dtype
    and shape): equal for two files that hold the same tensors, however they were saved.

    Raises:
        InvalidStateError: the file is not a state dict (truncated, a foreign pickle).
    """
    try:
        state = torch.load(path, map_location="cpu", weights_only=True)
        return policy_digest(state)
    except Exception as error:  # a truncated file, a foreign pickle, not a mapping of tensors
        raise InvalidStateError(f"{path} is not a state dict of tensors: {' '.join(str(error).split())[:100]}") from None


def _portable(path: Path) -> str:
    """``path`` relative to the package's parent folder when it lies below it, else absolute."""
    resolved = path.resolve()
    return resolved.relative_to(_PACKAGE_PARENT).as_posix() if resolved.is_relative_to(_PACKAGE_PARENT) else str(resolved)


@dataclass(frozen=True)
class ExpertBody:
    """The weights file an expert walks (``None``: none, a scripted expert) and its :func:`weights_digest`.

    Examples:
        >>> body = resolve_expert_body({"_target_": "torchrl_causal.experts.HumanoidMazeExpert", "weights": "steady"})
        >>> body.weights, body.sha256 == weights_digest(body.file())
        ('torchrl_causal/envs/assets/humanoid_locomotion_steady.pt', True)
        >>> resolve_expert_body({"_target_": "torchrl_causal.experts.RoverExpert"}).to_record()
        {'weights': None, 'sha256': None}
    """

    weights: str | None
    sha256: str | None

    @classmethod
    def of_file(cls, path: Path | None) -> ExpertBody:
        """The body of the weights file ``path`` (``None``: a scripted expert's).

        Raises:
            MissingFileError: naming the file.
        """
        if path is None:
            return cls(None, None)
        if not path.is_file():
            raise MissingFileError(f"the expert's skill weights {path} do not exist: the expert cannot be built or recorded")
        return cls(_portable(path), weights_digest(path))

    @classmethod
    def from_record(cls, record: Mapping[str, Any], where: str = EXPERT_BODY_KEY) -> ExpertBody:
        """The body a config records at ``where``.

        Raises:
            ExpertBodyError: the record lacks a key, or names a file without its digest.
        """
        missing = [key for key in ("weights", "sha256") if key not in record]
        if missing:
            raise ExpertBodyError(f"{where} lacks {missing[0]!r}: it records an expert's weights file and that file's sha256")
        body = cls(record["weights"], record["sha256"])
        if (body.weights is None) != (body.sha256 is None):
            raise ExpertBodyError(
                f"{where} names {'a file' if body.weights else 'a digest'} without its {'sha256' if body.weights else 'file'}"
            )
        return body

    def to_record(self) -> dict[str, str | None]:
        """What ``config.yaml`` keeps at :data:`EXPERT_BODY_KEY`."""
        return {"weights": self.weights, "sha256": self.sha256}

    def file(self) -> Path | None:
        """The weights file: a relative path is read below the package's parent folder."""
        if self.weights is None:
            return None
        path = Path(self.weights)
        return path if path.is_absolute() else _PACKAGE_PARENT / path

    def verified_file(self, where: str = EXPERT_BODY_KEY) -> Path | None:
        """:meth:`file`, once it holds the recorded tensors.

        Raises:
            MissingFileError: the file is gone.
            ExpertBodyError: it holds other tensors than the recorded body's.
        """
        path = self.file()
        if path is None:
            return None
        if not path.is_file():
            raise MissingFileError(
                f"{where}.weights={self.weights}: that file does not exist, so the expert this run recorded cannot be rebuilt; "
                "restore it (a checkout at the run's commit has it) or point the record at a copy"
            )
        found = weights_digest(path)
        if found != self.sha256:
            raise ExpertBodyError(
                f"{where}.sha256={self.sha256}: {path} now holds another body (sha256 {found}); nothing was evaluated: "
                "the run's expert walked the recorded one: restore that file (a checkout at the run's commit has it)"
            )
        return path


def expert_weights_file(expert: Mapping[str, Any] | DictConfig, weights: str | os.PathLike | None = None) -> Path | None:
    """The weights file the expert config ``expert`` (``env.expert``) walks, with ``weights`` in
    place of its own ``weights`` when given; ``None`` for an expert class that walks none."""
    target = get_class(str(expert["_target_"]))
    resolve = getattr(target, "weights_file", None)
    if resolve is None:
        return None
    chosen = expert.get("weights") if weights is None else weights
    return Path(resolve(None if chosen is None else str(chosen)))


def resolve_expert_body(expert: Mapping[str, Any] | DictConfig, weights: str | os.PathLike | None = None) -> ExpertBody:
    """The :class:`ExpertBody` of the expert config ``expert`` (``weights``: as :func:`expert_weights_file`).

    Raises:
        MissingFileError: the weights file it names does not exist.
    """
    return ExpertBody.of_file(expert_weights_file(expert, weights))


def recorded_body(cfg: DictConfig) -> ExpertBody | None:
    """The body ``cfg`` records (:data:`EXPERT_BODY_KEY`); ``None`` for a config that records none
    (a composed config, or a run made before runs recorded it)."""
    record = OmegaConf.select(cfg, EXPERT_BODY_KEY)
    if record is None:
        return None
    fields = OmegaConf.to_container(record) if isinstance(record, DictConfig) else record
    if not isinstance(fields, Mapping):
        raise ExpertBodyError(f"{EXPERT_BODY_KEY} must be a mapping with weights and sha256, got {fields!r}")
    return ExpertBody.from_record(cast("Mapping[str, Any]", fields))
