"""run_in_processes: a signal to the parent starts no new run, reaches each running worker
once (it checkpoints and exits 130), and nothing is printed as a traceback."""

from __future__ import annotations

import os
import signal
import threading
import time
from pathlib import Path

from torchrl_causal.experiment.interrupts import deferred_signals, run_in_processes


def steps_until_signalled(folder: str) -> int:
    """A stand-in for a run: marks its start, works in steps, and on a signal finishes the
    step and exits with 128 + signal (as a trainer does after its checkpoint)."""
    Path(folder, "started").touch()
    with deferred_signals() as signals:
        for _ in range(600):
            time.sleep(0.05)
            if signals.received is not None:
                Path(folder, f"stopped-{signals.received}").touch()
                return 128 + signals.received
    return 0


def quick(folder: str) -> int:
    Path(folder, "started").touch()
    return 0


def test_sigint_starts_no_new_run_and_reaches_each_worker_once(tmp_path: Path) -> None:
    # A suite started as a background job (`nohup ... &`) inherits SIGINT ignored: install
    # Python's own handler so that "the parent's handler is back" means the same everywhere.
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        _interrupt_two_of_three(tmp_path)
    finally:
        signal.signal(signal.SIGINT, previous)


def _interrupt_two_of_three(tmp_path: Path) -> None:
    folders = [tmp_path / f"task{i}" for i in range(3)]
    for folder in folders:
        folder.mkdir()

    def interrupt_when_both_started() -> None:
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline and not all((f / "started").exists() for f in folders[:2]):
            time.sleep(0.05)
        os.kill(os.getpid(), signal.SIGINT)

    threading.Thread(target=interrupt_when_both_started, daemon=True).start()
    codes = run_in_processes(steps_until_signalled, [str(f) for f in folders], workers=2)
    assert codes == [130, 130, None]
    assert [sorted(p.name for p in f.iterdir()) for f in folders] == [["started", "stopped-2"]] * 2 + [[]]
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler  # the parent's handler is back


def test_without_signals_every_task_runs_and_a_failure_starts_nothing_new(tmp_path: Path) -> None:
    folders = [tmp_path / name for name in ("a", "b")]
    for folder in folders:
        folder.mkdir()
    tasks = [str(folders[0]), "/nonexistent/folder", str(folders[1])]  # the second fails
    assert run_in_processes(quick, tasks, workers=1) == [0, 1, None]
    assert (folders[0] / "started").exists() and not (folders[1] / "started").exists()
