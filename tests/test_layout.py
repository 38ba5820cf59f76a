"""The package's layout keeps what was written against the old one working: archived runs
name classes by dotted path, and the README's commands are ``python -m torchrl_causal.<command>``."""

from __future__ import annotations

import importlib
import re
import runpy
import shutil
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import pytest
from hydra.utils import get_object
from omegaconf import OmegaConf

ROOT = Path(__file__).resolve().parents[1]
ARCHIVED_CONFIGS = sorted((ROOT / "results").rglob("config.yaml"))
SHIPPED_CONFIGS = sorted((ROOT / "torchrl_causal" / "conf").rglob("*.yaml"))
DOCUMENTS = sorted([ROOT / "README.md", *(ROOT / "docs").rglob("*.md"), *(ROOT / "results").rglob("*.md")])
# a weights or state file under results/ or the package, as the docs name it (no placeholders)
NAMED_WEIGHTS = re.compile(r"(?:results|torchrl_causal)/[\w./-]+\.pt\b")
COMMANDS = ("train", "evaluate", "report", "status", "archive", "demo", "filmstrip", "strength_ablation")


def _dotted_paths(node: object) -> Iterator[str]:
    """Every ``_target_`` and ``trainer`` value of a config tree (the keys that name code)."""
    if isinstance(node, dict):
        for key, value in node.items():
            if key in ("_target_", "trainer") and isinstance(value, str) and value:
                yield value
            yield from _dotted_paths(value)
    elif isinstance(node, list):
        for item in node:
            yield from _dotted_paths(item)


def _unresolved(configs: list[Path]) -> tuple[set[str], list[str]]:
    """Every dotted path the ``configs`` name, and those of them that do not import (with why)."""
    named = {path for config in configs for path in _dotted_paths(OmegaConf.to_container(OmegaConf.load(config)))}
    unresolved = []
    for path in sorted(named):
        try:
            get_object(path)
        except Exception as error:  # noqa: BLE001 (each failure is reported with its path)
            unresolved.append(f"{path}: {error}")
    return named, unresolved


def test_archived_runs_name_code_that_still_resolves() -> None:
    """Kept import paths, not a migration: every class or function an archived run's
    ``config.yaml`` names (``torchrl_causal.trainers.OffPolicyILTrainer``, the experts at their
    old place ``torchrl_causal.envs.AntMazeExpert``, ...) imports."""
    assert len(ARCHIVED_CONFIGS) >= 10, "the archived runs under results/ are the point of this test"
    named, unresolved = _unresolved(ARCHIVED_CONFIGS)
    assert {"torchrl_causal.trainers.OffPolicyILTrainer", "torchrl_causal.envs.AntMazeExpert"} <= named  # the walk reaches what it is for
    assert not unresolved, unresolved


def test_shipped_configs_name_code_that_resolves() -> None:
    """Every ``_target_`` and ``trainer`` of ``torchrl_causal/conf`` imports, the experts at their new place."""
    named, unresolved = _unresolved(SHIPPED_CONFIGS)
    assert "torchrl_causal.experts.HumanoidMazeExpert" in named and not any(".envs." in path and "Expert" in path for path in named)
    assert not unresolved, unresolved


