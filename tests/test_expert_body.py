"""The expert's body (issue 57): every run records the skill weights its expert walks, and
re-evaluating an expert row walks that body or refuses, in one line, a file that is missing,
swapped, or a record that names none."""

from __future__ import annotations

import hashlib
import shutil
from pathlib import Path

import pytest
import torch
from omegaconf import OmegaConf

from torchrl_causal.experiment import compose_config
from torchrl_causal.experiment.expert_body import ExpertBody, ExpertBodyError, recorded_body, weights_digest
from torchrl_causal.experiment.run_directory import EXPERT_BODY_KEY, ConfigMismatchError, RunDirectory, config_digest
from torchrl_causal.experts.skills import HUMANOID_LOCOMOTION_BODIES, LOCOMOTION_WEIGHTS
from torchrl_causal.lifecycle import evaluate_run, run

PACKAGE_PARENT = Path(__file__).resolve().parents[1]
STEADY, FAST = HUMANOID_LOCOMOTION_BODIES["steady"][0], HUMANOID_LOCOMOTION_BODIES["fast"][0]
ARCHIVED_EXPERT = PACKAGE_PARENT / "results/runs/humanoidmaze/humanoidmaze_medium/h2000-cs1.0-k2/expert/seed0"

#: A maze expert row that costs a few seconds: 12 steps, 2 episodes per regime.
TINY_EXPERT = [
    "algo=expert",
    "env.horizon=12",
    "progress_bar=false",
    "threads=1",
    "eval.final_episodes=2",
    "eval.num_envs=2",
    "eval.trajectories=0",
]


def independent_digest(path: Path) -> str:
    """SHA-256 over a state dict's tensors by sorted name, written here from the definition."""
    digest = hashlib.sha256()
    for name, value in sorted(torch.load(path, map_location="cpu", weights_only=True).items()):
        digest.update(f"{name}:{value.dtype}:{tuple(value.shape)}".encode())
        digest.update(value.detach().contiguous().numpy().tobytes())
    return digest.hexdigest()


def expert_row(root: Path, env: str, *extra: str) -> Path:
    """Runs the tiny expert row of ``env`` under ``root``; its run directory."""
    cfg = compose_config([f"env={env}", *TINY_EXPERT, f"run_root={root}", *extra])
    run(cfg)
    return Path(cfg.run_dir)


@pytest.mark.parametrize(
    ("env", "expected"),
    [
        ("antmaze_medium", LOCOMOTION_WEIGHTS),
        ("humanoidmaze_medium", STEADY),
        ("humanoidmaze_large", FAST),
        ("rovermaze_medium", None),
    ],
)
def test_every_shipped_expert_row_records_the_body_it_walked(tmp_path: Path, env: str, expected: Path | None) -> None:
    """The stored config names the file each shipped env's expert walks (the humanoid's differ by
    maze: issue 57) and its digest; RoverMaze's scripted expert records that it walks none."""
    stored = OmegaConf.load(expert_row(tmp_path, env) / "config.yaml")
    record = OmegaConf.to_container(OmegaConf.select(stored, EXPERT_BODY_KEY))
    if expected is None:
        assert record == {"weights": None, "sha256": None}
        return
    assert not Path(record["weights"]).is_absolute()  # a shipped body is named below the package: archives travel
    assert (PACKAGE_PARENT / record["weights"]).resolve() == expected.resolve()
    assert record["sha256"] == independent_digest(expected)


def test_the_two_humanoid_bodies_have_different_digests_and_a_resave_keeps_one(tmp_path: Path) -> None:
    copy = tmp_path / "resaved.pt"
    torch.save({name: value.clone() for name, value in torch.load(STEADY, weights_only=True).items()}, copy)
    assert weights_digest(STEADY) != weights_digest(FAST)
    assert weights_digest(copy) == weights_digest(STEADY)


def test_a_reevaluation_with_a_swapped_body_file_is_refused(tmp_path: Path, capsys) -> None:
    """A run of one's own body (a copy of the steady file); the file then holds the fast body:
    the expert row is refused, in one line naming the field, not evaluated with the new body."""
    from torchrl_causal.cli.evaluate import main as evaluate_main

    body = tmp_path / "body.pt"
    shutil.copyfile(STEADY, body)
    run_dir = expert_row(tmp_path / "runs", "humanoidmaze_medium", f"env.expert.weights={body}")
    assert recorded_body(RunDirectory(run_dir).read_config()) == ExpertBody(str(body.resolve()), independent_digest(STEADY))
    first = evaluate_run(run_dir, "deploy", 1, num_envs=1, save=False)
    assert first.n_episodes == 1

    shutil.copyfile(FAST, body)
    with pytest.raises(ExpertBodyError, match=r"env\.expert_body\.sha256=.* now holds another body") as error:
        evaluate_run(run_dir, "deploy", 1, num_envs=1, save=False)
    assert "\n" not in str(error.value)
    with pytest.raises(SystemExit, match=r"^error: env\.expert_body\.sha256=") as exited:
        evaluate_main([f"run_dir={run_dir}", "episodes=1", "num_envs=1", "save=false"])
    assert "\n" not in str(exited.value)

    body.unlink()
    with pytest.raises(FileNotFoundError, match=r"env\.expert_body\.weights=.*body\.pt: that file does not exist"):
        evaluate_run(run_dir, "deploy", 1, num_envs=1, save=False)


