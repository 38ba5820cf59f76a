"""SIGINT / SIGTERM / SIGUSR2 for runs: finish the step in flight, checkpoint, say how to resume.

A training iteration interrupted half-way (a collector between env steps, an optimiser
between parameter groups) leaves nothing worth saving, so :func:`deferred_signals`
records the signal and lets the iteration finish; the trainer then checkpoints and
raises :class:`RunInterrupted`. A second signal stops at once. Outside training
(building envs, the final evaluation) :func:`signals_raise` turns both signals into
:class:`RunInterrupted` straight away, so that SIGTERM, too, unwinds through the code
that marks the run interrupted instead of killing the process where it stands.

SIGUSR2 is what SLURM sends ahead of a job's time limit (``--signal=USR2@<s>``) and
submitit on pre-emption. Under a job scheduler another handler may already be installed
for these signals (submitit's requeues the job); :func:`signals_raise` calls it once the
run has checkpointed and marked itself interrupted, so the job is requeued and resumes.

Handlers can only be installed from the main thread; elsewhere both context managers
change nothing.
"""

from __future__ import annotations

import logging
import multiprocessing
import multiprocessing.connection
import os
import signal
import threading
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass
from types import FrameType
from typing import Any, TypeGuard

__all__ = ["RunInterrupted", "DeferredSignals", "deferred_signals", "ignored_signals", "run_in_processes", "signals_raise"]

log = logging.getLogger(__name__)

_SIGNALS = (signal.SIGINT, signal.SIGTERM, signal.SIGUSR2)


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
#: What ``signal.signal`` returns: a Python handler, a ``signal.Handlers`` value (SIG_DFL,
#: SIG_IGN) or an int, or None for a handler not installed from Python.
PreviousHandler = Callable[[int, FrameType | None], Any] | int | signal.Handlers | None


@contextmanager
def _handlers(handler: Handler) -> Iterator[dict[int, PreviousHandler]]:
    """Installs ``handler`` for the run's signals; yields the handlers it replaced."""
    if threading.current_thread() is not threading.main_thread():
        yield {}
        return
    previous: dict[int, PreviousHandler] = {number: signal.signal(number, handler) for number in _SIGNALS}
    try:
        yield previous
    finally:
        for number, old in previous.items():
            signal.signal(number, old)


def _raise(number: int, frame: FrameType | None) -> None:
    raise RunInterrupted(number)


def _chained(handler: PreviousHandler) -> TypeGuard[Callable[[int, FrameType | None], Any]]:
    """Whether ``handler`` is another program's Python handler to pass the signal on to
    (not the default action, ignoring, or Python's KeyboardInterrupt)."""
    return callable(handler) and handler is not signal.default_int_handler


@contextmanager
def signals_raise() -> Iterator[None]:
    """SIGINT, SIGTERM and SIGUSR2 raise :class:`RunInterrupted` where the program stands.

    When the block ends on :class:`RunInterrupted` (the run saved what it had and marked
    itself interrupted), the handler that was installed before for that signal, if it is a
    Python function (submitit's, which requeues the job), is called with it.

    Examples:
        >>> import os
        >>> received = []
        >>> previous = signal.signal(signal.SIGUSR2, lambda number, frame: received.append(number))
        >>> try:
        ...     with signals_raise():
        ...         os.kill(os.getpid(), signal.SIGUSR2)
        ... except RunInterrupted as stop:
        ...     print(stop, received == [signal.SIGUSR2])
        interrupted by SIGUSR2 True
        >>> _ = signal.signal(signal.SIGUSR2, previous)
    """
    with _handlers(_raise) as previous:
        try:
            yield
        except RunInterrupted as stop:
            handler = previous.get(stop.signal_number)
            if not _chained(handler):
                raise
            signal.signal(stop.signal_number, handler)
            log.warning(
                "%s: passing it on to the handler that was installed before the run (%s)",
                stop.signal_name,
                getattr(handler, "__qualname__", handler),
            )
            handler(stop.signal_number, None)
            raise


