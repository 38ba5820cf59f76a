"""Progress of long loops: a tqdm bar on a terminal, plain periodic log lines otherwise.

A tqdm bar redraws itself with carriage returns, which a redirected stream (a log file,
a CI console, a cluster job's output) records as one ever-growing line. So
:func:`progress` draws the bar only when standard error is a terminal; otherwise it
logs one line at most every ``interval_s`` seconds and one at the end, through the
``torchrl_causal.progress`` logger.

Examples:
    >>> import io
    >>> lines = io.StringIO()
    >>> handler = logging.StreamHandler(lines)
    >>> log.addHandler(handler); log.setLevel(logging.INFO)
    >>> with Progress(3, "demo", "episodes", interval_s=3600) as bar:  # what progress() gives off a terminal
    ...     for _ in range(3):
    ...         bar.update(1)
    >>> log.removeHandler(handler); log.setLevel(logging.NOTSET)
    >>> print(lines.getvalue(), end="")
    demo: 3/3 episodes (100%)
"""

from __future__ import annotations

import logging
import sys
import time
from collections.abc import Mapping
from types import TracebackType

from tqdm.auto import tqdm

__all__ = ["Progress", "progress"]

log = logging.getLogger(__name__)


class Progress:
    """Counts ``total`` units; reports as log lines (see the module docstring)."""

    def __init__(self, total: int, desc: str, unit: str, *, initial: int = 0, interval_s: float = 30.0, leave: bool = True) -> None:
        self.total, self.desc, self.unit, self.n = total, desc, unit, initial
        self.interval_s, self.leave = interval_s, leave
        self.postfix = ""
        self._last = time.monotonic()
        self._reported: int | None = None

    def update(self, n: int = 1) -> None:
        self.n += n
        if time.monotonic() - self._last >= self.interval_s:
            self._report()

    def set_postfix(self, values: Mapping[str, object], refresh: bool = False) -> None:
        self.postfix = ", ".join(f"{k}={v}" for k, v in values.items())

    def _report(self) -> None:
        self._last = time.monotonic()
        self._reported = self.n
        share = f" ({100 * self.n / self.total:.0f}%)" if self.total else ""
        log.info("%s: %d/%d %s%s%s", self.desc, self.n, self.total, self.unit, share, f" [{self.postfix}]" if self.postfix else "")

    def close(self) -> None:
        """Logs the final count, unless ``leave=False`` and the loop was too short for a line."""
        if self._reported != self.n and (self.leave or self._reported is not None):
            self._report()

    def __enter__(self) -> Progress:
        return self

    def __exit__(self, kind: type[BaseException] | None, error: BaseException | None, tb: TracebackType | None) -> None:
        self.close()


class _Silent(Progress):
    def _report(self) -> None:
        pass


def progress(
    total: int, desc: str, unit: str, *, enabled: bool = True, initial: int = 0, interval_s: float = 30.0, leave: bool = True
) -> Progress | tqdm:
    """A progress reporter with tqdm's ``update`` / ``set_postfix`` / ``close`` interface.

    Args:
        total: units to count.
        desc: what is counted (the bar's or the line's prefix).
        unit: the unit's name.
        enabled: ``False`` reports nothing.
        initial: units already done (a resumed run).
        interval_s: seconds between log lines when standard error is not a terminal.
        leave: keep the finished bar on screen; without a terminal, log the final count
            even when the loop was too short for a periodic line.
    """
    if not enabled:
        return _Silent(total, desc, unit, initial=initial)
    if sys.stderr.isatty():
        return tqdm(total=total, initial=initial, desc=desc, unit=unit, dynamic_ncols=True, leave=leave)
    return Progress(total, desc, unit, initial=initial, interval_s=interval_s, leave=leave)
