"""The walking-skill PPO trainer: its normaliser, the folded export, a tiny humanoid run and its resume.

Budgets are tiny (hidden 16, 4 envs x 16 steps); the checks are closed forms (merged statistics,
folded layers), counts that follow from the config, and what travels in the resume state.
"""

from __future__ import annotations

import json
import math
from dataclasses import replace
from pathlib import Path

import pytest
import torch
from tensordict import TensorDict
from torchrl.envs.utils import ExplorationType, set_exploration_type

from torchrl_causal.experts.locomotion import SKILLS, make_locomotion_actor
from torchrl_causal.experts.locomotion_ppo import (
    ADAPTIVE_LR_BOUNDS,
    PPOLocomotionConfig,
    RunningNormalisation,
    adapt_learning_rate,
    fold_observation_normalisation,
    gaussian_kl,
    make_ppo_actor,
    train_locomotion_ppo,
)

FRAMES = 4 * 16


def _config(total_steps: int, **changes) -> PPOLocomotionConfig:
    base = {"num_envs": 4, "rollout_steps": 16, "minibatch_size": 32, "epochs": 2, "hidden": 16, "eval_every": 2 * FRAMES}
    return PPOLocomotionConfig(total_steps=total_steps, eval_envs=2, eval_steps=10, **{**base, **changes})


@pytest.mark.parametrize("seed", range(5))
def test_merged_statistics_are_those_of_all_the_data(seed: int) -> None:
    generator = torch.Generator().manual_seed(seed)
    data = torch.randn(300, 3, generator=generator) * torch.tensor([1.0, 10.0, 0.1]) + torch.tensor([5.0, -2.0, 0.0])
    cuts = sorted(torch.randint(1, 299, (3,), generator=generator).tolist())
    norm = RunningNormalisation(3)
    for part in torch.tensor_split(data, cuts):
        if len(part):
            norm.update(part)
    assert int(norm.count) == 300
    torch.testing.assert_close(norm.mean, data.mean(0), rtol=1e-5, atol=1e-5)
    torch.testing.assert_close(norm.var, data.var(0, unbiased=False), rtol=1e-4, atol=1e-5)


def test_the_folded_body_acts_as_the_ppo_actor_and_loads_into_the_skill_network() -> None:
    skill = SKILLS["humanoid"]
    norm, body = RunningNormalisation(skill.observation_dim), skill.network(32)
    norm.update(torch.randn(500, skill.observation_dim) * 4 + 2)
    observation = TensorDict(observation=torch.randn(7, skill.observation_dim) * 4 + 2, batch_size=[7])
    shipped = skill.network(32)  # what the maze expert builds before loading the weights
    shipped.load_state_dict(fold_observation_normalisation(norm, body).state_dict())
    with set_exploration_type(ExplorationType.DETERMINISTIC):
        ppo_action = make_ppo_actor(body, norm)(observation.clone())["action"]
        sac_action = make_locomotion_actor(shipped)(observation.clone())["action"]
    torch.testing.assert_close(ppo_action, sac_action, atol=1e-5, rtol=1e-5)
    assert torch.equal(shipped[2].weight, body[2].weight)  # only the first layer changes


