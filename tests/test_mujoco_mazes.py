"""Confounded AntMaze and Confounded HumanoidMaze: specs, mechanism, tasks, determinism, rendering.

Facts checked against sources independent of the env code: the paper's variable dimensions
(Appendix D, tab:env-summary: |V^O| = 35 / 89, |X| = 8 / 21), the gymnasium-robotics maze
geometry (wall geoms of the compiled MuJoCo model), a planar rotation by strength * pi, and
MuJoCo's determinism. Humanoid steps are kept few: it is the slow one.
"""

from __future__ import annotations

import ctypes.util
import math

import numpy as np
import pytest
import torch
from torchrl.envs import SerialEnv
from torchrl.envs.utils import check_env_specs

from torchrl_causal.envs import AntMazeEnv, GustProcess, HumanoidMazeEnv
from torchrl_causal.experts import MazePlanner

ENVS = (AntMazeEnv, HumanoidMazeEnv)

# Appendix D: variable -> dimension; X is the action, the latent variable is hidden from the imitator.
PAPER_DIMS = {
    AntMazeEnv: {"P": 3, "O": 4, "A": 8, "L": 3, "T": 3, "J": 8, "W": 2, "X": 8},
    HumanoidMazeEnv: {"P": 2, "A": 21, "H": 1, "E": 12, "V": 3, "C": 3, "J": 27, "W": 2, "X": 21},
}
PAPER_LATENT = {AntMazeEnv: "O", HumanoidMazeEnv: "C"}
PAPER_IMITATOR_DIMS = {AntMazeEnv: 35, HumanoidMazeEnv: 89}  # observed states + previous action
PAPER_HORIZON = {AntMazeEnv: 1000, HumanoidMazeEnv: 2000}


def _key(variable: str, latent: str) -> str | tuple[str, str]:
    return ("latent", variable) if variable == latent else variable


def _rollout(env, steps: int, *, action_seed: int = 0, keys=("P", "W")) -> dict[str, torch.Tensor]:
    """Steps ``env`` from a reset under uniform random actions drawn from ``action_seed``."""
    generator = torch.Generator().manual_seed(action_seed)
    td = env.reset()
    trace = {key: [td[key].clone()] for key in keys}
    for _ in range(steps):
        td["action"] = 2 * torch.rand(env.action_spec.shape, generator=generator) - 1
        td = env.step(td)["next"]
        for key in keys:
            trace[key].append(td[key].clone())
    return {key: torch.stack(values) for key, values in trace.items()}


@pytest.mark.parametrize("regime", ["train", "deploy"])
@pytest.mark.parametrize("env_cls", ENVS)
def test_specs(env_cls, regime):
    env = env_cls("medium", batch_size=2, regime=regime, confounding_strength=0.7, seed=0)
    check_env_specs(env, seed=0)
    assert env.horizon == PAPER_HORIZON[env_cls]
    assert env.regime == regime and env.confounding_strength == 0.7


def test_serial_env_batches_the_ant():
    env = SerialEnv(2, lambda: AntMazeEnv("large", regime="deploy", seed=0))
    check_env_specs(env, seed=0)
    env.close()


@pytest.mark.parametrize("env_cls", ENVS)
def test_variables_match_paper_and_template(env_cls):
    env = env_cls("medium", batch_size=3, seed=0)
    template = env.causal_template
    latent, dims = PAPER_LATENT[env_cls], PAPER_DIMS[env_cls]
    assert set(template.variables) == set(dims)
    assert template.action == "X" and template.latent == (latent,)
    td = env.rand_step(env.reset())
    for variable in template.variables:
        key = "action" if variable == template.action else _key(variable, latent)
        assert td[key].shape == (3, dims[variable]), variable
        spec = env.full_action_spec["action"] if key == "action" else env.observation_spec[key]
        assert spec.shape == (3, dims[variable]), variable
    imitator = sum(dims[v] for v in template.observed)  # observed states and X (the previous action)
    assert imitator == PAPER_IMITATOR_DIMS[env_cls]


