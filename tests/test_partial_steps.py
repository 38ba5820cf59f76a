"""Partial steps (TorchRL's ``"_step"`` mask) and the evaluation that stops simulating ended episodes.

Two independent facts are checked on every confounded env: a partial step gives the stepped
rows exactly what a full step gives them, draws the same random numbers and leaves the
skipped rows as they were (env level); and :func:`evaluate_policy` gives per-episode records
(success, return, length, trajectory) equal to the loop that steps every env until the
round's last episode ends (``skip_finished=False``), over several rounds, in both regimes.
"""

from __future__ import annotations

from collections.abc import Callable

import pytest
import torch
from tensordict import TensorDictBase
from torchrl.envs import EnvBase, TransformedEnv

from torchrl_causal.envs import (
    AntMazeEnv,
    HumanoidMazeEnv,
    RouteChoiceEnv,
    RoverExpert,
    RoverMazeEnv,
    RoverParameters,
)
from torchrl_causal.envs.base import STEP_MASK_KEY, PartialStepError
from torchrl_causal.envs.experts import AntMazeExpert, HumanoidMazeExpert, RouteChoiceExpert
from torchrl_causal.evaluation import evaluate_policy
from torchrl_causal.transforms import CausalWindowTransform

BATCH = 5


def _random_actions(env: EnvBase, seed: int) -> Callable[[TensorDictBase], TensorDictBase]:
    generator = torch.Generator().manual_seed(seed)
    spec = env.action_spec

    def act(td: TensorDictBase) -> TensorDictBase:
        uniform = torch.rand(spec.shape, generator=generator)
        if not hasattr(spec.space, "low"):  # Route Choice's binary action
            return td.set("action", (uniform < 0.5).to(spec.dtype))
        return td.set("action", spec.space.low + (spec.space.high - spec.space.low) * uniform)

    return act


MAKERS: dict[str, Callable[[], EnvBase]] = {
    "rover": lambda: RoverMazeEnv(maze="u", batch_size=BATCH, seed=3, horizon=50),
    "route_choice": lambda: RouteChoiceEnv(batch_size=BATCH, seed=3),
    "antmaze": lambda: AntMazeEnv("medium", batch_size=BATCH, seed=3, horizon=20),
    "humanoidmaze": lambda: HumanoidMazeEnv("medium", batch_size=BATCH, seed=3, horizon=20),
}


def _physics(env: EnvBase) -> torch.Tensor | None:
    simulator = getattr(env, "simulator", None)
    return None if simulator is None else torch.from_numpy(simulator.get_state())


@pytest.mark.parametrize("name", sorted(MAKERS))
def test_partial_step_steps_the_named_rows_as_a_full_step_does(name):
    full, partial = MAKERS[name](), MAKERS[name]()
    act = _random_actions(full, seed=1)
    td_full, td_partial = full.reset(), partial.reset()
    for _ in range(2 if name != "route_choice" else 0):  # mid-episode, where there is an episode to continue
        action = act(td_full)["action"]
        td_full = full.step(td_full.set("action", action))["next"]
        td_partial = partial.step(td_partial.set("action", action.clone()))["next"]
    live = torch.tensor([True, False, True, True, False])
    action = act(td_full)["action"]
    physics_before = _physics(partial)
    stepped = full.step(td_full.clone().set("action", action))["next"]
    masked_input = td_partial.clone().set("action", action.clone()).set(STEP_MASK_KEY, live)
    skipped = partial.step(masked_input)["next"]

    assert set(skipped.keys(True, True)) == set(stepped.keys(True, True))
    for key, value in stepped.items(True, True):
        assert torch.equal(skipped[key][live], value[live]), key  # the stepped rows: bit for bit
        expected = torch.zeros_like(value[~live]) if key == "reward" else masked_input.get(key, None)
        if key != "reward" and expected is None:
            continue  # not in the input: read from the held state (checked through the physics below)
        expected = expected if key == "reward" else expected[~live]
        assert torch.equal(skipped[key][~live], expected), key  # the skipped rows repeat their input
    assert torch.equal(full.rng.get_state(), partial.rng.get_state())  # the same random numbers drawn
    if physics_before is not None:  # the skipped simulations were not stepped
        assert torch.equal(_physics(partial)[~live], physics_before[~live])
        assert not torch.equal(_physics(partial)[live], physics_before[live])
    # A full step afterwards continues the stepped rows exactly as in the env never masked.
    action = act(td_full)["action"]
    again_full = full.step(stepped.set("action", action))["next"]
    again_partial = partial.step(skipped.set("action", action.clone()))["next"]
    for key, value in again_full.items(True, True):
        assert torch.equal(again_partial[key][live], value[live]), key


def test_partial_step_holds_the_skipped_rows_counters():
    env = RoverMazeEnv(maze="u", batch_size=3, seed=0, horizon=4)
    td = env.reset()
    act = _random_actions(env, seed=0)
    live = torch.tensor([True, False, True])
    for _ in range(4):
        td = env.step(act(td).set(STEP_MASK_KEY, live))["next"]
    # The stepped rows reach the horizon; the skipped one never left its first step.
    assert td["truncated"].squeeze(-1).tolist() == [True, False, True]
    assert env.get_extra_state()["_step_count"].squeeze(-1).tolist() == [4, 0, 4]


