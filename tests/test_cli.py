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


# ---------------------------------------------------------------- every command explains itself

KEY_VALUE_COMMANDS = ("evaluate", "report", "status", "archive", "demo", "filmstrip", "strength_ablation")


@pytest.mark.parametrize("command", KEY_VALUE_COMMANDS)
@pytest.mark.parametrize("flag", ["--help", "-h"])
def test_every_command_answers_help_with_its_options_defaults_and_an_example(command: str, flag: str, capsys) -> None:
    import importlib

    from torchrl_causal.cli.arguments import REQUIRED

    module = importlib.import_module(f"torchrl_causal.cli.{command}")
    with pytest.raises(SystemExit) as stop:
        module.main([flag])
    assert stop.value.code == 0
    out = capsys.readouterr().out
    lines = out.splitlines()
    assert lines[0].startswith(f"usage: python -m torchrl_causal.{command}")
    example = [line for line in lines if line.startswith("example: ")]
    assert len(example) == 1 and (f"torchrl_causal.{command}" in example[0] or "make demo" in example[0])
    options = getattr(module, "OPTIONS", {})
    for name, option in options.items():
        (line,) = [line for line in lines if line.startswith(f"  {name}=")]
        if option.default is REQUIRED:
            assert "(required)" in line, line
        elif option.default is not None and not option.placeholder:
            assert line.startswith(f"  {name}={option.shown(name)} "), line  # its default
    if not options:
        assert "options: none" in lines


def test_help_names_a_commands_help(capsys) -> None:
    from torchrl_causal.cli import main

    with pytest.raises(SystemExit) as stop:
        main(["help", "evaluate"])
    assert stop.value.code == 0
    out = capsys.readouterr().out
    assert out.startswith("usage: python -m torchrl_causal.evaluate run_dir=<dir>") and "  episodes=1000 " in out


def test_python_m_torchrl_causal_cli_help_works() -> None:
    done = subprocess.run([sys.executable, "-m", "torchrl_causal.cli", "help"], capture_output=True, text=True, timeout=120)
    assert done.returncode == 0 and done.stderr == ""
    assert done.stdout.splitlines()[1] == "commands: train, evaluate, report, status, archive, demo, filmstrip, strength_ablation"


def test_a_key_given_twice_is_refused_in_one_line() -> None:
    from torchrl_causal.cli.evaluate import main

    with pytest.raises(SystemExit) as stop:
        main(["run_dir=somewhere", "episodes=4", "episodes=8"])
    assert stop.value.code == "error: episodes is given twice (episodes=4, then episodes=8): give it once"


def test_train_help_lists_only_options_that_run(monkeypatch, capsys) -> None:
    from torchrl_causal.algorithms import ALGORITHMS
    from torchrl_causal.cli.train import main

    monkeypatch.setattr(sys, "argv", ["train", "--help"])
    try:
        main()
    except SystemExit as stop:
        assert stop.code in (0, None)
    out = capsys.readouterr().out
    assert "schema" not in out
    (algo,) = [line for line in out.splitlines() if line.startswith("algo: ")]
    assert algo == "algo: " + ", ".join(sorted(entry.name for entry in ALGORITHMS))
    (logger,) = [line for line in out.splitlines() if line.startswith("logger: ")]
    assert logger == "logger: csv, tensorboard, wandb"
    assert "example: python -m torchrl_causal.train " in out


def test_an_internal_schema_is_no_algo_choice() -> None:
    from hydra.errors import MissingConfigException

    from torchrl_causal.experiment import compose_config

    with pytest.raises(MissingConfigException) as refused:
        compose_config(["algo=schema_bc"])
    from torchrl_causal.algorithms import ALGORITHMS

    # Hydra's line after "Available options in 'algo':" lists them, one per line, then its search path
    listed = str(refused.value).split("Available options in 'algo':", 1)[1].split("Config search path", 1)[0]
    assert sorted(listed.split()) == sorted(entry.name for entry in ALGORITHMS)


def test_a_run_root_on_a_file_system_that_stores_no_files_is_refused_in_one_line() -> None:
    import shutil

    from torchrl_causal.experiment import ConfigValueError, compose_config
    from torchrl_causal.lifecycle import run

    if not Path("/proc").is_dir() or shutil.disk_usage("/proc").total != 0:
        pytest.skip("no procfs here")
    cfg = compose_config([*TINY, "run_root=/proc/torchrl_causal_runs"])
    with pytest.raises(ConfigValueError, match=r"lies below /proc, on a file system that stores no files .*choose another run_root$"):
        run(cfg)
    assert not Path("/proc/torchrl_causal_runs").exists()


def test_a_checkpoint_that_cannot_be_written_is_one_line_naming_it(tmp_path: Path, monkeypatch) -> None:
    import torch

    from torchrl_causal.cli.arguments import one_line_errors
    from torchrl_causal.errors import TorchRLCausalError
    from torchrl_causal.experiment.run_directory import CheckpointWriteError, atomic_save

    def full_disk(obj, file):  # what torch.save raises when a write fails (disk full, file size limit)
        Path(file).write_bytes(b"partial")
        raise RuntimeError("[enforce fail at inline_container.cc:672] . unexpected pos 3456 vs 3344")

    monkeypatch.setattr(torch, "save", full_disk)
    target = tmp_path / "checkpoints" / "last.pt"
    target.parent.mkdir()
    with pytest.raises(CheckpointWriteError) as refused:  # the library's own refusal, an OSError naming the file
        atomic_save({"x": 1}, target)
    assert isinstance(refused.value, TorchRLCausalError) and refused.value.filename == str(target)
    with pytest.raises(SystemExit) as stop, one_line_errors():
        atomic_save({"x": 1}, target)
    assert str(stop.value.code).startswith(f"error: {target}: cannot write this checkpoint (a full disk or a file size limit?)")
    assert "\n" not in str(stop.value.code)
    assert list(target.parent.iterdir()) == []  # no partial file left behind