@pytest.mark.parametrize("env_cls", ENVS)
def test_gust_pushes_the_torso_along_its_direction(env_cls):
    # The same seed consumes the same random numbers whatever the gust probability, so the two
    # runs differ only by the force on the torso; a period beyond the run holds one direction.
    finals = {}
    for probability in (0.0, 1.0):
        env = env_cls("medium", batch_size=2, seed=5)
        env.gust_process = GustProcess(period=10_000, probability=probability, low=5.0, high=5.0)
        finals[probability] = _rollout(env, 10)["P"][-1, :, :2]
        gust = env.gust.clone()
    push = ((finals[1.0] - finals[0.0]) * GustProcess.direction(gust)).sum(-1)
    # 5 N for 0.5 s (ant, 0.91 kg) / 0.25 s (humanoid, 40.8 kg): centimetres to decimetres.
    minimum = 0.05 if env_cls is AntMazeEnv else 0.002
    assert (push > minimum).all(), push


@pytest.mark.parametrize("strength", [0.3, 1.0])
@pytest.mark.parametrize("env_cls", ENVS)
def test_deploy_compass_is_train_compass_rotated(env_cls, strength):
    keys = ("P", "J", "W")
    train = _rollout(env_cls("medium", batch_size=2, regime="train", seed=1), 3, keys=keys)
    deploy = _rollout(env_cls("medium", batch_size=2, regime="deploy", confounding_strength=strength, seed=1), 3, keys=keys)
    torch.testing.assert_close(deploy["P"], train["P"], rtol=0, atol=0)  # the regime only moves W
    torch.testing.assert_close(deploy["J"], train["J"], rtol=0, atol=0)
    angle = strength * math.pi
    cos, sin = math.cos(angle), math.sin(angle)
    x, y = train["W"].unbind(-1)
    torch.testing.assert_close(deploy["W"], torch.stack((cos * x - sin * y, sin * x + cos * y), -1))
    assert not torch.allclose(deploy["W"], train["W"], atol=1e-2)


def test_train_compass_reads_the_true_heading():
    env = AntMazeEnv("medium", batch_size=4, seed=2)
    env.gust_process = GustProcess(probability=0.0)
    td = env.reset()
    w, x, y, z = td["latent", "O"].unbind(-1)
    yaw = torch.atan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))
    expected = torch.tanh(0.9 * torch.stack((torch.cos(yaw), torch.sin(yaw)), -1))
    # calm: W = tanh(0.9 heading + N(0, 0.05^2)); tanh is 1-Lipschitz, so 4 sigma bounds the gap
    assert (td["W"] - expected).abs().max() < 4 * 0.05


@pytest.mark.parametrize("env_cls", ENVS)
def test_reaching_the_goal_terminates(env_cls):
    env = env_cls("medium", batch_size=2, seed=0)
    td = env.reset()
    data = env.simulator.datas[0]
    data.qpos[:2] = env.goal_xy + 0.1  # teleport batch element 0 next to the goal
    td["action"] = torch.zeros(env.action_spec.shape)
    out = env.step(td)["next"]
    assert out["success"].squeeze(-1).tolist() == [True, False]
    assert out["terminated"].squeeze(-1).tolist() == [True, False]
    assert out["done"].squeeze(-1).tolist() == [True, False]
    # the paper's reward: 1{success} - |U_t| (1 + d_t / 25), d_t in metres after the step
    distance = torch.from_numpy(np.linalg.norm(env.simulator.qpos()[:, :2] - env.goal_xy, axis=1)).float()
    expected_reward = out["success"].float() - td["scm", "U"].norm(dim=-1, keepdim=True) * (1 + distance[:, None] / 25)
    torch.testing.assert_close(out["reward"], expected_reward)


def test_horizon_truncates():
    env = AntMazeEnv("medium", batch_size=1, horizon=3, seed=0)
    td = env.rollout(10, break_when_any_done=True)
    assert td.shape == (1, 3)
    assert td["next", "truncated"][0, :, 0].tolist() == [False, False, True]
    assert not td["next", "terminated"].any()