#: Old import paths (archived configs, the results' commands, other branches) and where each now lives.
OLD_PATHS = {
    "torchrl_causal.envs.AntMazeExpert": "torchrl_causal.experts.policies.AntMazeExpert",
    "torchrl_causal.envs.HumanoidMazeExpert": "torchrl_causal.experts.policies.HumanoidMazeExpert",
    "torchrl_causal.envs.RoverExpert": "torchrl_causal.experts.policies.RoverExpert",
    "torchrl_causal.envs.RouteChoiceExpert": "torchrl_causal.experts.policies.RouteChoiceExpert",
    "torchrl_causal.envs.MazePlanner": "torchrl_causal.experts.planner.MazePlanner",
    "torchrl_causal.envs.experts.RouteChoiceExpert": "torchrl_causal.experts.policies.RouteChoiceExpert",
    "torchrl_causal.envs.planner.MazePlanner": "torchrl_causal.experts.planner.MazePlanner",
    "torchrl_causal.envs.planner.MazeLayout": "torchrl_causal.envs.maze_layout.MazeLayout",
    "torchrl_causal.envs.locomotion.train_locomotion": "torchrl_causal.experts.locomotion.train_locomotion",
    "torchrl_causal.envs.locomotion_ppo.export_learner": "torchrl_causal.experts.locomotion_ppo.export_learner",
    # what left the skill trainers for their shared base, and the builders for transforms/
    "torchrl_causal.experts.locomotion.finish_skill_run": "torchrl_causal.experts.skill_run.finish_skill_run",
    "torchrl_causal.experts.locomotion.upright_speed": "torchrl_causal.experts.skill_run.upright_speed",
    "torchrl_causal.experiment.builders.RelaxedBinaryAction": "torchrl_causal.transforms.actions.RelaxedBinaryAction",
    "torchrl_causal.cli.arguments.OneLineParser": "torchrl_causal.command_line.OneLineParser",
}


@pytest.mark.parametrize("old", sorted(OLD_PATHS))
def test_old_paths_of_the_experts_give_the_same_objects(old: str) -> None:
    assert get_object(old) is get_object(OLD_PATHS[old])


@pytest.mark.parametrize("module", ["locomotion", "locomotion_ppo"])
def test_old_skill_trainer_commands_run_the_same_command_line(module: str, monkeypatch, capsys) -> None:
    """``python -m torchrl_causal.envs.locomotion_ppo --export-from ...`` (as the results quote it)
    runs the command line of :mod:`torchrl_causal.experts.locomotion_ppo`."""
    monkeypatch.setattr("sys.argv", [module, "--help"])
    monkeypatch.delitem(sys.modules, f"torchrl_causal.envs.{module}", raising=False)  # run as python -m would, fresh
    with pytest.raises(SystemExit) as done:
        runpy.run_module(f"torchrl_causal.envs.{module}", run_name="__main__")
    assert done.value.code == 0
    summary = " ".join(str(importlib.import_module(f"torchrl_causal.experts.{module}").__doc__).split("\n\n")[0].split())
    assert summary in " ".join(capsys.readouterr().out.split())  # the new module's own command line


@pytest.mark.parametrize("command", COMMANDS)
def test_readme_command_paths_run_the_cli(command: str) -> None:
    """``python -m torchrl_causal.<command>`` runs the command line of :mod:`torchrl_causal.cli`."""
    shim = importlib.import_module(f"torchrl_causal.{command}")
    assert shim.main is importlib.import_module(f"torchrl_causal.cli.{command}").main


def _weights_named_in_docs() -> list[str]:
    return sorted({match for document in DOCUMENTS for match in NAMED_WEIGHTS.findall(document.read_text())})


def test_the_weights_the_docs_name_are_files_git_keeps() -> None:
    """A resume state or shipped weights file the docs tell a user to resume from is committed:
    ``*.pt`` is ignored, so each such path needs its exception in ``.gitignore`` (the PPO resume
    states of three sessions were named here and silently never committed)."""
    if shutil.which("git") is None or not (ROOT / ".git").exists():
        pytest.skip("not a git checkout")
    named = _weights_named_in_docs()
    assert "torchrl_causal/envs/assets/ant_locomotion.pt" in named  # the scan reaches what it is for
    ignored = subprocess.run(
        ["git", "check-ignore", "--no-index", *named], cwd=ROOT, capture_output=True, text=True, check=False
    ).stdout.split()
    assert not ignored, f"named in the docs but ignored by .gitignore: {ignored}"
    missing = [path for path in named if path.startswith("results/") and not (ROOT / path).is_file()]
    assert not missing, f"named in the docs but not in the repository: {missing}"