def test_a_malformed_step_mask_is_named():
    env = RoverMazeEnv(maze="u", batch_size=3, seed=0)
    td = _random_actions(env, seed=0)(env.reset())
    before = env.get_extra_state()
    with pytest.raises(PartialStepError, match="'_step' entry must be a bool mask of the env's batch"):
        env.step(td.set(STEP_MASK_KEY, torch.tensor([1, 0, 1])))
    with pytest.raises(PartialStepError, match=r"shape \(3, 2\)"):
        env.step(td.set(STEP_MASK_KEY, torch.ones(3, 2, dtype=torch.bool)))
    after = env.get_extra_state()  # refused before anything moved
    assert torch.equal(before["rng"], after["rng"]) and torch.equal(before["position"], after["position"])


def _goal(env: EnvBase) -> torch.Tensor:
    env = env.base_env if isinstance(env, TransformedEnv) else env
    goal = env.goal_position if isinstance(env, RoverMazeEnv) else torch.as_tensor(env.goal_xy)
    return goal.reshape(-1)[:2].float()


def _median_reach(make: Callable[..., EnvBase], expert: Callable[[EnvBase], Callable], episodes: int) -> float:
    """A goal radius that about half of the episodes reach at some step (within the
    horizon): the median of each episode's closest approach to the goal, from a first
    evaluation that no episode can succeed in, so that the compared evaluations end
    episodes at many different steps."""
    env = make(1e-6)
    probe = evaluate_policy(
        env, expert(env), episodes=episodes, max_steps=env.horizon, regime="train", position_key="P", trajectories=episodes
    )
    assert not any(probe.successes)
    goal = _goal(env)
    closest = sorted(min((torch.tensor(p) - goal).norm().item() for p in path) for path in probe.trajectories)
    return (closest[episodes // 2 - 1] + closest[episodes // 2]) / 2


def _compare_paths(make: Callable[[str], EnvBase], policy: Callable[[EnvBase], Callable], episodes: int, regime: str, position_key):
    results = []
    for skip_finished in (False, True):
        env = make(regime)
        results.append(
            evaluate_policy(
                env,
                policy(env),
                episodes=episodes,
                max_steps=env.horizon,
                regime=regime,
                position_key=position_key,
                trajectories=episodes if position_key else 0,
                skip_finished=skip_finished,
            )
        )
    reference, skipping = results
    assert skipping.successes == reference.successes
    assert skipping.returns == reference.returns  # exact float equality
    assert skipping.lengths == reference.lengths
    assert [list(map(list, p)) for p in skipping.trajectories] == [list(map(list, p)) for p in reference.trajectories]
    return reference


def _check_mixed(reference, horizon: int) -> None:
    """The setting exercises skipping: some episodes end early, some run on after them."""
    assert min(reference.lengths) < max(reference.lengths)
    assert any(reference.successes) and min(reference.lengths) < horizon


MAZES = {
    "rover": (
        lambda radius, regime="train": RoverMazeEnv(
            maze="u", batch_size=4, regime=regime, seed=11, horizon=40, params=RoverParameters(goal_radius=radius)
        ),
        lambda env: RoverExpert(env, seed=0),
    ),
    "antmaze": (
        lambda radius, regime="train": AntMazeEnv("medium", batch_size=4, regime=regime, seed=11, horizon=25, success_radius=radius),
        AntMazeExpert,
    ),
    "humanoidmaze": (
        lambda radius, regime="train": HumanoidMazeEnv("medium", batch_size=4, regime=regime, seed=11, horizon=25, success_radius=radius),
        HumanoidMazeExpert,
    ),
}


@pytest.mark.parametrize("regime", ["train", "deploy"])
@pytest.mark.parametrize("maze", sorted(MAZES))
def test_evaluation_skipping_ended_episodes_gives_the_same_records(maze, regime):
    make, expert = MAZES[maze]
    episodes = 10  # three rounds of four envs, the last one partly kept
    radius = _median_reach(make, expert, episodes)
    reference = _compare_paths(lambda regime: make(radius, regime), expert, episodes, regime, "P")
    _check_mixed(reference, make(radius).horizon)


@pytest.mark.parametrize("regime", ["train", "deploy"])
def test_evaluation_of_route_choice_is_unchanged(regime):
    reference = _compare_paths(lambda regime: RouteChoiceEnv(batch_size=8, regime=regime, seed=5), RouteChoiceExpert, 20, regime, None)
    assert set(reference.lengths) == {1}


def test_evaluation_through_the_window_transform_is_unchanged():
    """The imitator's env (the window's lag buffers in a TransformedEnv) with an actor-like
    policy: a fixed random linear map of the encoding."""

    def make(radius: float, regime: str = "train") -> TransformedEnv:
        base = RoverMazeEnv(maze="u", batch_size=4, regime=regime, seed=2, horizon=60, params=RoverParameters(goal_radius=radius))
        return TransformedEnv(base, CausalWindowTransform.from_env(base, k=2))

    def linear(env: EnvBase) -> Callable[[TensorDictBase], TensorDictBase]:
        weights = torch.randn(env.observation_spec["observation"].shape[-1], 2, generator=torch.Generator().manual_seed(0))
        return lambda td: td.set("action", torch.tanh(td["observation"] @ weights + torch.tensor([1.0, 0.0])))

    radius = _median_reach(make, linear, 8)
    for regime in ("train", "deploy"):
        _check_mixed(_compare_paths(lambda regime: make(radius, regime), linear, 8, regime, "P"), 60)
