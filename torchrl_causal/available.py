"""What memory this process can still allocate: the one reading that every pre-allocation
check shares (a run's footprint, an env's simulations).

Examples:
    >>> available_memory() > 0
    True
"""

from __future__ import annotations

import os
from pathlib import Path

__all__ = ["available_memory"]


def _meminfo_available() -> int | None:
    try:
        with open("/proc/meminfo") as handle:
            for line in handle:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except OSError:
        pass
    return None


def _cgroup_available() -> int | None:
    """What the cgroup (v2) this process runs in still allows, when it sets a limit."""
    try:
        limit = Path("/sys/fs/cgroup/memory.max").read_text().strip()
        if limit == "max":
            return None
        return int(limit) - int(Path("/sys/fs/cgroup/memory.current").read_text())
    except (OSError, ValueError):
        return None


def available_memory() -> int:
    """Bytes this process can still allocate without swapping: the kernel's
    ``MemAvailable``, lowered to the cgroup's remaining limit when there is one."""
    candidates = [value for value in (_meminfo_available(), _cgroup_available()) if value is not None]
    if not candidates:
        candidates = [os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")]
    return max(0, min(candidates))
