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

An attempt also records what it cost when it ends (completed, interrupted or failed):
:class:`AttemptClock` measures its wall time and its process CPU time (``wall_s``,
``cpu_s``), so that a results table can say what a row cost. An attempt killed outright
(SIGKILL, out of memory) records none.
"""

from __future__ import annotations

import hashlib
import os
import platform
import sys
import time
from collections.abc import Mapping
from dataclasses import dataclass, field
from functools import cache
from importlib import metadata
from pathlib import Path
from typing import Any

import torch

__all__ = [
    "COST_FIELDS",
    "PACKAGE_DIR",
    "PACKAGES",
    "RUNTIME_FIELDS",
    "AttemptClock",
    "attempt_identity",
    "cpu_model",
    "identity_changes",
    "machine_identity",
    "package_versions",
    "process_cpu_seconds",
    "source_fingerprint",
]

PACKAGE_DIR = Path(__file__).resolve().parents[1]

#: The fields of an attempt that change a run's numbers when they change (another CPU or
#: thread count changes floating-point summation order; another numpy, mujoco or TorchRL
#: changes the envs' and collectors' arithmetic).
RUNTIME_FIELDS: tuple[str, ...] = ("source", "torch", "packages", "cpu", "threads", "demonstrations", "compile", "device", "precision")

#: What an attempt records of its cost when it ends (:meth:`AttemptClock.cost`).
COST_FIELDS: tuple[str, ...] = ("wall_s", "cpu_s")

#: The distributions whose versions a run records (their import names differ for two).
PACKAGES: tuple[str, ...] = ("torch", "torchrl", "tensordict", "numpy", "mujoco", "gymnasium", "hydra-core")


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


def package_versions(names: tuple[str, ...] = PACKAGES) -> dict[str, str | None]:
    """The installed version of each distribution in ``names`` (``None``: not installed).

    Examples:
        >>> versions = package_versions()
        >>> list(versions) == list(PACKAGES), versions["torch"] == torch.__version__
        (True, True)
    """
    versions: dict[str, str | None] = {}
    for name in names:
        try:
            versions[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            versions[name] = None
    return versions


@cache
def cpu_model() -> str:
    """The processor's model name (``/proc/cpuinfo`` on Linux, else :func:`platform.processor`),
    or the machine type when neither names it."""
    try:
        with open("/proc/cpuinfo") as handle:
            for line in handle:
                if line.startswith(("model name", "Hardware", "Processor")) and ":" in line:
                    return " ".join(line.split(":", 1)[1].split())
    except OSError:
        pass
    return platform.processor() or platform.machine() or "unknown"


def machine_identity() -> dict[str, object]:
    """The package versions (:data:`PACKAGES`), CPU model, torch's thread count and the
    machine's core count of this process.

    Examples:
        >>> sorted(machine_identity())
        ['cores', 'cpu', 'packages', 'threads']
    """
    return {"packages": package_versions(), "cpu": cpu_model(), "threads": torch.get_num_threads(), "cores": os.cpu_count()}


def attempt_identity(demonstrations: str | None, compile: bool, device: str | torch.device, precision: str = "fp32") -> dict[str, Any]:
    """What an attempt trains under: the library's :func:`source_fingerprint`, torch's and
    Python's versions, the demonstration set's checksum (``demonstrations``, its first 12
    hex digits are kept; ``None`` for none), whether it compiles, on which device, in which
    precision its updates run (``algo.precision``: ``fp32`` or ``bf16``), and the
    :func:`machine_identity` (package versions, CPU, threads).

    Examples:
        >>> identity = attempt_identity("b34e70289b3df979", compile=False, device="cpu")
        >>> sorted(identity)
        ['compile', 'cores', 'cpu', 'demonstrations', 'device', 'packages', 'precision', 'python', 'source', 'threads', 'torch']
        >>> identity["demonstrations"], identity["precision"]
        ('b34e70289b3d', 'fp32')
    """
    return {
        "source": source_fingerprint(),
        "torch": torch.__version__,
        "python": sys.version.split()[0],
        "demonstrations": None if demonstrations is None else demonstrations[:12],
        "compile": bool(compile),
        "device": str(device),
        "precision": precision,
        **machine_identity(),
    }


def identity_changes(previous: Mapping[str, Any], current: Mapping[str, Any]) -> dict[str, tuple[Any, Any]]:
    """The :data:`RUNTIME_FIELDS` whose values differ between two attempts, as
    ``{field: (previous, current)}``. A field the previous attempt did not record (it
    predates the field: ``packages``, ``cpu``, ``threads``) is unknown, not changed.

    Examples:
        >>> identity_changes({"source": "a", "torch": "2.13.0", "compile": False, "device": "cpu"},
        ...                  {"source": "b", "torch": "2.13.0", "compile": True, "device": "cpu", "threads": 2})
        {'source': ('a', 'b'), 'compile': (False, True)}
    """
    return {
        key: (previous.get(key), current.get(key)) for key in RUNTIME_FIELDS if key in previous and previous.get(key) != current.get(key)
    }


def process_cpu_seconds() -> float:
    """User plus system CPU seconds of this process (all its threads) and of its child
    processes that have ended and been waited for (a collector's worker processes, once
    the collector shut them down). Where :mod:`resource` is missing (Windows), this
    process's :func:`time.process_time` alone.

    Examples:
        >>> before = process_cpu_seconds()
        >>> _ = sum(i * i for i in range(200_000))
        >>> process_cpu_seconds() > before
        True
    """
    try:
        import resource
    except ImportError:  # not a Unix
        return time.process_time()
    own, children = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_utime + own.ru_stime + children.ru_utime + children.ru_stime


@dataclass(frozen=True)
class AttemptClock:
    """Wall time and process CPU time since the clock was made (the start of an attempt).

    CPU time is what a run costs on a shared machine: its wall time stretches with
    whatever else runs on the same cores, its CPU time does not (much).

    Examples:
        >>> clock = AttemptClock()
        >>> cost = clock.cost()
        >>> sorted(cost) == sorted(COST_FIELDS), cost["wall_s"] >= 0, cost["cpu_s"] >= 0
        (True, True, True)
    """

    wall_start: float = field(default_factory=time.monotonic)
    cpu_start: float = field(default_factory=process_cpu_seconds)

    def cost(self) -> dict[str, float]:
        """``{"wall_s": ..., "cpu_s": ...}`` so far, in seconds (to the millisecond)."""
        return {
            "wall_s": round(time.monotonic() - self.wall_start, 3),
            "cpu_s": round(process_cpu_seconds() - self.cpu_start, 3),
        }
