"""The PPO skill trainer's collection in several processes (``collector_workers``) and in one.

Checks: the seeds of the workers (brute force over many runs and attempts), the batch of a
two-worker run (its size, its simulations' distinct streams, the policy and normaliser each
worker acted with, one thread per worker), its resume, and that one worker collects exactly
as the in-process path always did. The two-worker test spawns two processes once; budgets are
tiny (hidden 16, 4 envs x 8 steps).
"""

from __future__ import annotations

import math
import multiprocessing
import os
import signal
from dataclasses import replace

import pytest
import torch
from torchrl.objectives.value import GAE

import torchrl_causal.experts.locomotion_ppo as ppo
from torchrl_causal.experiment.interrupts import RunInterrupted
from torchrl_causal.experts.locomotion import SKILLS
from torchrl_causal.experts.locomotion_ppo import PPOLocomotionConfig, train_locomotion_ppo
from torchrl_causal.experts.skill_run import skill_collector, worker_seeds

ENVS, STEPS = 4, 8
FRAMES = ENVS * STEPS

spawn_unavailable = pytest.mark.skipif(
    "spawn" not in multiprocessing.get_all_start_methods(), reason="the collector workers are spawned processes"
)


def _config(total_steps: int, **changes) -> PPOLocomotionConfig:
    base = {"num_envs": ENVS, "rollout_steps": STEPS, "minibatch_size": 16, "epochs": 1, "hidden": 16, "eval_every": 10 * FRAMES}
    return PPOLocomotionConfig(total_steps=total_steps, eval_envs=1, eval_steps=5, **{**base, **changes})


def _single_threaded_humanoid(count: int, seed: int, **options):
    """The humanoid's env, refused unless built in a one-thread process (a collector worker's)."""
    threads = (torch.get_num_threads(), os.environ.get("OMP_NUM_THREADS"))
    if threads != (1, "1"):
        raise RuntimeError(f"a collector worker runs (torch threads, OMP_NUM_THREADS) = {threads}, not (1, '1')")
    return SKILLS["humanoid"].make_env(count, seed, **options)


@pytest.fixture
def collected(monkeypatch):
    """Every batch the trainer learns from (as GAE first sees it), with the actor's own
    ``(loc, scale)`` on its observations at that moment (the weights that should have acted)."""
    actors, batches = [], []
    make_actor = ppo.make_ppo_actor
    monkeypatch.setattr(ppo, "make_ppo_actor", lambda *args, **kwargs: actors.append(make_actor(*args, **kwargs)) or actors[-1])
    forward = GAE.forward

    def spy(self, tensordict, *args, **kwargs):
        with torch.no_grad():
            params = actors[-1].get_dist_params(tensordict.select("observation").clone())
        batches.append((tensordict.clone(), params["loc"], params["scale"]))
        return forward(self, tensordict, *args, **kwargs)

    monkeypatch.setattr(GAE, "forward", spy)
    return batches


def test_worker_seeds_differ_across_workers_attempts_and_runs() -> None:
    seen: dict[int, tuple[int, int, int]] = {}
    for run_seed in range(5):
        for collect_seed in range(run_seed + 1, run_seed + 41):  # a run's attempts, runs overlapping in collect_seed
            pairs = worker_seeds(run_seed, collect_seed, 4)
            assert worker_seeds(run_seed, collect_seed, 2) == pairs[:2]  # the same key: the same first workers
            for worker, pair in enumerate(pairs):
                for seed in (pair.env, pair.policy):
                    assert 0 <= seed < 2**63 and seed not in seen, (run_seed, collect_seed, worker, seen.get(seed))
                    seen[seed] = (run_seed, collect_seed, worker)
    assert len(seen) == 5 * 40 * 4 * 2


@pytest.mark.parametrize(
    ("change", "message"),
    [
        ({"collector_workers": 0}, "collector_workers must be >= 1"),
        ({"collector_workers": 3}, r"collector_workers \(3\) must divide num_envs \(4\)"),
    ],
)
def test_a_worker_count_that_does_not_split_the_envs_is_refused_in_one_line(change, message) -> None:
    with pytest.raises(ValueError, match=message):
        _config(FRAMES, **change)


def test_the_command_line_sets_the_worker_count(tmp_path, monkeypatch) -> None:
    seen = {}
    monkeypatch.setattr(ppo, "train_locomotion_ppo", lambda run_dir, config, **kw: seen.update(config=config) or {})
    ppo.main(["--run-dir", str(tmp_path), "--collector-workers", "2"])
    assert seen["config"].collector_workers == 2
    ppo.main(["--run-dir", str(tmp_path)])
    assert seen["config"].collector_workers == 1  # the default: the runs on record