@pytest.mark.parametrize("env_cls", ENVS)
def test_same_seed_same_rollout(env_cls):
    keys = ("P", "J", "W", ("latent", PAPER_LATENT[env_cls]), ("scm", "U"))
    steps = 25 if env_cls is AntMazeEnv else 8
    first = _rollout(env_cls("large", batch_size=2, seed=11), steps, keys=keys)
    second = _rollout(env_cls("large", batch_size=2, seed=11), steps, keys=keys)
    other = _rollout(env_cls("large", batch_size=2, seed=12), steps, keys=keys)
    for key in keys:
        torch.testing.assert_close(first[key], second[key], rtol=0, atol=0)
    assert not torch.equal(first["P"], other["P"])


def test_partial_reset_leaves_other_simulations_alone():
    env = AntMazeEnv("medium", batch_size=2, seed=0)
    td = env.reset()
    td["action"] = torch.ones(env.action_spec.shape)
    td = env.step(td)["next"]
    before = td["P"].clone()
    td["_reset"] = torch.tensor([[True], [False]])
    after = env.reset(td)
    torch.testing.assert_close(after["P"][1], before[1], rtol=0, atol=0)
    start = torch.as_tensor(env.start_xy, dtype=torch.float32)
    assert (after["P"][0, :2] - start).abs().max() <= 0.25 * env.layout.cell_size


@pytest.mark.parametrize("maze", ["medium", "large"])
def test_planner_path_is_valid_in_the_mujoco_maze(maze):
    env = AntMazeEnv(maze, seed=0)
    model, layout, task = env.simulator.model, env.layout, env.task
    # The planner's walls and coordinates are the compiled MuJoCo maze's.
    rows, cols = layout.shape
    wall_names = {model.geom(i).name for i in range(model.ngeom)}
    for row in range(rows):
        for col in range(cols):
            wall = f"block_{row}_{col}" in wall_names
            assert wall == (not layout.is_free_cell((row, col)))
            if wall:
                centre = layout.cell_center(torch.tensor([row, col])).numpy()
                np.testing.assert_allclose(model.geom(f"block_{row}_{col}").pos[:2], centre)
    planner = MazePlanner(layout, goal_cell=task.goal_cell, lookahead=rows * cols)
    start = layout.cell_center(torch.tensor(task.start_cell))
    length = int(planner.cells_to_goal(start))
    path = [tuple(cell) for cell in planner.path_cells(start)[: length + 1].tolist()]
    assert path[0] == task.start_cell and path[-1] == task.goal_cell
    assert all(layout.is_free_cell(cell) for cell in path)
    assert all(abs(a[0] - b[0]) + abs(a[1] - b[1]) == 1 for a, b in zip(path, path[1:]))
    assert len(set(path)) == len(path)


def test_bad_arguments_name_the_offender():
    with pytest.raises(ValueError, match="maze"):
        AntMazeEnv("u")
    with pytest.raises(ValueError, match="confounding_strength"):
        HumanoidMazeEnv("medium", confounding_strength=1.5)
    with pytest.raises(ValueError, match="regime"):
        AntMazeEnv("medium", regime="test")
    with pytest.raises(ValueError, match="success_radius"):
        AntMazeEnv("medium", success_radius=0.0)


def _egl_available() -> bool:
    return ctypes.util.find_library("EGL") is not None


@pytest.mark.skipif(
    not _egl_available(),
    reason="offscreen rendering needs EGL: apt-get install libegl1 libegl-mesa0 libgl1-mesa-dri",
)
@pytest.mark.parametrize("env_cls", ENVS)
def test_render_gives_rgb_frames(env_cls):
    # Skipped (never passed) only where the EGL library is absent; where it is present, a
    # rendering failure fails the test.
    env = env_cls("medium", batch_size=2, seed=0)
    env.reset()
    env.simulator.datas[1].qpos[:2] = env.goal_xy
    frames = env.render(width=96, height=64)
    assert frames.shape == (2, 64, 96, 3) and frames.dtype == np.uint8
    assert frames.std() > 5  # a lit scene, not a blank buffer
    assert np.abs(frames[0].astype(int) - frames[1]).sum() > 0  # the agent moved: the picture did too
    env.close()