def test_a_run_resumes_from_its_small_state_on_another_machine(tmp_path) -> None:
    first = train_locomotion_ppo(tmp_path / "a", _config(2 * FRAMES), output=tmp_path / "a.pt", progress_bar=False)
    assert first["steps"] == 2 * FRAMES and (tmp_path / "a.pt").exists()
    state_file = tmp_path / "a" / "resume_state.pt"
    state = torch.load(state_file, weights_only=True)
    assert state["algorithm"] == "ppo" and state["counters"]["iterations"] == 2 and state["optimizer"]["state"]
    means = [key for key in state["loss"] if key.endswith(".count")]
    assert means and all(int(state["loss"][key]) == 2 * FRAMES for key in means)  # the normaliser travels
    assert set(state["best_body"]) == set(SKILLS["humanoid"].network(16).state_dict())

    second = train_locomotion_ppo(tmp_path / "b", _config(3 * FRAMES), resume_from=state_file, progress_bar=False)
    assert second["steps"] == 3 * FRAMES
    resumed = torch.load(tmp_path / "b" / "resume_state.pt", weights_only=True)
    assert resumed["counters"]["iterations"] == 3 and resumed["counters"]["collect_seed"] == state["counters"]["collect_seed"] + 1
    assert all(int(resumed["loss"][key]) == 3 * FRAMES for key in means)
    weight = next(key for key in state["loss"] if key.endswith("weight"))
    assert not torch.equal(resumed["loss"][weight], state["loss"][weight])  # it kept learning
    # The same directory continues from its own state; a finished budget trains nothing more.
    again = train_locomotion_ppo(tmp_path / "b", _config(3 * FRAMES), progress_bar=False)
    assert again["steps"] == 3 * FRAMES
    assert json.loads((tmp_path / "b" / "ppo_config.json").read_text())["num_envs"] == 4


def test_resume_refuses_another_config_or_a_sac_state(tmp_path) -> None:
    shipped = SKILLS["humanoid"].weights.read_bytes()
    train_locomotion_ppo(tmp_path / "a", _config(FRAMES), progress_bar=False)
    state_file = tmp_path / "a" / "resume_state.pt"
    with pytest.raises(ValueError, match=r"changed: \['clip_epsilon'\]"):
        train_locomotion_ppo(tmp_path / "b", _config(2 * FRAMES, clip_epsilon=0.1), resume_from=state_file, progress_bar=False)
    sac_state = tmp_path / "sac.pt"
    torch.save({"progress": 200, "skill": "humanoid", "config": {}, "loss": {}}, sac_state)  # a SAC resume state has no "algorithm"
    with pytest.raises(ValueError, match="not PPO's 'humanoid'"):
        train_locomotion_ppo(tmp_path / "c", _config(FRAMES), resume_from=sac_state, progress_bar=False)
    assert SKILLS["humanoid"].weights.read_bytes() == shipped  # output=None by default: the shipped weights are untouched


@pytest.mark.parametrize(
    ("change", "message"),
    [
        ({"num_envs": 0}, "num_envs must be >= 1"),
        ({"minibatch_size": 10_000}, "exceeds a batch"),
        ({"gamma": 1.0}, "0 < gamma < 1"),
        ({"init_scale": 0.0}, "init_scale must be > 0.01"),
        ({"command_spread": -0.1}, r"command_spread must lie in \[0, pi\]"),
        ({"desired_kl": 0.0}, "desired_kl must be > 0"),
        ({"command_frame": math.inf}, "command_frame must be a finite angle"),
        ({"desired_kl": 0.01, "anneal_lr": True}, "excludes anneal_lr"),
        ({"direction_period": (200, 100)}, "direction_period must be two steps 1 <= low <= high"),
        ({"direction_period": (0, 10)}, "direction_period must be two steps"),
        ({"direction_period": (100,)}, "direction_period must be two steps"),
    ],
)
def test_bad_configs_are_refused_in_one_line(change, message) -> None:
    with pytest.raises(ValueError, match=message):
        _config(FRAMES, **change)


@pytest.mark.parametrize("init_scale", [0.3, 1.0])
def test_the_exploration_noise_starts_at_init_scale(init_scale: float) -> None:
    body = SKILLS["humanoid"].network(16)
    torch.nn.init.zeros_(body[-1].weight)
    torch.nn.init.zeros_(body[-1].bias)  # the body outputs 0: loc 0, scale exactly the softplus's bias
    actor = make_ppo_actor(body, RunningNormalisation(SKILLS["humanoid"].observation_dim), init_scale)
    out = actor(TensorDict(observation=torch.randn(5, SKILLS["humanoid"].observation_dim), batch_size=[5]))
    torch.testing.assert_close(out["scale"], torch.full_like(out["scale"], init_scale))


