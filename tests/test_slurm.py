"""The SLURM launcher (``hydra/launcher=slurm``, the ``[cluster]`` extra) composes and
writes a sane job: a fake ``sbatch`` on ``PATH`` captures the script submitit generates."""

from __future__ import annotations

import os
import re
import stat
import subprocess
import sys
from pathlib import Path

import pytest

from torchrl_causal.experiment import compose_config

pytest.importorskip(
    "hydra_plugins.hydra_submitit_launcher", reason="hydra-submitit-launcher is not installed: pip install 'torchrl-causal[cluster]'"
)

REPO = Path(__file__).resolve().parents[1]
FAKE_SBATCH = """#!/bin/sh
# Keeps the job script submitit hands to sbatch, then refuses it: nothing runs.
cp "$1" "{capture}"
echo "sbatch: error: a fake sbatch for tests" >&2
exit 1
"""


def _launcher(*overrides: str):
    from hydra import compose, initialize_config_dir

    from torchrl_causal.experiment.config import CONFIG_DIR, CONFIG_NAME

    with initialize_config_dir(config_dir=str(CONFIG_DIR), version_base="1.3"):
        cfg = compose(config_name=CONFIG_NAME, overrides=["hydra/launcher=slurm", *overrides], return_hydra_config=True)
    return cfg


def test_slurm_launcher_composes_with_requeue_and_the_runs_cores() -> None:
    compose_config()  # registers the schemas and resolvers
    cfg = _launcher("threads=2", "collector_workers=3")
    launcher = cfg.hydra.launcher
    assert launcher._target_.endswith("SlurmLauncher")
    assert launcher.cpus_per_task == 6  # threads x collector_workers
    assert launcher.max_num_timeout > 0 and launcher.additional_parameters.requeue is True
    assert 60 <= launcher.timeout_min <= 24 * 60  # within a usual partition's limit
    assert _launcher("hydra.launcher.timeout_min=90").hydra.launcher.timeout_min == 90


def test_a_job_asks_a_gpu_only_for_a_cuda_run() -> None:
    compose_config()  # registers the schemas and resolvers
    assert _launcher("device=cuda").hydra.launcher.gpus_per_node == 1
    assert _launcher("device=cuda:1").hydra.launcher.gpus_per_node == 1
    assert _launcher("device=cpu").hydra.launcher.gpus_per_node is None  # no --gpus-per-node line
    assert _launcher().hydra.launcher.gpus_per_node is None  # the default device is the CPU


def test_fake_sbatch_receives_a_sane_job(tmp_path: Path) -> None:
    bin_dir = tmp_path / "bin"
    bin_dir.mkdir()
    capture = tmp_path / "job.sh"
    # submitit looks for srun on PATH before it writes the job; only sbatch is called.
    for name, text in (("sbatch", FAKE_SBATCH.format(capture=capture)), ("srun", "#!/bin/sh\nexit 1\n")):
        (bin_dir / name).write_text(text)
        (bin_dir / name).chmod((bin_dir / name).stat().st_mode | stat.S_IXUSR)
    env = {
        **os.environ,
        "PATH": f"{bin_dir}{os.pathsep}{os.environ['PATH']}",
        "PYTHONPATH": os.pathsep.join([str(REPO), os.environ.get("PYTHONPATH", "")]),
    }
    command = [
        sys.executable,
        "-m",
        "torchrl_causal.train",
        "-m",
        "hydra/launcher=slurm",
        "hydra.launcher.partition=gpu",
        "hydra.launcher.timeout_min=240",
        "device=cuda",  # the submitting node needs no GPU: each job checks its own
        "threads=2",
        "collector_workers=2",
        "env=route_choice",
        "algo=bc",
        f"run_root={tmp_path / 'runs'}",
    ]
    done = subprocess.run(command, capture_output=True, text=True, env=env, cwd=tmp_path, timeout=300)
    assert done.returncode != 0 and "a fake sbatch for tests" in done.stderr, done.stderr[-3000:]
    script = capture.read_text()
    flags = dict(re.findall(r"^#SBATCH --([\w-]+)(?:=(.*))?$", script, flags=re.M))
    assert flags["time"] == "240" and flags["partition"] == "gpu"
    assert "requeue" in flags and flags["signal"].startswith("USR2@")
    assert flags["cpus-per-task"] == "4" and flags["gpus-per-node"] == "1"
    # The job runs the interpreter that submitted it (the venv's), through submitit.
    assert f"{sys.executable} -u -m submitit.core._submit" in script
    assert not list((tmp_path / "runs").rglob("status.json"))  # nothing ran


def test_without_sbatch_the_sweep_is_refused_in_one_line(tmp_path: Path) -> None:
    bin_dir = tmp_path / "bin"
    bin_dir.mkdir()
    python = Path(sys.executable)
    env = {
        **os.environ,
        # the interpreter's folder and the system's, where no sbatch is: as on a machine with no cluster
        "PATH": os.pathsep.join([str(python.parent), "/usr/bin", "/bin"]),
        "PYTHONPATH": os.pathsep.join([str(REPO), os.environ.get("PYTHONPATH", "")]),
    }
    assert not any((Path(folder) / "sbatch").exists() for folder in env["PATH"].split(os.pathsep))
    command = [sys.executable, "-m", "torchrl_causal.train", "-m", "hydra/launcher=slurm", "env=route_choice", "algo=bc"]
    done = subprocess.run([*command, f"run_root={tmp_path / 'runs'}"], capture_output=True, text=True, env=env, cwd=tmp_path, timeout=300)
    lines = [line for line in done.stderr.splitlines() if line.strip()]
    assert done.returncode == 1 and "Traceback" not in done.stderr, done.stderr[-3000:]
    assert len(lines) == 1 and "sbatch, which is not on PATH" in lines[0] and "hydra/launcher=processes" in lines[0]
    assert not (tmp_path / "runs").exists()