def test_one_worker_collects_in_this_process_on_the_env_seeded_as_always(tmp_path, monkeypatch, collected) -> None:
    config = _config(FRAMES, seed=3)
    starts = []

    def recording_collector(env, actor, *args, **kwargs):
        starts.append((torch.get_rng_state(), {k: v.clone() for k, v in actor.state_dict().items()}))
        return skill_collector(env, actor, *args, **kwargs)

    monkeypatch.setattr(ppo, "skill_collector", recording_collector)
    train_locomotion_ppo(tmp_path, config, progress_bar=False)
    ((batch, _, _),), ((rng, weights),) = collected, starts
    # Today's path, rebuilt by hand: one env of every simulation seeded seed + 1 (a fresh run's
    # first attempt), the actor's sampled actions drawn from this process's generator.
    actor = ppo.make_ppo_actor(SKILLS["humanoid"].network(config.hidden), ppo.RunningNormalisation(SKILLS["humanoid"].observation_dim))
    actor.load_state_dict(weights)
    torch.set_rng_state(rng)
    reference = next(iter(skill_collector(SKILLS["humanoid"].make_env(ENVS, config.seed + 1), actor, FRAMES, FRAMES)))
    assert batch.shape == reference.shape == (ENVS, STEPS)
    for key in ("observation", "action", ("next", "observation"), ("next", "terminated")):
        assert torch.equal(batch[key], reference[key]), key
    assert torch.equal(batch["next", "reward"], reference["next", "reward"] * config.reward_scale)  # the update scaled it


@spawn_unavailable
def test_two_workers_fill_the_batch_with_distinct_streams_and_the_current_policy_and_stop_cleanly_on_sigterm(
    tmp_path, monkeypatch, collected, torch_threads
) -> None:
    monkeypatch.setenv("OMP_NUM_THREADS", "2")  # the workers must not inherit these
    torch.set_num_threads(2)

    def terminated_evaluation(*args, **kwargs):  # the first evaluation (after batch 2) meets a SIGTERM
        os.kill(os.getpid(), signal.SIGTERM)
        return {"speed": 0.1, "fall_rate": 0.0, "steps_to_fall": 10.0}

    monkeypatch.setattr(ppo, "evaluate_locomotion", terminated_evaluation)
    skill = replace(SKILLS["humanoid"], make_env=_single_threaded_humanoid)
    config = _config(3 * FRAMES, collector_workers=2, eval_every=2 * FRAMES)
    with pytest.raises(RunInterrupted, match="SIGTERM"):
        train_locomotion_ppo(tmp_path, config, skill=skill, progress_bar=False)
    assert not multiprocessing.active_children()  # the workers are shut down, not orphaned
    assert torch.get_num_threads() == 2 and os.environ["OMP_NUM_THREADS"] == "2"  # this process keeps its own
    assert len(collected) == 2
    for batch, loc, scale in collected:
        assert batch.shape == (ENVS, STEPS)  # frames_per_batch, split over the workers and put back together
        # Each worker acted with the learner of the moment (the second batch: after one update
        # and one normaliser update), not a stale copy.
        torch.testing.assert_close(batch["loc"], loc, rtol=1e-5, atol=1e-5)
        torch.testing.assert_close(batch["scale"], scale, rtol=1e-5, atol=1e-5)
    starts = torch.cat([batch["observation"][:, 0] for batch, _, _ in collected])
    assert torch.unique(starts, dim=0).shape[0] == 2 * ENVS  # no two simulations, in or across batches, replay a stream
    first = collected[0][0]
    assert not torch.equal(first["action"][: ENVS // 2], first["action"][ENVS // 2 :])  # nor two workers' policy noise

    # The stopped run saved its two batches and resumes, here with one worker (the count is bookkeeping).
    state = torch.load(tmp_path / "resume_state.pt", weights_only=True)
    assert state["progress"] == 2 * FRAMES and state["counters"]["iterations"] == 2 and state["config"]["collector_workers"] == 2
    monkeypatch.setattr(ppo, "evaluate_locomotion", lambda *a, **k: {"speed": 0.1, "fall_rate": 0.0, "steps_to_fall": 10.0})
    record = train_locomotion_ppo(tmp_path, replace(config, collector_workers=1), progress_bar=False)
    resumed = torch.load(tmp_path / "resume_state.pt", weights_only=True)
    assert record["steps"] == 3 * FRAMES and resumed["counters"]["iterations"] == 3
    assert resumed["counters"]["collect_seed"] == state["counters"]["collect_seed"] + 1


def test_a_widened_curriculum_reaches_the_training_envs_through_new_workers(tmp_path, monkeypatch) -> None:
    # The gate is met at the first evaluation (after batch 1): the commands widen from 0 to pi.
    monkeypatch.setattr(ppo, "evaluate_locomotion", lambda *a, **k: {"speed": 0.4, "fall_rate": 0.0, "steps_to_fall": 10.0})
    built = []

    def in_process(make_env, seeds, actor, frames_per_batch, steps):
        # What the workers would build, recorded; collected here over all the simulations (no processes).
        options = make_env.args[2]
        built.append((options["command_spread"], [pair.env for pair in seeds], steps))
        return skill_collector(SKILLS["humanoid"].make_env(ENVS, seeds[0].env, **options), actor, frames_per_batch, steps)

    monkeypatch.setattr(ppo, "parallel_skill_collector", in_process)
    config = _config(3 * FRAMES, collector_workers=2, command_spread=0.0, widen_gate=0.3, widen_step=math.pi, eval_every=FRAMES)
    record = train_locomotion_ppo(tmp_path, config, progress_bar=False)
    assert record["steps"] == 3 * FRAMES
    assert [(spread, steps) for spread, _, steps in built] == [(0.0, 3 * FRAMES), (math.pi, 2 * FRAMES)]
    assert set(built[0][1]).isdisjoint(built[1][1])  # the new workers draw fresh streams
    state = torch.load(tmp_path / "resume_state.pt", weights_only=True)
    assert state["counters"]["collect_seed"] == config.seed + 2 and state["counters"]["command_spread"] == pytest.approx(math.pi)
