"""SIGUSR2 (SLURM's warning ahead of a time limit, submitit's pre-emption signal) and
SIGTERM checkpoint a run like SIGINT, leave it resumable, and reach the handler a job
scheduler installed before the run (submitit's requeues the job)."""

from __future__ import annotations

import signal
from pathlib import Path

import pytest
from hydra.utils import get_class
from test_trainers import _interrupt_at, tiny_config

from torchrl_causal.experiment import RunDirectory, RunInterrupted
from torchrl_causal.lifecycle import run

BC = ("algo.epochs=4", "algo.eval_every=2", "checkpoint_every_s=3600")


@pytest.mark.parametrize("number", [signal.SIGUSR2, signal.SIGTERM])
def test_signal_checkpoints_then_reaches_the_schedulers_handler_and_the_run_resumes(tmp_path: Path, number) -> None:
    cfg = tiny_config(tmp_path, "route_choice", "bc", True, *BC)
    run_dir = RunDirectory(cfg.run_dir)
    seen = []

    def scheduler(received: int, frame) -> None:  # what submitit's handler finds when it is called
        seen.append((received, run_dir.read_status().get("status"), run_dir.last_checkpoint.is_file()))

    previous = signal.signal(number, scheduler)
    try:
        with (
            _interrupt_at(get_class(cfg.algo.trainer), 2, number),
            pytest.raises(RunInterrupted, match=f"interrupted by {signal.Signals(number).name} at 2/4") as stop,
        ):
            run(cfg)
    finally:
        signal.signal(number, previous)
    assert stop.value.exit_code == 128 + number
    assert seen == [(number, "interrupted", True)]  # after the checkpoint, once
    assert run_dir.read_status()["progress"] == 2
    run(tiny_config(tmp_path, "route_choice", "bc", True, *BC))  # the requeued job: same command
    assert run_dir.read_status()["status"] == "complete"
    assert [attempt["progress"] for attempt in run_dir.read_attempts()] == [0, 2]


def test_without_a_previous_handler_the_signal_only_stops_the_run(tmp_path: Path) -> None:
    cfg = tiny_config(tmp_path, "route_choice", "bc", True, *BC)
    previous = signal.signal(signal.SIGUSR2, signal.SIG_DFL)  # SIGUSR2's default action would kill the process
    try:
        with _interrupt_at(get_class(cfg.algo.trainer), 1, signal.SIGUSR2), pytest.raises(RunInterrupted):
            run(cfg)
    finally:
        signal.signal(signal.SIGUSR2, previous)
    assert RunDirectory(cfg.run_dir).read_status()["status"] == "interrupted"
