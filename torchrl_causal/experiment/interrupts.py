"""SIGINT / SIGTERM for runs: finish the step in flight, checkpoint, say how to resume.

A training iteration interrupted half-way (a collector between env steps, an optimiser
between parameter groups) leaves nothing worth saving, so :func:`deferred_signals`
records the signal and lets the iteration finish; the trainer then checkpoints and
raises :class:`RunInterrupted`. A second signal stops at once. Outside training
(building envs, the final evaluation) :func:`signals_raise` turns both signals into
:class:`RunInterrupted` straight away, so that SIGTERM, too, unwinds through the code
that marks the run interrupted instead of killing the process where it stands.

Handlers can only be installed from the main thread; elsewhere both context managers
change nothing.
"""

from __future__ import annotations

import logging
import signal
import threading
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from types import FrameType

__all__ = ["RunInterrupted", "DeferredSignals", "deferred_signals", "signals_raise"]

log = logging.getLogger(__name__)

_SIGNALS = (signal.SIGINT, signal.SIGTERM)


class RunInterrupted(Exception):
    """The run stopped on a signal; what was done is saved and a rerun resumes it.

    Attributes:
        signal_number: the signal that stopped it.
        exit_code: the conventional exit status, ``128 + signal_number``.
    """

    def __init__(self, signal_number: int, message: str = "") -> None:
        self.signal_number = signal_number
        super().__init__(message or f"interrupted by {signal.Signals(signal_number).name}")

    @property
    def signal_name(self) -> str:
        return signal.Signals(self.signal_number).name

    @property
    def exit_code(self) -> int:
        return 128 + self.signal_number


Handler = Callable[[int, FrameType | None], None]


@contextmanager
def _handlers(handler: Handler) -> Iterator[None]:
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = {number: signal.signal(number, handler) for number in _SIGNALS}
    try:
        yield
    finally:
        for number, old in previous.items():
            signal.signal(number, old)


def _raise(number: int, frame: FrameType | None) -> None:
    raise RunInterrupted(number)


@contextmanager
def signals_raise() -> Iterator[None]:
    """SIGINT and SIGTERM raise :class:`RunInterrupted` where the program stands."""
    with _handlers(_raise):
        yield


@dataclass
class DeferredSignals:
    """The first SIGINT / SIGTERM received inside :func:`deferred_signals` (``None``: none)."""

    received: int | None = None

    def _handle(self, number: int, frame: FrameType | None) -> None:
        if self.received is not None:
            raise RunInterrupted(number, f"{signal.Signals(number).name} again: stopping without a checkpoint")
        self.received = number
        log.warning("%s received: finishing the current step, then checkpointing (send it again to stop at once)",
                    signal.Signals(number).name)


@contextmanager
def deferred_signals() -> Iterator[DeferredSignals]:
    """Records SIGINT / SIGTERM instead of acting on them; a second one raises
    :class:`RunInterrupted` at once.

    Examples:
        >>> import os
        >>> with deferred_signals() as signals:
        ...     os.kill(os.getpid(), signal.SIGTERM)  # noted, not acted on
        ...     finished = True
        >>> finished, signals.received == signal.SIGTERM
        (True, True)
    """
    signals = DeferredSignals()
    with _handlers(signals._handle):
        yield signals