def test_annealing_decays_the_learning_rate_linearly_to_zero(tmp_path) -> None:
    # Iteration i (0-based) updates at lr * (1 - i * FRAMES / total): the last of 4 at a quarter.
    config = _config(4 * FRAMES, anneal_lr=True, lr=1e-3)
    train_locomotion_ppo(tmp_path / "a", config, progress_bar=False)
    state = torch.load(tmp_path / "a" / "resume_state.pt", weights_only=True)
    assert state["optimizer"]["param_groups"][0]["lr"] == pytest.approx(0.25e-3)
    plain = train_locomotion_ppo(tmp_path / "b", _config(FRAMES), progress_bar=False)
    assert plain["steps"] == FRAMES
    assert torch.load(tmp_path / "b" / "resume_state.pt", weights_only=True)["optimizer"]["param_groups"][0]["lr"] == 3e-4


@pytest.mark.parametrize("seed", range(5))
def test_the_update_kl_is_torchs_kl_of_the_two_gaussians(seed: int) -> None:
    generator = torch.Generator().manual_seed(seed)
    loc, other_loc = torch.randn(2, 7, 21, generator=generator)
    scale, other_scale = 0.05 + torch.rand(2, 7, 21, generator=generator)
    reference = torch.distributions.kl_divergence(
        torch.distributions.Normal(loc, scale), torch.distributions.Normal(other_loc, other_scale)
    ).sum(-1)
    torch.testing.assert_close(gaussian_kl(loc, scale, other_loc, other_scale), reference)


@pytest.mark.parametrize("seed", range(20))
def test_the_adaptive_learning_rate_moves_against_the_kl_and_stays_in_bounds(seed: int) -> None:
    generator = torch.Generator().manual_seed(seed)
    lr, desired = 10 ** (-5 + 3 * torch.rand((), generator=generator).item()), 0.01
    kl = desired * 10 ** (2 * torch.rand((), generator=generator).item() - 1)  # 0.1x to 10x the target
    new = adapt_learning_rate(lr, kl, desired)
    low, high = ADAPTIVE_LR_BOUNDS
    expected = max(low, lr / 1.5) if kl > 2 * desired else min(high, lr * 1.5) if kl < desired / 2 else lr
    assert new == pytest.approx(expected) and low <= new <= high


def test_a_kl_adaptive_run_cools_its_learning_rate_when_each_step_moves_the_policy_too_far(tmp_path) -> None:
    # A learning rate of 0.01 on a 16-unit body moves the policy far more than a KL of 1e-6 in a
    # batch's update: each of the 3 batches divides the rate by 1.5.
    config = _config(3 * FRAMES, lr=1e-2, desired_kl=1e-6)
    train_locomotion_ppo(tmp_path / "a", config, progress_bar=False)
    lr = torch.load(tmp_path / "a" / "resume_state.pt", weights_only=True)["optimizer"]["param_groups"][0]["lr"]
    assert lr == pytest.approx(1e-2 / 1.5**3)
    logged = (tmp_path / "a" / "logs" / "ppo" / "scalars" / "lr.csv").read_text().splitlines()
    assert [float(line.split(",")[1]) for line in logged] == pytest.approx([1e-2 / 1.5, 1e-2 / 1.5**2, 1e-2 / 1.5**3])
    # A target no update can exceed raises it instead, up to the bound.
    train_locomotion_ppo(tmp_path / "b", _config(3 * FRAMES, lr=5e-3, desired_kl=100.0), progress_bar=False)
    assert torch.load(tmp_path / "b" / "resume_state.pt", weights_only=True)["optimizer"]["param_groups"][0]["lr"] == ADAPTIVE_LR_BOUNDS[1]


