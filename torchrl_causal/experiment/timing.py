"""CPU and wall time per part of a run: what ``benchmarks/run_cost.py`` reports.

The training loops mark their parts with :func:`timed` (``"updates"``, ``"replay sampling"``,
``"collection"``, ``"evaluation"``, ``"warm start (BC)"``, ``"warm start (critics)"``,
``"compile"``, ``"checkpoints"``, ``"setup"``). Nothing is measured unless a :class:`PartTimer` is recording
(:meth:`PartTimer.recording`, one at a time in a process); outside one, :func:`timed` is a
no-op. A part's time is charged to it alone: a part inside another (the compilation inside
the first update, the replay sampling inside the warm start's critic fit) is taken out of the
outer one, and the time outside every part goes to ``"other"``, so the parts add up to the
time recorded.

CPU time is the process's (:func:`time.process_time`, every thread of it) plus that of its
finished child processes (:func:`os.times`: the C++ compiler inductor runs, counted when it
exits, at the clock tick's resolution). With ``threads=1``, one collector worker and
``TORCHINDUCTOR_COMPILE_THREADS=1`` (no pool of compile workers that outlive their work)
that is the run's whole cost.
"""

from __future__ import annotations

import os
import time
from collections import Counter, defaultdict
from collections.abc import Iterator
from contextlib import AbstractContextManager, contextmanager, nullcontext

from torchrl_causal.errors import InvalidStateError

__all__ = ["OTHER", "PartTimer", "cpu_seconds", "timed"]

#: Where the time outside every part is charged.
OTHER = "other"


def cpu_seconds() -> float:
    """CPU seconds of this process (every thread) and of its children that have exited."""
    children = os.times()
    return time.process_time() + children.children_user + children.children_system


class PartTimer:
    """Accumulates CPU and wall seconds per named part, each exclusive of the parts inside it.

    Examples:
        >>> timer = PartTimer()
        >>> with timer.recording():
        ...     with timed("updates"):
        ...         with timed("compile"):
        ...             _ = sum(range(10_000))
        ...     with timed("updates"):
        ...         pass
        >>> timer.calls["updates"], timer.calls["compile"], sorted(timer.cpu) == ["compile", "other", "updates"]
        (2, 1, True)
        >>> abs(sum(timer.wall.values()) - timer.total_wall) < 1e-9
        True
    """

    def __init__(self) -> None:
        self.cpu: defaultdict[str, float] = defaultdict(float)
        self.wall: defaultdict[str, float] = defaultdict(float)
        self.calls: Counter[str] = Counter()
        self._stack: list[str] = []
        self._mark = (0.0, 0.0)

    @property
    def total_cpu(self) -> float:
        """CPU seconds recorded, all parts and ``"other"``."""
        return sum(self.cpu.values())

    @property
    def total_wall(self) -> float:
        """Wall seconds recorded, all parts and ``"other"``."""
        return sum(self.wall.values())

    def _charge(self) -> None:
        # The time since the last mark goes to the innermost open part (or to OTHER).
        cpu, wall = cpu_seconds(), time.perf_counter()
        name = self._stack[-1] if self._stack else OTHER
        self.cpu[name] += cpu - self._mark[0]
        self.wall[name] += wall - self._mark[1]
        self._mark = (cpu, wall)

    @contextmanager
    def part(self, name: str) -> Iterator[None]:
        """Charges the block's time to ``name`` (less the parts opened inside it)."""
        self._charge()
        self._stack.append(name)
        self.calls[name] += 1
        try:
            yield
        finally:
            self._charge()
            self._stack.pop()

    @contextmanager
    def recording(self) -> Iterator[PartTimer]:
        """Makes this timer the one :func:`timed` charges, for the block.

        Raises:
            RuntimeError: when another timer is recording already.
        """
        if _RECORDING:
            raise InvalidStateError("a PartTimer is recording already: one at a time in a process")
        _RECORDING.append(self)
        self._mark = (cpu_seconds(), time.perf_counter())
        try:
            yield self
        finally:
            self._charge()
            _RECORDING.pop()


_RECORDING: list[PartTimer] = []


def timed(name: str | None) -> AbstractContextManager:
    """The recording timer's :meth:`~PartTimer.part` ``name``; a no-op when no timer is
    recording, or for ``name=None`` (a part that is only sometimes one)."""
    if name is None or not _RECORDING:
        return nullcontext()
    return _RECORDING[-1].part(name)