def test_the_recorded_body_wins_over_the_weights_the_config_names(tmp_path: Path) -> None:
    """The stored config says ``weights: fast`` but records the steady body: the expert rebuilt
    from it walks the steady tensors."""
    from torchrl_causal.envs import HumanoidMazeEnv
    from torchrl_causal.experiment.builders import make_expert

    cfg = OmegaConf.create({"env": {"expert": {"_target_": "torchrl_causal.experts.HumanoidMazeExpert", "weights": "fast"}}})
    OmegaConf.update(cfg, EXPERT_BODY_KEY, {"weights": str(STEADY), "sha256": weights_digest(STEADY)}, force_add=True)
    expert = make_expert(cfg, HumanoidMazeEnv("medium", batch_size=1, seed=0))
    steady = torch.load(STEADY, weights_only=True)
    walked = expert.locomotion.state_dict()
    assert set(walked) == set(steady) and all(torch.equal(walked[name], steady[name]) for name in steady)


@pytest.fixture(scope="module")
def steady_row(tmp_path_factory) -> Path:
    """A tiny HumanoidMaze-Medium expert row, which records the steady body (read only: copy it to edit it)."""
    return expert_row(tmp_path_factory.mktemp("steady"), "humanoidmaze_medium")


def test_an_expert_row_without_the_record_is_refused_unless_told_which_body(tmp_path: Path, steady_row: Path) -> None:
    run_dir = Path(shutil.copytree(steady_row, tmp_path / "old"))
    stored = OmegaConf.load(run_dir / "config.yaml")
    del stored.env["expert_body"]  # as rows made before the record were written
    (run_dir / "config.yaml").write_text(OmegaConf.to_yaml(stored))
    with pytest.raises(ExpertBodyError, match=r"records no expert body \(env\.expert_body.*expert_weights=") as error:
        evaluate_run(run_dir, "deploy", 1, num_envs=1, save=False)
    assert "\n" not in str(error.value)
    assert evaluate_run(run_dir, "deploy", 1, num_envs=1, save=False, expert_weights="steady").n_episodes == 1


def test_an_override_that_names_another_body_than_the_record_is_refused(steady_row: Path) -> None:
    with pytest.raises(ExpertBodyError, match=r"expert_weights=fast is another body"):
        evaluate_run(steady_row, "deploy", 1, num_envs=1, save=False, expert_weights="fast")


def test_a_scripted_expert_row_without_the_record_still_evaluates(tmp_path: Path) -> None:
    """RoverMaze's expert walks no weights file: a row made before the record has nothing to choose."""
    run_dir = expert_row(tmp_path, "rovermaze_u")
    stored = OmegaConf.load(run_dir / "config.yaml")
    del stored.env["expert_body"]
    (run_dir / "config.yaml").write_text(OmegaConf.to_yaml(stored))
    assert evaluate_run(run_dir, "deploy", 2, num_envs=2, save=False).n_episodes == 2


def test_the_archived_humanoidmaze_medium_expert_row_walks_the_steady_body() -> None:
    """Its record was added by hand (it predates the record): it names the steady file and that
    file holds the body it names."""
    cfg = RunDirectory(ARCHIVED_EXPERT).read_config()
    body = recorded_body(cfg)
    assert body is not None and body.verified_file() == STEADY.resolve()


# -- claiming a run directory -------------------------------------------------------------------


def tiny_claim_config(root: Path):
    return compose_config(["env=rovermaze_u", "algo=expert", f"run_root={root}"])


def test_claim_refuses_another_body_and_stamps_only_runs_that_are_not_complete(tmp_path: Path) -> None:
    cfg = tiny_claim_config(tmp_path)
    run_dir = RunDirectory(cfg.run_dir)
    run_dir.path.mkdir(parents=True)
    one, other = {"weights": "a.pt", "sha256": "1" * 64}, {"weights": "a.pt", "sha256": "2" * 64}
    run_dir.claim(cfg, recorded={EXPERT_BODY_KEY: one})
    assert OmegaConf.to_container(OmegaConf.select(run_dir.read_config(), EXPERT_BODY_KEY)) == one
    with pytest.raises(ConfigMismatchError, match=r"env\.expert_body: .*'1111.*-> .*'2222"):
        run_dir.claim(cfg, recorded={EXPERT_BODY_KEY: other})
    run_dir.claim(cfg, recorded={EXPERT_BODY_KEY: one})  # the same body: accepted

    # a run made before the record: a complete one stays without it, an unfinished one gets it
    run_dir.claim(cfg)
    assert OmegaConf.select(run_dir.read_config(), EXPERT_BODY_KEY) is None
    run_dir.write_status("complete", total=0, progress=0)
    run_dir.claim(cfg, recorded={EXPERT_BODY_KEY: one})
    assert OmegaConf.select(run_dir.read_config(), EXPERT_BODY_KEY) is None
    run_dir.write_status("interrupted", total=0, progress=0)
    run_dir.claim(cfg, recorded={EXPERT_BODY_KEY: one})
    assert OmegaConf.to_container(OmegaConf.select(run_dir.read_config(), EXPERT_BODY_KEY)) == one


def test_the_config_digest_leaves_the_body_record_out() -> None:
    """A run resumed across the record's introduction keeps its selected policy's identity."""
    base = {"seed": 0, "env": {"name": "x", "expert": {"_target_": "E"}}}
    recorded = {"seed": 0, "env": {"name": "x", "expert": {"_target_": "E"}, "expert_body": {"weights": "a.pt", "sha256": "1"}}}
    assert config_digest(base) == config_digest(recorded)
    assert config_digest(base) != config_digest({**base, "seed": 1})