def test_a_run_started_from_another_runs_learner_continues_its_steps_under_its_own_config(tmp_path) -> None:
    train_locomotion_ppo(tmp_path / "stand", _config(2 * FRAMES), progress_bar=False)
    parent_file = tmp_path / "stand" / "resume_state.pt"
    parent = torch.load(parent_file, weights_only=True)
    child = train_locomotion_ppo(
        tmp_path / "walk", _config(3 * FRAMES, speed_weight=2.5, lr=1e-4), init_from=parent_file, progress_bar=False
    )
    assert child["steps"] == 3 * FRAMES and child["init_steps"] == 2 * FRAMES and child["init_from"] == str(parent_file)
    state = torch.load(tmp_path / "walk" / "resume_state.pt", weights_only=True)
    assert state["config"]["speed_weight"] == 2.5 and state["optimizer"]["param_groups"][0]["lr"] == 1e-4
    assert state["counters"]["iterations"] == 3 and state["counters"]["collect_seed"] == parent["counters"]["collect_seed"] + 1
    means = [key for key in state["loss"] if key.endswith(".count")]
    assert all(int(state["loss"][key]) == 3 * FRAMES for key in means)  # the parent's normaliser, one batch more
    for missing in ({"init_from": tmp_path / "none.pt"}, {"resume_from": tmp_path / "none.pt"}):
        with pytest.raises(FileNotFoundError, match="no checkpoint at"):
            train_locomotion_ppo(tmp_path / "z", _config(FRAMES), progress_bar=False, **missing)
    with pytest.raises(ValueError, match="not both"):
        train_locomotion_ppo(tmp_path / "x", _config(FRAMES), resume_from=parent_file, init_from=parent_file)
    with pytest.raises(ValueError, match="does not fit this config"):
        train_locomotion_ppo(tmp_path / "y", _config(3 * FRAMES, hidden=8), init_from=parent_file, progress_bar=False)
    # init_scale biases the noise's softplus: the same weights under another one are another policy.
    with pytest.raises(ValueError, match=r"init_scale=1.0, which sets the policy's noise mapping: pass the same \(--init-scale 1.0\)"):
        train_locomotion_ppo(tmp_path / "w", _config(3 * FRAMES, init_scale=0.3), init_from=parent_file, progress_bar=False)
    assert not (tmp_path / "w" / "ppo_config.json").exists()


def test_reward_options_the_skills_env_lacks_are_refused(tmp_path) -> None:
    with pytest.raises(ValueError, match=r"ant skill's env takes no \['speed_weight'\]"):
        train_locomotion_ppo(tmp_path, _config(FRAMES, speed_weight=2.0), skill="ant", progress_bar=False)
    with pytest.raises(ValueError, match="speed_weight must be >= 0"):
        _config(FRAMES, speed_weight=-1.0)


def test_the_best_evaluation_is_the_fastest_upright_one_not_the_fastest(tmp_path, monkeypatch) -> None:
    import torchrl_causal.experts.locomotion_ppo as ppo

    evaluations = iter([{"speed": 0.5, "fall_rate": 1.0, "steps_to_fall": 30.0}, {"speed": 0.1, "fall_rate": 0.0, "steps_to_fall": 10.0}])
    monkeypatch.setattr(ppo, "evaluate_locomotion", lambda *args, **kwargs: next(evaluations))
    record = train_locomotion_ppo(tmp_path, _config(4 * FRAMES), progress_bar=False)  # evaluates at 2 and 4 batches
    assert record["best_eval_score"] == pytest.approx(0.1)  # a lunge that falls scores 0, whatever its speed


def test_the_command_line_sets_the_config_it_names(tmp_path, monkeypatch) -> None:
    from torchrl_causal.experts import locomotion_ppo

    seen = {}
    monkeypatch.setattr(locomotion_ppo, "train_locomotion_ppo", lambda run_dir, config, **kw: seen.update(config=config, **kw) or {})
    argv = ["--run-dir", str(tmp_path), "--gamma", "0.995", "--speed-weight", "2.5", "--command-spread", "0.5", "--steps", "640"]
    locomotion_ppo.main([*argv, "--init-from", "parent.pt", "--output", "x.pt"])
    config = seen["config"]
    assert (config.gamma, config.speed_weight, config.command_spread, config.total_steps) == (0.995, 2.5, 0.5, 640)
    assert config.lmbda == PPOLocomotionConfig().lmbda and seen["init_from"] == "parent.pt"
    locomotion_ppo.main(argv)  # no --output: the export stays in the run directory, never the package's weights
    locomotion_ppo.main([*argv, "--command-spread", "pi"])  # uniform commands, exactly (3.1416 would be refused)
    assert seen["config"].command_spread == math.pi
    locomotion_ppo.main([*argv, "--direction-period", "300", "600"])
    assert seen["config"].direction_period == (300, 600)
    assert seen["output"] == tmp_path / "export.pt" and seen["output"] != SKILLS["humanoid"].weights
    with pytest.raises(SystemExit, match="^error: need 0 < gamma < 1"):  # one line, no traceback
        locomotion_ppo.main(["--run-dir", str(tmp_path), "--gamma", "1.0"])


