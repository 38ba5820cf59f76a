"""Confounded RoverMaze: dynamics invariants, the confounding mechanism, planner and expert."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch
from torchrl.envs.utils import check_env_specs

from torchrl_causal.envs import MAZE_MAPS, MazeLayout, RoverMazeEnv, RoverParameters, rotate
from torchrl_causal.envs.rover_maze import ROVER_COLOURS
from torchrl_causal.experts import MazePlanner, RoverExpert


def _wall_rectangles(maze: str) -> torch.Tensor:
    """``[n, 4]`` (x_min, x_max, y_min, y_max) of every wall cell, from the raw map (cell size 1)."""
    rows = MAZE_MAPS[maze]
    height, width = len(rows), len(rows[0])
    boxes = [
        (col - width / 2, col + 1 - width / 2, height / 2 - row - 1, height / 2 - row)
        for row, line in enumerate(rows)
        for col, cell in enumerate(line)
        if cell == 1
    ]
    return torch.tensor(boxes)


def _gap_to_walls(points: torch.Tensor, maze: str) -> torch.Tensor:
    """Chebyshev distance from each point to the nearest wall cell (0 inside a wall)."""
    walls = _wall_rectangles(maze)
    x, y = points[..., 0:1], points[..., 1:2]
    dx = torch.clamp(torch.maximum(walls[:, 0] - x, x - walls[:, 1]), min=0)
    dy = torch.clamp(torch.maximum(walls[:, 2] - y, y - walls[:, 3]), min=0)
    return torch.maximum(dx, dy).amin(-1)


def _uniform_policy(generator, throttle=(0.0, 1.0)):
    low, high = throttle

    def act(td):
        u = torch.rand((*td.shape, 2), generator=generator)
        return td.set("action", torch.stack((low + (high - low) * u[..., 0], 2 * u[..., 1] - 1), -1))

    return act


def _still(td):
    return td.set("action", torch.zeros((*td.shape, 2)))


@pytest.mark.parametrize("maze", ["u", "medium", "large"])
@pytest.mark.parametrize("regime", ["train", "deploy"])
def test_specs(maze, regime):
    check_env_specs(RoverMazeEnv(maze=maze, batch_size=(4,), regime=regime, seed=0))


def test_bad_arguments_are_named():
    with pytest.raises(ValueError, match="maze"):
        RoverMazeEnv(maze="huge")
    with pytest.raises(ValueError, match="tunnel"):
        RoverParameters(max_speed=0.9)
    with pytest.raises(ValueError, match="confounding_strength"):
        RoverMazeEnv(batch_size=(2,), confounding_strength=2.0)


@pytest.mark.parametrize("maze", ["u", "medium"])
def test_walls_are_never_crossed(maze):
    env = RoverMazeEnv(maze=maze, batch_size=(256,), seed=0)
    rollout = env.rollout(300, _uniform_policy(torch.Generator().manual_seed(0)), break_when_any_done=False)
    before, after = rollout["P"], rollout["next", "P"]
    half = env.params.half_size
    # the footprint never overlaps a wall, before or after any step
    assert (_gap_to_walls(after, maze) >= half - 1e-5).all()
    # moves are axis-separated: the corner point of each move is clear too, and steps are short
    corner = torch.stack((after[..., 0], before[..., 1]), -1)
    moved = ~rollout["next", "done"].squeeze(-1)
    assert (_gap_to_walls(corner[moved], maze) >= half - 1e-5).all()
    assert ((after - before)[moved].abs().amax(-1) < 0.2).all()
    # the rover did run into walls (else this test would check nothing)
    assert (_gap_to_walls(after, maze) < half + 0.01).float().mean() > 0.05


def test_heading_persists_and_speed_follows_throttle():
    params = RoverParameters(heading_noise=0.0)
    env = RoverMazeEnv(maze="medium", batch_size=(64,), params=params, seed=0)
    rollout = env.rollout(20, _uniform_policy(torch.Generator().manual_seed(1), (-1.0, 1.0)))
    angle = torch.atan2(rollout["latent", "O"][..., 1], rollout["latent", "O"][..., 0])
    next_angle = torch.atan2(rollout["next", "latent", "O"][..., 1], rollout["next", "latent", "O"][..., 0])
    turned = torch.remainder(next_angle - angle + math.pi, 2 * math.pi) - math.pi
    torch.testing.assert_close(turned, params.turn_rate * rollout["action"][..., 1], atol=1e-5, rtol=0)
    speed = rollout["L"] + params.speed_response * (params.max_speed * rollout["action"][..., :1] - rollout["L"])
    torch.testing.assert_close(rollout["next", "L"], speed)


def test_gusts_follow_the_process_and_push_the_rover():
    env = RoverMazeEnv(maze="large", batch_size=(512,), seed=0)
    rollout = env.rollout(200, _still)
    gust = rollout["scm", "U"]  # the gust during each step
    blocks = gust.reshape(512, 40, 5, 2)
    assert torch.equal(blocks, blocks[:, :, :1].expand_as(blocks))  # redrawn every 5 steps only
    magnitude = blocks[:, :, 0].norm(dim=-1)
    active = magnitude > 0
    assert abs(active.float().mean().item() - 0.05) < 4 * math.sqrt(0.05 * 0.95 / active.numel())
    assert ((magnitude[active] >= 2.0) & (magnitude[active] <= 5.0)).all()
    # standing still, the rover moves exactly by the push of the gust unless a wall stops it
    push = rollout["next", "P"] - rollout["P"]
    free = _gap_to_walls(rollout["P"], "large") > env.params.half_size + 0.05
    torch.testing.assert_close(push[free], env.params.gust_push * gust[free], atol=1e-5, rtol=0)
    # and pays the paper's 1{success} - |U_t| (1 + d_t / 25), d_t in metres (4 per cell) after the step
    metres = 4.0 * (rollout["next", "P"] - env.goal_position).norm(dim=-1, keepdim=True)
    expected = rollout["next", "success"].float() - gust.norm(dim=-1, keepdim=True) * (1 + metres / 25)
    torch.testing.assert_close(rollout["next", "reward"], expected)


@pytest.mark.parametrize("strength", [0.0, 0.25, 0.5, 1.0])
def test_deploy_rotates_the_compass_by_strength_pi(strength):
    readings = {}
    for regime in ("train", "deploy"):
        env = RoverMazeEnv(maze="medium", batch_size=(32,), regime=regime, confounding_strength=strength, seed=3)
        readings[regime] = env.rollout(50, _still)["W"]
    torch.testing.assert_close(readings["deploy"], rotate(readings["train"], strength * math.pi), atol=1e-6, rtol=0)
    if strength == 0.0:
        assert torch.equal(readings["deploy"], readings["train"])


def test_compass_reads_the_heading_in_training():
    env = RoverMazeEnv(maze="medium", batch_size=(256,), seed=0)
    rollout = env.rollout(50, _uniform_policy(torch.Generator().manual_seed(2)))
    calm = rollout["scm", "U"].norm(dim=-1) == 0
    raw = torch.atanh(rollout["W"][calm])
    residual = raw - 0.9 * rollout["latent", "O"][calm]
    assert residual.mean(0).abs().max() < 0.01 and abs(residual.std().item() - 0.05) < 0.005


def test_heading_is_hidden_at_reset_but_visible_in_lags_of_position():
    env = RoverMazeEnv(maze="medium", batch_size=(64,), seed=0)
    # at reset the heading is uniform and independent of what the imitator sees (P, L = 0)
    start = RoverMazeEnv(maze="medium", batch_size=(4096,), seed=1).reset()
    heading = start["latent", "O"]
    assert (start["L"] == 0).all()
    assert heading.mean(0).abs().max() < 4 / math.sqrt(4096)
    centred = start["P"] - start["P"].mean(0)
    correlation = (centred.T @ heading) / (centred.norm(dim=0)[:, None] * heading.norm(dim=0)[None] + 1e-12)
    assert correlation.abs().max() < 4 / math.sqrt(4096)
    # while moving, the heading is linearly decodable from the last three position differences
    rollout = env.rollout(300, RoverExpert(env, seed=0))
    dp = rollout["next", "P"] - rollout["P"]
    window = torch.cat((dp[:, 2:], dp[:, 1:-1], dp[:, :-2]), -1)  # ΔP_t, ΔP_{t-1}, ΔP_{t-2}
    target = rollout["next", "latent", "O"][:, 2:]
    moving = (rollout["next", "L"][:, 2:, 0] > 0.5 * env.params.max_speed) & ~rollout["next", "done"][:, 2:, 0]
    features = torch.cat((window[moving], torch.ones(int(moving.sum()), 1)), -1).double()
    solution = torch.linalg.lstsq(features, target[moving].double()).solution
    residual = target[moving].double() - features @ solution
    r_squared = 1 - residual.pow(2).sum() / (target[moving].double() - target[moving].double().mean(0)).pow(2).sum()
    assert r_squared > 0.9, r_squared


def test_template_excludes_the_compass_from_every_causal_window():
    from torchrl_causal.graphs import observation_window, windowed_adjustment

    template = RoverMazeEnv(maze="u", batch_size=(1,)).causal_template
    assert template.latent == ("O",)
    for k in (0, 1, 10):
        window = windowed_adjustment(template, k, mode="relaxed")
        assert "W" in window.excluded and "W" not in window.lags
        assert window.lags["P"] == tuple(range(k + 1)) and window.lags["L"] == tuple(range(k + 1))
    assert "W" in observation_window(template).lags


def test_planner_distance_field_and_waypoints():
    layout = MazeLayout.from_name("medium")
    planner = MazePlanner(layout, goal_cell=(6, 6))
    # hand-derived: (1, 1) is 10 moves from (6, 6); (4, 6) is 2 (south twice)
    assert planner.distance[1, 1] == 10 and planner.distance[4, 6] == 2 and planner.distance[0, 0] == -1
    generator = torch.Generator().manual_seed(0)
    cells = torch.tensor(layout.free_cells())[torch.randint(len(layout.free_cells()), (500,), generator=generator)]
    points = layout.cell_center(cells) + (torch.rand(500, 2, generator=generator) - 0.5) * 0.6
    waypoints = planner.waypoint(points)
    # a waypoint is never further from the goal, and the straight segment to it is clear of walls
    assert (planner.cells_to_goal(waypoints) <= planner.cells_to_goal(points)).all()
    segment = points[:, None] + (waypoints - points)[:, None] * torch.linspace(0, 1, 50)[:, None]
    assert (_gap_to_walls(segment, "medium") >= planner.clearance - 1e-5).all()
    with pytest.raises(ValueError, match="goal_cell"):
        MazePlanner(layout, goal_cell=(0, 0))


@pytest.mark.parametrize(("maze", "batch", "steps", "minimum"), [("medium", 32, 500, 0.9), ("large", 16, 900, 0.8)])
def test_expert_succeeds(maze, batch, steps, minimum):
    env = RoverMazeEnv(maze=maze, batch_size=(batch,), seed=0)
    expert = RoverExpert(env, seed=0)
    td = env.reset()
    reached = torch.zeros(batch, dtype=torch.bool)
    with torch.no_grad():
        for _ in range(steps):
            step = env.step(expert(td))
            reached |= step["next", "success"].squeeze(-1)
            if reached.all():
                break
            td = env.maybe_reset(step["next"])
    assert reached.float().mean() >= minimum


def test_top_down_render_draws_walls_goal_and_the_rover_facing_its_heading() -> None:
    env = RoverMazeEnv(maze="u", batch_size=(2,), seed=0)
    env.reset()
    width, height = 100, 80
    rows, cols = env.layout.walls.shape
    scale = min(width / cols, height / rows) / env.layout.cell_size

    def pixel(frame, x, y):  # world (x, y) -> the frame's pixel, the maze centred on the origin
        return tuple(frame[int(height / 2 - y * scale), int(width / 2 + x * scale)].tolist())

    free = env.layout.cell_center(torch.tensor((1, 3))).tolist()
    env.position = torch.tensor([free, free], dtype=env.position.dtype)
    env.heading = torch.tensor([[0.0], [math.pi / 2]], dtype=env.heading.dtype)
    frames = env.render(width=width, height=height)
    assert frames.shape == (2, height, width, 3) and frames.dtype == np.uint8
    half = env.params.half_size
    for frame, (dx, dy) in zip(frames, ((1.0, 0.0), (0.0, 1.0))):  # heading 0 faces +x, pi/2 faces +y
        for cell in map(tuple, env.layout.walls.nonzero().tolist()):
            assert pixel(frame, *env.layout.cell_center(torch.tensor(cell)).tolist()) == ROVER_COLOURS["wall"]
        assert pixel(frame, *env.goal_position.reshape(-1).tolist()) == ROVER_COLOURS["goal"]
        assert pixel(frame, *free) == ROVER_COLOURS["rover"]
        assert pixel(frame, free[0] + 0.7 * half * dx, free[1] + 0.7 * half * dy) == ROVER_COLOURS["nose"]
        assert pixel(frame, free[0] - 0.7 * half * dx, free[1] - 0.7 * half * dy) == ROVER_COLOURS["rover"]
        assert pixel(frame, free[0] + 2 * half, free[1]) == ROVER_COLOURS["floor"]
    with pytest.raises(ValueError, match="camera"):
        env.render(camera="track")
    with pytest.raises(ValueError, match="reset"):
        RoverMazeEnv(maze="u", batch_size=(1,), seed=0).render()
