"""How maze episodes fail: a body that went down, one that stopped short of the goal, or one
that ended off the shortest route (a wrong corridor), for AntMaze and HumanoidMaze runs.

Rolls out each run's selected policy (``checkpoints/best.pt``, deterministic actions; the expert
for an ``expert`` run) for ``--episodes`` episodes in one batch, to the horizon, and classifies
every failed episode once, in this order:

* **down**: the ant flipped (its torso ends below ``--flip-height``, 0.35 m: it rests on its
  back at ~0.27 m and no policy here rights it) or the humanoid fell (its head dropped below
  ``--fall-height``, 0.9 m, the walking skill's fall, at any step of the episode; a fallen
  humanoid does not end the episode);
* **stopped short**: upright, ending within ``--short`` metres (2 m) of the goal;
* **wrong corridor**: upright, ending in a cell that lies on no shortest route from the start
  cell to the goal cell (its BFS distance from the start plus its distance to the goal exceeds
  the start's distance to the goal);
* **on the route**: upright, on a shortest route, further than ``--short`` from the goal (too slow).

    OMP_NUM_THREADS=1 python benchmarks/maze_failures.py RUN_DIR [RUN_DIR ...] --regime deploy --episodes 100
"""

from __future__ import annotations

import torch
from tensordict.nn import InteractionType, set_interaction_type

from torchrl_causal.cli.arguments import OneLineParser, count, non_negative, positive_number
from torchrl_causal.envs import HumanoidMazeEnv
from torchrl_causal.experts import MazePlanner
from torchrl_causal.lifecycle import open_run

CLASSES = ("success", "down", "stopped_short", "wrong_corridor", "on_route")


def classify(run_dir: str, regime: str, episodes: int, seed: int, flip_height: float, fall_height: float, short: float) -> dict[str, float]:
    """Counts of each of :data:`CLASSES` over ``episodes`` episodes of the run's selected policy."""
    _, evaluator, policy = open_run(run_dir)
    env = evaluator.make_env(regime, episodes, seed)
    acting = evaluator.acting_policy(policy, env)
    if isinstance(acting, torch.nn.Module):
        acting.eval()
    maze = getattr(env, "base_env", env)
    layout = maze.layout
    goal_cell = tuple(int(c) for c in maze.task.goal_cell)
    with torch.no_grad(), set_interaction_type(InteractionType.DETERMINISTIC):
        rollout = env.rollout(evaluator.cfg.env.horizon, acting, break_when_any_done=False)
    env.close()
    done = rollout["next", "done"].squeeze(-1)
    steps = done.shape[1]
    last = torch.where(done.any(1), done.float().argmax(1), torch.full((episodes,), steps - 1))
    rows = torch.arange(episodes)
    within = torch.arange(steps)[None, :] <= last[:, None]
    success = rollout["next", "success"].squeeze(-1)[rows, last]
    position = rollout["next", "P"]
    end = position[rows, last]
    if isinstance(maze, HumanoidMazeEnv):
        down = ((rollout["next", "H"][..., 0] < fall_height) & within).any(1)
    else:
        down = end[:, 2] < flip_height
    down &= ~success
    upright = ~success & ~down
    to_goal = MazePlanner(layout, goal_cell)
    start_xy = rollout["P"][:, 0, :2]
    start_cell = tuple(int(c) for c in layout.cell_of(start_xy[:1])[0])
    from_start = MazePlanner(layout, start_cell)
    route = int(to_goal.cells_to_goal(start_xy[:1])[0])
    detour = from_start.cells_to_goal(end[:, :2]) + to_goal.cells_to_goal(end[:, :2]) > route
    goal_xy = layout.cell_center(torch.tensor(goal_cell)).to(end.dtype)
    near = (end[:, :2] - goal_xy).norm(dim=-1) < short
    counts = {
        "success": success,
        "down": down,
        "stopped_short": upright & near,
        "wrong_corridor": upright & ~near & detour,
        "on_route": upright & ~near & ~detour,
    }
    return {"episodes": episodes, **{name: int(mask.sum()) for name, mask in counts.items()}}


def main() -> None:
    parser = OneLineParser(description=__doc__.splitlines()[0])
    parser.add_argument("runs", nargs="+", help="run directories (with checkpoints/best.pt, or an expert run)")
    parser.add_argument("--regime", default="deploy", choices=["train", "deploy"])
    parser.add_argument("--episodes", type=count, default=100)
    parser.add_argument("--seed", type=non_negative, default=40_000)
    parser.add_argument("--flip-height", type=positive_number, default=0.35, help="ant: torso height (m) below which it has flipped")
    parser.add_argument("--fall-height", type=positive_number, default=0.9, help="humanoid: head height (m) below which it has fallen")
    parser.add_argument(
        "--short", type=positive_number, default=2.0, help="metres from the goal: an upright failure within it stopped short"
    )
    args = parser.parse_args()
    torch.set_num_threads(1)
    print(f"| run | {args.regime} episodes | " + " | ".join(f"{name.replace('_', ' ')} %" for name in CLASSES) + " |")
    print("|---|---:|" + "---:|" * len(CLASSES))
    for run in args.runs:
        counts = classify(run, args.regime, args.episodes, args.seed, args.flip_height, args.fall_height, args.short)
        n = counts["episodes"]
        print(f"| {run} | {n} | " + " | ".join(f"{100 * counts[name] / n:.1f}" for name in CLASSES) + " |", flush=True)


if __name__ == "__main__":
    main()