def test_the_commands_widen_at_each_evaluation_that_reaches_the_gate(tmp_path, monkeypatch) -> None:
    import torchrl_causal.experts.locomotion_ppo as ppo

    # Upright speeds 0.4 (gate met), 0.1 (not), 0.5 (met), 0.5 (met, but pi is the ceiling) at 2, 4, 6 and 8 batches.
    speeds = iter([0.4, 0.1, 0.5, 0.5])
    spreads_evaluated = []

    def fake_evaluation(*args, env_options, **kwargs):
        spreads_evaluated.append(env_options["command_spread"])
        return {"speed": next(speeds), "fall_rate": 0.0, "steps_to_fall": 10.0}

    envs = []
    humanoid = SKILLS["humanoid"]
    skill = replace(humanoid, make_env=lambda *args, **kwargs: envs.append(humanoid.make_env(*args, **kwargs)) or envs[-1])
    monkeypatch.setattr(ppo, "evaluate_locomotion", fake_evaluation)
    config = _config(8 * FRAMES, command_spread=0.0, widen_gate=0.3, widen_step=2.0)
    record = train_locomotion_ppo(tmp_path, config, skill=skill, progress_bar=False)
    assert spreads_evaluated == pytest.approx([0.0, 2.0, 2.0, math.pi])
    assert envs[0].command_spread == pytest.approx(math.pi)  # the training commands widened with them
    state = torch.load(tmp_path / "resume_state.pt", weights_only=True)
    assert state["counters"]["command_spread"] == pytest.approx(math.pi)
    assert record["best_eval_score"] == pytest.approx(0.5)  # the widest spread's best, selected afresh


@pytest.mark.parametrize(
    ("change", "message"),
    [
        ({"widen_gate": 0.3}, "needs a command_spread below pi"),
        ({"widen_gate": 0.3, "command_spread": math.pi}, "needs a command_spread below pi"),
        ({"widen_gate": 0.0, "command_spread": 0.0}, "need widen_gate > 0"),
        ({"widen_gate": 0.3, "command_spread": 0.0, "widen_step": 0.0}, "0 < widen_step <= pi"),
    ],
)
def test_a_curriculum_without_room_to_widen_is_refused_in_one_line(change, message) -> None:
    with pytest.raises(ValueError, match=message):
        _config(FRAMES, **change)


def test_a_command_frame_run_learns_on_turned_observations_and_exports_a_body_for_the_envs_own(tmp_path) -> None:
    from torchrl_causal.envs.humanoid import COMMAND_FRAME_VECTORS
    from torchrl_causal.experts.skills import CommandFrame, load_humanoid_locomotion_network

    plain = train_locomotion_ppo(tmp_path / "world", _config(FRAMES, hidden=256), progress_bar=False)
    assert "exported" not in plain
    # A world-frame learner starts a command-frame run: the frame is no part of the learner's state.
    train_locomotion_ppo(
        tmp_path / "turned",
        _config(3 * FRAMES, hidden=256, command_frame=-math.pi / 2),
        init_from=tmp_path / "world" / "resume_state.pt",
        output=tmp_path / "turned.pt",
        progress_bar=False,
    )
    state = torch.load(tmp_path / "turned" / "resume_state.pt", weights_only=True)
    assert not any("command_frame" in key for key in state["loss"])
    body = load_humanoid_locomotion_network(tmp_path / "turned.pt")
    assert isinstance(body[0], CommandFrame) and float(body[0].command_frame) == pytest.approx(-math.pi / 2)
    observation = torch.randn(4, SKILLS["humanoid"].observation_dim)
    observation[:, -2:] = torch.nn.functional.normalize(observation[:, -2:], dim=-1)
    turned = observation.clone()  # the world turned by 180 degrees: the exported body acts the same
    for i in COMMAND_FRAME_VECTORS:
        turned[:, i : i + 2] = -observation[:, i : i + 2]
    torch.testing.assert_close(body(turned), body(observation), rtol=1e-5, atol=1e-5)
    with pytest.raises(ValueError, match="the ant skill has no command frame"):
        train_locomotion_ppo(tmp_path / "ant", _config(FRAMES, command_frame=0.0), skill="ant", progress_bar=False)