@dataclass
class DeferredSignals:
    """The first SIGINT / SIGTERM / SIGUSR2 received inside :func:`deferred_signals` (``None``: none)."""

    received: int | None = None

    def _handle(self, number: int, frame: FrameType | None) -> None:
        if self.received is not None:
            raise RunInterrupted(number, f"{signal.Signals(number).name} again: stopping without a checkpoint")
        self.received = number
        log.warning(
            "%s received: finishing the current step, then checkpointing (send it again to stop at once)", signal.Signals(number).name
        )


@contextmanager
def deferred_signals() -> Iterator[DeferredSignals]:
    """Records SIGINT / SIGTERM / SIGUSR2 instead of acting on them; a second one raises
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


def _worker(function: Callable[[Any], int], task: Any, stop: Any) -> None:
    """A worker process: out of the terminal's process group (its parent forwards signals,
    once), signals raising :class:`RunInterrupted` from here on, ``function(task)``'s
    status as its exit status."""
    os.setpgrp()
    code = 128 + signal.SIGINT
    try:
        with signals_raise():
            if not stop.is_set():  # a signal reached the parent while this process was starting
                code = int(function(task))
    except RunInterrupted as stop_signal:
        code = stop_signal.exit_code
    raise SystemExit(code)


@contextmanager
def ignored_signals() -> Iterator[None]:
    """SIGINT, SIGTERM and SIGUSR2 ignored: a process spawned now inherits that through its start-up
    (the interpreter keeps an ignored SIGINT ignored), so it cannot die in its imports, and a
    terminal's Ctrl-C reaches only its parent, which decides when it stops.

    Examples:
        >>> with ignored_signals():
        ...     signal.getsignal(signal.SIGTERM) is signal.SIG_IGN
        True
        >>> signal.getsignal(signal.SIGTERM) is signal.SIG_IGN
        False
    """
    previous = {number: signal.signal(number, signal.SIG_IGN) for number in _SIGNALS}
    try:
        yield
    finally:
        for number, handler in previous.items():
            signal.signal(number, handler)


def run_in_processes(function: Callable[[Any], int], tasks: Sequence[Any], workers: int) -> list[int | None]:
    """Runs ``function(task)`` for every task in fresh (spawned) processes, ``workers`` at a
    time; returns each task's exit status, ``None`` for a task never started.

    ``function`` (importable, picklable) returns an exit status, 0 for success. On the
    first SIGINT or SIGTERM (or the first non-zero status) no further task starts; the
    signal is forwarded once to every running worker, which (running a trainer) finishes its
    step, checkpoints and exits with ``128 + signal``. A second signal is forwarded too:
    the workers stop at once. Workers run in their own process groups, so a terminal's
    Ctrl-C reaches them only through this forwarding, never twice.

    Must be called from the main thread (it handles the signals).
    """
    context = multiprocessing.get_context("spawn")
    stop = context.Event()
    codes: list[int | None] = [None] * len(tasks)
    running: dict[int, multiprocessing.process.BaseProcess] = {}

    def forward(number: int, frame: FrameType | None) -> None:
        if not stop.is_set():
            log.warning(
                "%s received: no new run starts; the runs in flight checkpoint and stop (send it again to stop them at once)",
                signal.Signals(number).name,
            )
        stop.set()
        for process in running.values():
            if process.pid is not None and process.exitcode is None:
                os.kill(process.pid, number)

    with _handlers(forward):
        queued = iter(range(len(tasks)))
        while True:
            while not stop.is_set() and len(running) < workers and (index := next(queued, None)) is not None:
                process = context.Process(target=_worker, args=(function, tasks[index], stop))
                with ignored_signals():
                    process.start()
                running[index] = process
            if not running:
                break
            multiprocessing.connection.wait([process.sentinel for process in running.values()], timeout=1.0)
            for index, child in list(running.items()):
                if child.exitcode is not None:
                    codes[index] = child.exitcode
                    if child.exitcode != 0:
                        stop.set()  # an interrupted or failed run: start nothing new
                    del running[index]
    return codes
