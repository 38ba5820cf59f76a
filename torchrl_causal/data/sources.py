"""Where a run's demonstrations come from: ``demos.source``.

* ``null`` (the default): our own format at ``demos.path``, collected with the env's
  expert when absent (:mod:`torchrl_causal.data.demonstrations`);
* ``minari:<dataset id or path>``: a Minari dataset (:mod:`torchrl_causal.data.minari_format`),
  by its directory or by its id under ``$MINARI_DATASETS_PATH`` / ``~/.minari/datasets``.
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from tensordict import TensorDictBase
from torchrl.envs import EnvBase

from torchrl_causal.data.demonstrations import DatasetError, load_demonstrations, read_metadata
from torchrl_causal.data.minari_format import METADATA_KEY, load_minari_demonstrations, read_minari_metadata
from torchrl_causal.extras import missing_extra

__all__ = ["MINARI_PREFIX", "check_source", "load_source", "minari_reference", "source_checksum", "source_problem"]

MINARI_PREFIX = "minari:"


def minari_reference(source: str | None) -> str | None:
    """The dataset id or path of a ``minari:`` source (``None`` for our own format).

    Examples:
        >>> minari_reference("minari:causal/rovermaze-u-v0"), minari_reference(None)
        ('causal/rovermaze-u-v0', None)
    """
    if source is None:
        return None
    if not source.startswith(MINARI_PREFIX) or not source[len(MINARI_PREFIX) :]:
        raise DatasetError(
            f"demos.source={source!r} is not a source: use null (our format at demos.path) or {MINARI_PREFIX}<dataset id or path>"
        )
    return source[len(MINARI_PREFIX) :]


def source_problem(source: str | None) -> str | None:
    """What stops ``source`` from being read on this machine (a malformed value, a missing
    extra), as a one-line message; ``None`` when nothing does. Reads no data."""
    try:
        reference = minari_reference(source)
    except DatasetError as error:
        return str(error)
    if reference is None:
        return None
    return missing_extra(f"demos.source={source}", "minari", "h5py")


def load_source(
    source: str | None, path: str | os.PathLike, expected: Mapping[str, Any] | EnvBase | None = None, *, verify_checksum: bool = True
) -> TensorDictBase:
    """The demonstrations of ``source`` (our format at ``path`` when ``source`` is ``None``),
    refused unless they match ``expected`` (see :func:`~torchrl_causal.data.load_demonstrations`)."""
    reference = minari_reference(source)
    if reference is None:
        return load_demonstrations(path, expected=expected, verify_checksum=verify_checksum)
    return load_minari_demonstrations(reference, expected=expected, verify_checksum=verify_checksum)


def check_source(source: str | None, path: str | os.PathLike, expected: Mapping[str, Any] | EnvBase) -> None:
    """Refuses demonstrations that a run could not train on, before the run starts: a
    Minari dataset always (it must exist), our format only where ``path`` exists (else the
    run collects it).

    Raises:
        DatasetError: see :func:`load_source`.
    """
    if minari_reference(source) is None and not Path(path).exists():
        return
    load_source(source, path, expected)


def source_checksum(source: str | None, path: str | os.PathLike) -> str | None:
    """The recorded checksum of the demonstrations (``None`` for a Minari dataset exported
    elsewhere without one): what identifies the data a run trained on."""
    reference = minari_reference(source)
    if reference is None:
        return read_metadata(path)["checksum"]
    return read_minari_metadata(reference).get(METADATA_KEY, {}).get("checksum")
