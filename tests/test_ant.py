"""The paper's ant: OGBench's physics, the open-ground locomotion task and the shipped skill."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from torchrl.envs.utils import check_env_specs

from torchrl_causal.envs import AntMazeEnv
from torchrl_causal.envs.ant import AntLocomotionEnv
from torchrl_causal.envs.base import GustProcess
from torchrl_causal.experts.skills import load_locomotion_network

CALM = GustProcess(probability=0.0)


def test_antmaze_model_has_ogbench_physics():
    env = AntMazeEnv("medium", batch_size=1, seed=0)
    model = env.simulator.model
    assert model.opt.timestep == pytest.approx(0.02)
    assert env.simulator.frame_skip == 5 and env.simulator.control_dt == pytest.approx(0.1)  # 10 Hz
    np.testing.assert_allclose(model.actuator_gear[:, 0], 30.0)
    assert model.ngeom > 14  # the maze walls are there, and get the same contact
    np.testing.assert_allclose(model.geom_solref, np.tile([0.02, 1.0], (model.ngeom, 1)))
    np.testing.assert_allclose(model.geom_solimp[:, :3], np.tile([0.8, 0.8, 0.01], (model.ngeom, 1)))


def _random_torques(generator: torch.Generator, n: int) -> np.ndarray:
    return (torch.rand(n, 8, generator=generator) * 2 - 1).numpy()


def test_random_actions_keep_the_ant_upright():
    env = AntLocomotionEnv(batch_size=6, gust_process=CALM, seed=0)
    env.reset()
    generator = torch.Generator().manual_seed(1)
    upright = []
    for _ in range(1000):
        env.simulation.step(_random_torques(generator, 6), np.zeros((6, 2)))
        _, x, y, _ = env.simulation.qpos()[:, 3:7].T
        upright.append(1 - 2 * (x * x + y * y) > 0)  # the torso's z axis, world z component
    assert np.mean(upright) >= 0.95


def _displacement_after_gust(force: np.ndarray, *, settle: int = 20, n: int = 64) -> np.ndarray:
    env = AntLocomotionEnv(batch_size=n, gust_process=CALM, seed=3)
    env.reset()
    generator = torch.Generator().manual_seed(4)
    for t in range(settle + 10):
        push = np.tile(force, (n, 1)) if settle <= t < settle + 5 else np.zeros((n, 2))
        env.simulation.step(_random_torques(generator, n), push)
    return env.simulation.qpos()[:, :2]


def test_a_held_gust_moves_the_ant_as_ogbench_physics_does():
    # 3.5 N held for one 5-step gust window, same random torques with and without it;
    # OGBench's ant is displaced 0.33 m five steps after the window (gymnasium's: 0.20 m).
    pushed = _displacement_after_gust(np.array([3.5, 0.0]))
    calm = _displacement_after_gust(np.zeros(2))
    shift = np.linalg.norm(pushed - calm, axis=1).mean()
    assert shift == pytest.approx(0.33, rel=0.10)


def test_locomotion_env_specs_reward_and_termination():
    env = AntLocomotionEnv(batch_size=3, horizon=20, direction_period=7, seed=0)
    check_env_specs(env)
    rollout = env.rollout(20, break_when_any_done=False)
    velocity = (rollout["next", "xy"] - rollout["xy"]) / 0.1
    torch.testing.assert_close(rollout["next", "reward"], (velocity * rollout["direction"]).sum(-1, keepdim=True), atol=1e-5, rtol=1e-5)
    direction = rollout["direction"]
    torch.testing.assert_close(direction.norm(dim=-1), torch.ones(3, 20))
    changes = (direction[:, 1:] != direction[:, :-1]).any(-1)
    assert changes.nonzero()[:, 1].unique().tolist() == [6, 13]  # redrawn at steps 7 and 14
    assert rollout["next", "truncated"][:, -1].all()


def test_shipped_locomotion_weights_walk_in_every_direction():
    from tensordict import TensorDict
    from torchrl.envs.utils import ExplorationType, set_exploration_type

    from torchrl_causal.experts.locomotion import make_locomotion_actor

    actor = make_locomotion_actor(load_locomotion_network())
    east, north = torch.tensor([1.0, 0.0]), torch.tensor([0.0, 1.0])
    directions = torch.stack((east, north, -east, -north))
    env = AntLocomotionEnv(batch_size=4, direction_period=10_000, seed=0)
    start = env.reset(TensorDict(direction=directions, batch_size=[4]))
    with set_exploration_type(ExplorationType.DETERMINISTIC):
        rollout = env.rollout(150, actor, auto_reset=False, tensordict=start, break_when_any_done=False)
    travelled = ((rollout["next", "xy"][:, -1] - rollout["xy"][:, 0]) * directions).sum(-1)
    assert not rollout["next", "terminated"].any()
    assert (travelled >= 3.0).all(), travelled.tolist()
