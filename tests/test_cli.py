"""``python -m torchrl_causal.train`` as a user runs it: a bad config stops with one line
and leaves nothing behind; Ctrl-C checkpoints, marks the run and says how to resume;
redirected output gets plain progress lines."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest
from tiny_runs import merged, tiny

# No budget: the Ctrl-C test sets one long enough to interrupt; progress bars as a user gets them.
TINY = tiny("sqil", "algo.buffer_size=100000", "progress_bar=true")


@pytest.fixture
def train_process() -> Iterator[Callable[..., subprocess.Popen]]:
    """Starts ``python -m torchrl_causal.train`` on a tiny run; kills what is still running at
    teardown, so a failed or timed-out test leaves no training behind."""
    started: list[subprocess.Popen] = []

    def start(root: Path, *overrides: str) -> subprocess.Popen:
        process = subprocess.Popen(
            [sys.executable, "-m", "torchrl_causal.train", *merged([f"run_root={root}", *TINY, *overrides])],
            cwd=root.parent,
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
            env={**os.environ, "OMP_NUM_THREADS": "1"},
        )
        started.append(process)
        return process

    yield start
    for process in started:
        if process.poll() is None:
            process.kill()
            process.communicate(timeout=60)


def test_an_out_of_range_value_stops_with_one_line_and_no_run_directory(tmp_path: Path) -> None:
    from torchrl_causal.cli.train import main
    from torchrl_causal.experiment import compose_config

    root = tmp_path / "runs"
    cfg = compose_config([f"run_root={root}", *TINY, "eval.final_episodes=0"])
    with pytest.raises(SystemExit) as stop:
        main.__wrapped__(cfg)  # the task function Hydra calls, without Hydra's own argv parsing
    assert str(stop.value.code) == "error: config value eval.final_episodes=0 is out of range: it must be >= 1"
    assert not root.exists()


def test_ctrl_c_checkpoints_marks_the_run_and_prints_how_to_resume(tmp_path: Path, train_process: Callable[..., subprocess.Popen]) -> None:
    root = tmp_path / "runs"
    process = train_process(root, "algo.total_steps=1000000", "algo.eval_every=100000", "checkpoint_every_s=3600")
    status_file = None
    deadline = time.monotonic() + 300
    while time.monotonic() < deadline and process.poll() is None:
        found = list(root.rglob("status.json")) if root.exists() else []
        if found and json.loads(found[0].read_text() or "{}").get("status") == "running":
            status_file = found[0]
            break
        time.sleep(0.5)
    assert status_file is not None, process.communicate(timeout=10)
    time.sleep(2.0)  # a few training iterations
    process.send_signal(signal.SIGINT)
    stdout, stderr = process.communicate(timeout=300)
    assert process.returncode == 130, stderr[-3000:]
    assert "Traceback" not in stderr and "\r" not in stdout + stderr
    last = stderr.strip().splitlines()[-1]
    assert "interrupted by SIGINT at " in last and "checkpoint saved. Resume with: python -m torchrl_causal.train" in last
    assert f"run_root={root}" in last and "algo.total_steps=1000000" in last
    status = json.loads(status_file.read_text())
    assert status["status"] == "interrupted" and status["progress"] > 0
    checkpoint = status_file.parent / "checkpoints" / "last.pt"
    assert checkpoint.is_file() and (status_file.parent / "replay" / "storage").is_dir()
    assert "SIGINT received" in (status_file.parent / "train.log").read_text()
