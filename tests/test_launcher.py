"""Sweeps on Hydra's submitit launcher (the ``[cluster]`` extra): a 2-job sweep with
``hydra/launcher=processes`` runs each job in its own process and gives the same per-job
results as Hydra's default launcher."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest
import torch
from test_trainers import TINY
from tiny_runs import ALGO, merged

from torchrl_causal.evaluation import load_runs
from torchrl_causal.experiment import load_checkpoint

pytest.importorskip(
    "hydra_plugins.hydra_submitit_launcher", reason="hydra-submitit-launcher is not installed: pip install 'torchrl-causal[cluster]'"
)

REPO = Path(__file__).resolve().parents[1]
SWEEP = ["-m", *merged(["env=route_choice", "algo=bc", "causal=true", "seed=0,1", *TINY, *ALGO["bc"]])]


def run_sweep(root: Path, *extra: str) -> None:
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(REPO), os.environ.get("PYTHONPATH", "")])}
    done = subprocess.run(
        [sys.executable, "-m", "torchrl_causal.train", "-m", *merged([*SWEEP[1:], f"run_root={root}", *extra])],
        capture_output=True,
        text=True,
        env=env,
        cwd=root.parent,
        timeout=600,
    )
    assert done.returncode == 0, done.stderr[-3000:]


def test_local_launcher_runs_jobs_in_their_own_processes_with_the_default_launchers_results(tmp_path: Path) -> None:
    run_sweep(tmp_path / "basic")
    run_sweep(tmp_path / "processes", "hydra/launcher=processes")
    runs = {name: {r.path.relative_to(tmp_path / name): r for r in load_runs(tmp_path / name)} for name in ("basic", "processes")}
    assert sorted(runs["basic"]) == sorted(runs["processes"]) and len(runs["basic"]) == 2
    for job, basic in runs["basic"].items():
        local = runs["processes"][job]
        for regime in ("train", "deploy"):
            assert local.evaluations[regime] == basic.evaluations[regime], (job, regime)
        assert local.curve == basic.curve
        for key, value in load_checkpoint(basic.path / "checkpoints" / "best.pt")["policy"].items():
            assert torch.equal(load_checkpoint(local.path / "checkpoints" / "best.pt")["policy"][key], value), key
        assert json.loads((local.path / "status.json").read_text())["status"] == "complete"

    # submitit's local executor names each job after its process id and logs it there.
    logs = {int(p.parent.name): p.read_text() for p in (tmp_path / "processes" / ".submitit").glob("*/*_0_log.out")}
    assert len(logs) == 2 and os.getpid() not in logs
    pids = {job: [pid for pid, text in logs.items() if f"{run.path} [deploy]" in text] for job, run in runs["processes"].items()}
    assert sorted(len(found) for found in pids.values()) == [1, 1], pids
    assert len({found[0] for found in pids.values()}) == 2  # two jobs, two processes
