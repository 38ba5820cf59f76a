"""docs/extending.md's worked example holds: applied to a copy of the package (each code
block written to the file its caption names, each registry line added to the tuple its
caption names), it changes no other file, the new loss trains and evaluates on the new
env through ``torchrl-causal train``, the loss is the pseudo-Huber function, and the new
command prints the window the README gives for the rover."""

from __future__ import annotations

import filecmp
import json
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PAGE = ROOT / "docs" / "extending.md"
BLOCK = re.compile(r"```\{code-block\} \w+\n:caption: (?P<caption>[^\n]+)\n\n(?P<body>.*?)```", re.DOTALL)
REGISTRY = re.compile(r"(?P<path>\S+), one line added to (?P<name>\w+)$")


def _blocks() -> list[tuple[str, str]]:
    return [(match["caption"], match["body"]) for match in BLOCK.finditer(PAGE.read_text())]


def _add_to_tuple(source: str, name: str, line: str) -> str:
    """``source`` with ``line`` added as the last item of the multi-line tuple ``name = (...)``."""
    start = re.search(rf"^{name}\b[^=\n]*= \($", source, re.MULTILINE)
    assert start is not None, f"no multi-line tuple {name} = ( to add a line to"
    end = source.index("\n)", start.end())
    return source[:end] + "\n" + line.rstrip("\n") + source[end:]


def _apply(package: Path) -> tuple[set[str], set[str]]:
    """Applies the page to ``package``'s parent; returns (new files, files given a registry line)."""
    new, registries = set(), set()
    for caption, body in _blocks():
        registry = REGISTRY.match(caption)
        if registry:
            target = package.parent / registry["path"]
            assert body.strip().count("\n") == 0, f"{caption}: a registry edit is one line"
            target.write_text(_add_to_tuple(target.read_text(), registry["name"], body))
            registries.add(registry["path"])
        else:
            target = package.parent / caption
            assert not target.exists(), f"{caption} exists already: the example must add, not replace"
            target.write_text(body)
            new.add(caption)
    return new, registries


def _changed(original: Path, copy: Path) -> set[str]:
    """Paths (relative to the package's parent) that differ between two package trees or exist in one only."""
    changed: set[str] = set()

    def walk(compare: filecmp.dircmp, prefix: str) -> None:
        changed.update(f"{prefix}/{name}" for name in [*compare.left_only, *compare.right_only, *compare.diff_files])
        for name, sub in compare.subdirs.items():
            walk(sub, f"{prefix}/{name}")

    walk(filecmp.dircmp(original, copy, ignore=["__pycache__"]), original.name)
    return changed


def test_the_page_names_one_module_config_and_registry_line_per_addition() -> None:
    captions = [caption for caption, _ in _blocks()]
    assert captions == [
        "torchrl_causal/objectives/pseudo_huber_bc.py",
        "torchrl_causal/conf/algo/pseudo_huber_bc.yaml",
        "torchrl_causal/algorithms.py, one line added to ALGORITHMS",
        "torchrl_causal/envs/rover_wide_goal.py",
        "torchrl_causal/conf/env/rovermaze_u_wide_goal.yaml",
        "torchrl_causal/cli/window.py",
        "torchrl_causal/cli/__init__.py, one line added to COMMANDS",
    ]


SCRIPT = r"""
import contextlib, io, json, sys, torch
from torchrl.data import Bounded
from tensordict import TensorDict
from torchrl_causal.cli import main
from torchrl_causal.modules import make_deterministic_actor
from torchrl_causal.objectives.pseudo_huber_bc import PseudoHuberBCLoss

out = io.StringIO()
with contextlib.redirect_stdout(out):
    main(["window", "env=rovermaze_u_wide_goal", "k=2"])
# the loss against its closed form, elementwise errors x = a - a*: delta^2 (sqrt(1 + (x/delta)^2) - 1)
spec = Bounded(-1.0, 1.0, shape=(2,))
actor = make_deterministic_actor(3, spec, hidden=8, num_blocks=1)
batch = TensorDict({"observation": torch.randn(64, 3), "action": spec.rand((64,))}, [64])
predicted = actor(batch.clone())["action"]
loss = PseudoHuberBCLoss(actor, delta=0.3)(batch)["loss_bc"].item()
x = (predicted - batch["action"]).double()
expected = (0.09 * (torch.sqrt(1 + (x / 0.3) ** 2) - 1)).mean().item()
json.dump({"window": out.getvalue(), "loss": loss, "expected": expected}, open(sys.argv[1], "w"))
main(["train", *sys.argv[2:]])  # last: Hydra's main may end the process
"""


@pytest.mark.slow
def test_the_worked_example_trains_and_runs_touching_nothing_else(tmp_path: Path) -> None:
    package = tmp_path / "src" / "torchrl_causal"
    shutil.copytree(ROOT / "torchrl_causal", package, ignore=shutil.ignore_patterns("__pycache__"))
    new, registries = _apply(package)
    assert registries == {"torchrl_causal/algorithms.py", "torchrl_causal/cli/__init__.py"}
    assert _changed(ROOT / "torchrl_causal", package) == new | registries  # nothing else touched
    for path in registries:
        before, after = (ROOT / path).read_text().splitlines(), (package.parent / path).read_text().splitlines()
        assert len(after) == len(before) + 1 and [line for line in after if line not in before] != []

    runs, result = tmp_path / "runs", tmp_path / "result.json"
    overrides = [
        "env=rovermaze_u_wide_goal",
        "algo=pseudo_huber_bc",
        "causal=true",
        "env.horizon=40",
        "window.k=2",
        "demos.episodes=6",
        "eval.episodes=4",
        "eval.num_envs=4",
        "eval.final_episodes=4",
        "algo.actor.hidden=16",
        "algo.actor.num_blocks=1",
        "algo.epochs=2",
        "algo.batch_size=64",
        "algo.eval_every=2",
        "threads=1",
        "progress_bar=false",
        f"run_root={runs}",
    ]
    env = {**os.environ, "PYTHONPATH": str(package.parent), "OMP_NUM_THREADS": "1"}
    done = subprocess.run([sys.executable, "-c", SCRIPT, str(result), *overrides], cwd=tmp_path, env=env, capture_output=True, text=True)
    assert done.returncode == 0, done.stderr[-3000:]
    found = json.loads(result.read_text())
    assert found["window"].splitlines() == ["P: lags 0, 1, 2", "L: lags 0, 1, 2", "X: lags 1, 2", "left out: W"]
    assert found["loss"] == pytest.approx(found["expected"], rel=1e-5)
    (run_dir,) = runs.glob("rovermaze_u_wide_goal/*/c_pseudo_huber_bc/seed0")
    assert "PseudoHuberBCLoss" in (run_dir / "config.yaml").read_text()
    assert "WideGoalRoverMazeEnv" in (run_dir / "config.yaml").read_text()
    assert list((run_dir / "eval").glob("*.json")), sorted(p.name for p in run_dir.rglob("*"))