def test_longer_command_legs_reach_the_training_env_only_and_the_run_resumes_with_them(tmp_path, monkeypatch) -> None:
    import torchrl_causal.experts.locomotion_ppo as ppo

    evaluated_options = []

    def fake_evaluation(*args, env_options, **kwargs):
        evaluated_options.append(dict(env_options))
        return {"speed": 0.1, "fall_rate": 0.0, "steps_to_fall": 10.0}

    envs = []
    humanoid = SKILLS["humanoid"]
    skill = replace(humanoid, make_env=lambda *args, **kwargs: envs.append(humanoid.make_env(*args, **kwargs)) or envs[-1])
    monkeypatch.setattr(ppo, "evaluate_locomotion", fake_evaluation)
    train_locomotion_ppo(tmp_path, _config(2 * FRAMES, direction_period=(300, 600)), skill=skill, progress_bar=False)
    assert envs[0].direction_period == (300, 600)
    assert evaluated_options and all("direction_period" not in options for options in evaluated_options)  # the skill's task
    # The run dir's config.json holds the period as a list: the same run continues, another period is refused.
    train_locomotion_ppo(tmp_path, _config(4 * FRAMES, direction_period=(300, 600)), skill=skill, progress_bar=False)
    assert torch.load(tmp_path / "resume_state.pt", weights_only=True)["progress"] == 4 * FRAMES
    with pytest.raises(ValueError, match=r"changed: \['direction_period'\]"):
        train_locomotion_ppo(tmp_path, _config(6 * FRAMES, direction_period=(300, 500)), skill=skill, progress_bar=False)
    with pytest.raises(ValueError, match=r"ant skill's env takes no \['direction_period'\]"):
        train_locomotion_ppo(tmp_path / "ant", _config(FRAMES, direction_period=(300, 600)), skill="ant", progress_bar=False)


def test_a_states_current_learner_exports_as_the_run_exports_its_best(tmp_path, monkeypatch) -> None:
    import torchrl_causal.experts.locomotion_ppo as ppo

    # Rising scores: the last evaluation is the best, so the state's learner is the best body.
    scores = iter([0.1, 0.2])
    monkeypatch.setattr(ppo, "evaluate_locomotion", lambda *a, **k: {"speed": next(scores), "fall_rate": 0.0, "steps_to_fall": 10.0})
    train_locomotion_ppo(tmp_path / "run", _config(4 * FRAMES, command_frame=-math.pi / 2), progress_bar=False)
    steps = ppo.export_learner(tmp_path / "run" / "resume_state.pt", tmp_path / "current.pt")
    assert steps == 4 * FRAMES
    exported = torch.load(tmp_path / "current.pt", weights_only=True)
    best = torch.load(tmp_path / "run" / "best_body.pt", weights_only=True)
    assert exported.keys() == best.keys() and all(torch.equal(exported[k], best[k]) for k in best)
    assert exported["0.command_frame"].item() == pytest.approx(-math.pi / 2)  # behind the run's frame, as the loader reads it
    with pytest.raises(SystemExit):
        ppo.main(["--export-from", str(tmp_path / "run" / "resume_state.pt")])  # no --output: refused, nothing written


