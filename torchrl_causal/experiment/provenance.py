"""Which code, data and runtime trained a run, attempt by attempt.

A run's config identifies what it computes, but not everything it computes it from: a fix
to a loss, a change of floating-point summation order, another torch or a regenerated
demonstration set (``demos.path`` is a runtime key) leaves ``config.yaml`` as it was and
changes the numbers. Two runs of one config and seed are bit-identical under the same
code, torch, demonstrations and runtime (``compile``, ``device``): measured for eager and
compiled runs, straight or interrupted and resumed, in ``tests/test_trainers.py`` and on
RoverMaze-Medium's C-SQIL config (``results/rovermaze_medium.md``, "Repeatability"). So
each attempt of a run (its start, and every resume) records them in ``code.json``; a
resume under other ones says so in the run's log, and the run's record (what
``python -m torchrl_causal.archive`` keeps) carries the whole list.
"""

from __future__ import annotations

import hashlib
import sys
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import torch

__all__ = ["PACKAGE_DIR", "RUNTIME_FIELDS", "attempt_identity", "identity_changes", "source_fingerprint"]

PACKAGE_DIR = Path(__file__).resolve().parents[1]

#: The fields of an attempt that change a run's numbers when they change.
RUNTIME_FIELDS: tuple[str, ...] = ("source", "torch", "demonstrations", "compile", "device")


def source_fingerprint(package_dir: Path = PACKAGE_DIR) -> str:
    """The first 12 hex digits of the SHA-256 of every ``.py`` file below ``package_dir``,
    each file named by its relative path, in sorted order: equal exactly when the sources
    are.

    Examples:
        >>> import tempfile
        >>> from pathlib import Path
        >>> root = Path(tempfile.mkdtemp())
        >>> _ = (root / "a.py").write_text("x = 1")
        >>> before = source_fingerprint(root)
        >>> _ = (root / "a.py").write_text("x = 2")
        >>> source_fingerprint(root) == before
        False
    """
    digest = hashlib.sha256()
    for path in sorted(package_dir.rglob("*.py")):
        digest.update(path.relative_to(package_dir).as_posix().encode())
        digest.update(b"\0")
        digest.update(path.read_bytes())
        digest.update(b"\0")
    return digest.hexdigest()[:12]


def attempt_identity(demonstrations: str | None, compile: bool, device: str | torch.device) -> dict[str, Any]:
    """What an attempt trains under: the library's :func:`source_fingerprint`, torch's and
    Python's versions, the demonstration set's checksum (``demonstrations``, its first 12
    hex digits are kept; ``None`` for none), and whether it compiles, on which device.

    Examples:
        >>> identity = attempt_identity("b34e70289b3df979", compile=False, device="cpu")
        >>> sorted(identity), identity["demonstrations"]
        (['compile', 'demonstrations', 'device', 'python', 'source', 'torch'], 'b34e70289b3d')
    """
    return {"source": source_fingerprint(), "torch": torch.__version__, "python": sys.version.split()[0],
            "demonstrations": None if demonstrations is None else demonstrations[:12], "compile": bool(compile),
            "device": str(device)}


def identity_changes(previous: Mapping[str, Any], current: Mapping[str, Any]) -> dict[str, tuple[Any, Any]]:
    """The :data:`RUNTIME_FIELDS` whose values differ between two attempts, as
    ``{field: (previous, current)}``.

    Examples:
        >>> identity_changes({"source": "a", "torch": "2.13.0", "compile": False, "device": "cpu"},
        ...                  {"source": "b", "torch": "2.13.0", "compile": True, "device": "cpu"})
        {'source': ('a', 'b'), 'compile': (False, True)}
    """
    return {key: (previous.get(key), current.get(key)) for key in RUNTIME_FIELDS
            if previous.get(key) != current.get(key)}
