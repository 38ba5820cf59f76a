"""End-to-end runs of every trainer on RoverMaze-U and Route Choice at toy budgets: the
loop runs, checkpoints atomically, resumes to the saved state, evaluates and reports."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
import torch
from omegaconf import OmegaConf

from torchrl_causal.evaluation import load_runs, write_report
from torchrl_causal.evaluation.runs import read_scalar_csv
from torchrl_causal.graphs.window import AdjustmentWindow
from torchrl_causal.trainers import BCTrainer, CheckpointError, OffPolicyILTrainer, compose_config, load_checkpoint, make_trainer

TINY = [
    "progress_bar=false", "threads=1", "demos.episodes=6", "eval.episodes=4", "eval.num_envs=4",
    "eval.final_episodes=8", "eval.trajectories=2",
]
ALGO_TINY = {
    "bc": ["algo.actor.hidden=16", "algo.actor.blocks=1", "algo.epochs=3", "algo.batch_size=64", "algo.eval_every=2"],
    "gail": ["algo.actor.hidden=16", "algo.actor.blocks=1", "algo.value.hidden=16", "algo.discriminator.hidden=16",
             "algo.rounds=2", "algo.episodes_per_round=2", "algo.batch_size=32", "algo.discriminator_batch_size=32",
             "algo.eval_every=1"],
    "sqil": ["algo.actor.hidden=16", "algo.actor.blocks=1", "algo.critic.hidden=16", "algo.critic.blocks=1",
             "algo.total_steps=240", "algo.random_steps=80", "algo.num_envs=2", "algo.frames_per_batch=40",
             "algo.batch_size=32", "algo.buffer_size=1000", "algo.eval_every=120"],
    "expert": [],
}
ALGO_TINY["iq_learn"] = ALGO_TINY["sqil"] + ["algo.value_samples=2"]
ENV_TINY = {"rovermaze_u": ["env=rovermaze_u", "env.horizon=40", "window.k=2"], "route_choice": ["env=route_choice"]}


def tiny_config(root: Path, env: str, algo: str, causal: bool, *extra: str):
    return compose_config([*ENV_TINY[env], f"algo={algo}", f"causal={causal}", f"run_root={root}", *TINY,
                           *ALGO_TINY[algo], *extra])


@pytest.fixture(scope="module")
def trained_runs(tmp_path_factory) -> dict[str, Path]:
    """Every algorithm, causal and not, on both envs (plus the expert), trained once."""
    roots = {}
    for env in ENV_TINY:
        root = tmp_path_factory.mktemp(env)
        for algo in ("bc", "gail", "sqil", "iq_learn"):
            for causal in (True, False):
                make_trainer(tiny_config(root, env, algo, causal)).fit()
        make_trainer(tiny_config(root, env, "expert", False)).fit()
        roots[env] = root
    return roots


@pytest.mark.parametrize("env", sorted(ENV_TINY))
def test_every_algorithm_runs_checkpoints_and_evaluates(trained_runs, env: str) -> None:
    runs = load_runs(trained_runs[env])
    assert sorted(r.label for r in runs) == sorted(
        ["expert", "c_bc", "c_gail", "c_sqil", "c_iq_learn", "bc", "gail", "sqil", "iq_learn"])
    for run in runs:
        status = json.loads((run.path / "status.json").read_text())
        assert status["status"] == "complete"
        assert status["progress"] == status["total"] or run.label.endswith("bc")  # BC may stop early
        for regime in ("train", "deploy"):
            result = run.evaluations[regime]
            assert result.n_episodes == 8 and len(result.returns) == 8
            assert all(1 <= n <= (40 if env == "rovermaze_u" else 1) for n in result.lengths)
        config = (run.path / "config.yaml").read_text()
        assert "${" not in config and OmegaConf.create(config).run_dir == str(run.path)  # resolved
        if run.label == "expert":
            assert not (run.path / "checkpoints").exists()
            continue
        window = AdjustmentWindow.from_dict(json.loads((run.path / "window.json").read_text()))
        assert ("W" in window.lags) != run.label.startswith("c_")  # the collider is what causal runs drop
        for name in ("last.pt", "best.pt"):
            state = load_checkpoint(run.path / "checkpoints" / name)  # weights_only=True
            assert state["progress"] <= status["total"]
        assert run.curve and run.curve[-1][0] == status["progress"]
    if env == "rovermaze_u":
        deploy = next(r for r in runs if r.label == "c_sqil").evaluations["deploy"]
        assert len(deploy.trajectories) == 2 and len(deploy.trajectories[0][0]) == 2
        assert next(r for r in runs if r.label == "c_sqil").maze["walls"]


def test_report_of_trained_runs(trained_runs, tmp_path: Path) -> None:
    report = write_report(trained_runs["rovermaze_u"], tmp_path, name="u")
    rows = report.csv.read_text().splitlines()
    assert rows[0] == "algorithm,regime,success_rate,success_se,return_mean,return_std,ep_len_mean,ep_len_std,n_episodes,seeds"
    assert len(rows) == 1 + 9 * 2
    assert {p.name for p in report.figures} == {"u_training_curves.png", "u_trajectories.png"}


def test_finished_run_is_not_retrained(trained_runs) -> None:
    cfg = tiny_config(trained_runs["route_choice"], "route_choice", "bc", True)
    before = (Path(cfg.run_dir) / "eval" / "deploy.json").stat().st_mtime_ns
    results = make_trainer(cfg).fit()
    assert results["deploy"].n_episodes == 8
    assert (Path(cfg.run_dir) / "eval" / "deploy.json").stat().st_mtime_ns == before


def test_raising_the_budget_continues_a_finished_run(tmp_path: Path) -> None:
    make_trainer(tiny_config(tmp_path, "route_choice", "gail", True)).fit()
    longer = make_trainer(tiny_config(tmp_path, "route_choice", "gail", True, "algo.rounds=4"))
    longer.fit()
    status = json.loads((Path(longer.cfg.run_dir) / "status.json").read_text())
    assert (status["status"], status["progress"], status["total"]) == ("complete", 4, 4)
    assert [step for step, _ in read_scalar_csv(Path(longer.cfg.run_dir) / "logs/scalars/eval/train_return.csv")] == [1, 2, 3, 4]


class _Interrupted(Exception):
    pass


def _interrupt_after_checkpoints(trainer, count: int) -> None:
    """Makes the trainer raise right after its ``count``-th checkpoint, like a killed job."""
    save = trainer.save_checkpoint
    calls = []

    def save_then_maybe_die() -> None:
        save()
        calls.append(1)
        if len(calls) == count:
            raise _Interrupted

    trainer.save_checkpoint = save_then_maybe_die


def test_bc_resume_is_exact(tmp_path: Path) -> None:
    extra = ("algo.epochs=4", "algo.patience=10", "algo.eval_every=3")
    straight = BCTrainer(tiny_config(tmp_path / "a", "rovermaze_u", "bc", True, *extra))
    straight.fit()
    interrupted = BCTrainer(tiny_config(tmp_path / "b", "rovermaze_u", "bc", True, *extra))
    _interrupt_after_checkpoints(interrupted, 2)
    with pytest.raises(_Interrupted):
        interrupted.fit()
    assert load_checkpoint(Path(interrupted.cfg.run_dir) / "checkpoints" / "last.pt")["progress"] == 2
    resumed = BCTrainer(tiny_config(tmp_path / "b", "rovermaze_u", "bc", True, *extra))
    resumed.fit()
    for (name, a), (_, b) in zip(straight.loss.named_parameters(), resumed.loss.named_parameters()):
        assert torch.equal(a, b), name
    curve_a = read_scalar_csv(Path(straight.cfg.run_dir) / "logs/scalars/train/loss_bc.csv")
    curve_b = read_scalar_csv(Path(resumed.cfg.run_dir) / "logs/scalars/train/loss_bc.csv")
    assert curve_a == curve_b and [s for s, _ in curve_b] == [1, 2, 3, 4]


def test_off_policy_resume_restores_the_saved_state(tmp_path: Path) -> None:
    cfg = tiny_config(tmp_path, "rovermaze_u", "sqil", True)
    first = OffPolicyILTrainer(cfg)
    _interrupt_after_checkpoints(first, 1)
    with pytest.raises(_Interrupted):
        first.fit()
    saved = load_checkpoint(Path(cfg.run_dir) / "checkpoints" / "last.pt")
    assert saved["progress"] == 120 and saved["training"]["updates"] == 10  # (120 - 80) * 0.25

    second = OffPolicyILTrainer(tiny_config(tmp_path, "rovermaze_u", "sqil", True))
    second.window = first.window
    second.setup()
    assert second._resume()
    assert second.progress == 120 and second.update.updates == 10 and len(second.policy_buffer) == 120
    for key, value in first.loss.state_dict().items():
        assert torch.equal(second.loss.state_dict()[key], value), key
    assert second.update.critic_optimizer.param_groups[0]["lr"] == first.update.critic_optimizer.param_groups[0]["lr"] < 3e-4
    torch.testing.assert_close(second.policy_buffer[:120]["observation"], first.policy_buffer[:120]["observation"])
    results = OffPolicyILTrainer(tiny_config(tmp_path, "rovermaze_u", "sqil", True)).fit()
    assert json.loads((Path(cfg.run_dir) / "status.json").read_text())["progress"] == 240
    assert results["deploy"].n_episodes == 8


def test_corrupted_checkpoint_is_refused_by_name(tmp_path: Path) -> None:
    cfg = tiny_config(tmp_path, "route_choice", "bc", True)
    last = Path(cfg.run_dir) / "checkpoints" / "last.pt"
    last.parent.mkdir(parents=True)
    last.write_bytes(b"not a checkpoint")
    with pytest.raises(CheckpointError, match="last.pt"):
        make_trainer(cfg).fit()


def test_route_choice_bc_reproduces_the_appendix_values(tmp_path: Path) -> None:
    """Through the whole trainer: causal BC takes the sheltered route (3/4 in both
    regimes), non-causal BC follows the compass (11/16 at training, 19/48 deployed)."""
    extra = ("demos.episodes=2000", "algo.epochs=60", "algo.batch_size=256", "algo.patience=60", "algo.eval_every=60",
             "eval.final_episodes=4000", "eval.num_envs=1000")
    expected = {True: (3 / 4, 3 / 4), False: (11 / 16, 19 / 48)}
    for causal, (train_value, deploy_value) in expected.items():
        results = make_trainer(tiny_config(tmp_path, "route_choice", "bc", causal, *extra)).fit()
        for regime, value in (("train", train_value), ("deploy", deploy_value)):
            result = results[regime]
            assert abs(result.return_mean - value) < 4 * result.success_se + 1e-9, (causal, regime, result.return_mean)


def test_evaluate_cli_reloads_best_policy(trained_runs) -> None:
    from torchrl_causal.evaluate import main as evaluate_main

    root = trained_runs["rovermaze_u"]
    for label in ("c_sqil", "expert"):
        (run,) = [r for r in load_runs(root) if r.label == label]
        result = evaluate_main([f"run_dir={run.path}", "regime=deploy", "episodes=6", "num_envs=3",
                                "confounding_strength=0.5"])
        assert result.n_episodes == 6 and result.regime == "deploy"
        assert (run.path / "eval" / "deploy-cs0.5.json").is_file()
    assert len(load_runs(root)) == 9  # the extra record does not replace the final evaluation
    with pytest.raises(SystemExit, match="unknown argument"):
        evaluate_main([f"run_dir={root}", "episodez=3"])