def _tree(folder):
    return {path.relative_to(folder): path.read_bytes() if path.is_file() else None for path in sorted(folder.rglob("*"))}


def test_a_folder_of_the_users_own_files_is_refused_by_both_trainers_and_left_as_it_was(tmp_path) -> None:
    from torchrl_causal.experiment.run_directory import ForeignFilesError
    from torchrl_causal.experts import locomotion, locomotion_ppo

    mine = tmp_path / "mine"
    (mine / "buffer.old").mkdir(parents=True)  # named like a run's own entry, but no run's config proves it one
    (mine / "buffer.old" / "data.bin").write_bytes(b"mine")
    (mine / "notes.txt").write_text("mine")
    before = _tree(mine)
    with pytest.raises(ForeignFilesError, match=r"mine is not a run directory \(it holds buffer.old, notes.txt, which no run wrote\)"):
        train_locomotion_ppo(mine, _config(FRAMES), progress_bar=False)  # PPO never writes a buffer.old
    sac = SKILLS["ant"].config(total_steps=200, random_steps=200, hidden=16, buffer_size=400, eval_envs=1, eval_steps=5)
    with pytest.raises(ForeignFilesError, match=r"\(it holds notes.txt, which"):
        locomotion.train_locomotion(mine, sac, skill="ant", progress_bar=False)
    assert _tree(mine) == before
    (mine / "notes.txt").unlink()
    before = _tree(mine)
    with pytest.raises(ForeignFilesError, match=r"it holds buffer.old"):
        locomotion.train_locomotion(mine, sac, skill="ant", progress_bar=False)
    with pytest.raises(SystemExit, match=r"^error: .*mine is not a run directory"):  # the command line: one line
        locomotion_ppo.main(["--run-dir", str(mine), "--steps", "64", "--num-envs", "4", "--rollout-steps", "16", "--minibatch-size", "32"])
    assert _tree(mine) == before
    other = tmp_path / "other"
    other.mkdir()
    (other / "ppo_config.json").write_text("not json")  # another program's file of the config's name
    with pytest.raises(ForeignFilesError, match=r"it holds ppo_config.json, which no run wrote"):
        train_locomotion_ppo(other, _config(FRAMES), progress_bar=False)
    assert _tree(other) == {Path("ppo_config.json"): b"not json"}  # nothing written, nothing removed


@pytest.mark.parametrize(
    "argv",
    [
        ["--steps", "-5"],
        ["--num-envs", "0"],
        ["--gamma", "nan"],
        ["--command-spread", "north"],
        ["--direction-period", "10", "0"],
        ["--entropy-coeff", "-1"],
    ],
)
def test_bad_flags_are_refused_in_one_line_before_anything_is_written(tmp_path, capsys, argv) -> None:
    from torchrl_causal.experts import locomotion_ppo

    with pytest.raises(SystemExit) as stop:
        locomotion_ppo.main(["--run-dir", str(tmp_path / "run"), *argv])
    err = capsys.readouterr().err
    assert stop.value.code == 2 and err.startswith("error: argument ") and err.count("\n") == 1, err
    assert not (tmp_path / "run").exists()


def test_a_run_folder_replaces_only_its_own_entries(tmp_path) -> None:
    from torchrl_causal.errors import InvalidValueError
    from torchrl_causal.experts.skill_run import SkillRunDirectory

    run = SkillRunDirectory(tmp_path, "c.json", ("buffer", "buffer.tmp", "buffer.old"))
    (tmp_path / "buffer").mkdir()
    (tmp_path / "buffer" / "old.bin").write_bytes(b"old")
    run.replace_folder("buffer", lambda folder: (folder.mkdir(), (folder / "new.bin").write_bytes(b"new")))
    assert sorted(p.name for p in tmp_path.iterdir()) == ["buffer"] and (tmp_path / "buffer" / "new.bin").read_bytes() == b"new"
    with pytest.raises(InvalidValueError, match="'data' is not one of"):
        run.replace_folder("data", lambda folder: folder.mkdir())
    assert sorted(p.name for p in tmp_path.iterdir()) == ["buffer"]
