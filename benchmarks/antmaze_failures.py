"""How AntMaze episodes fail: a flipped ant, or an upright one that ran out of time (and how far from the goal).

Rolls out each run's selected policy (``checkpoints/best.pt``, deterministic actions) for
``--episodes`` episodes in one batch and classifies each episode by where it ended. A
flipped ant rests on its back with the torso at z ~ 0.27 m (upright: 0.47-0.83 m in the
expert's demonstrations), and no policy here rights it: an episode that ends with the torso
below ``--flip-height`` is a flip.

    OMP_NUM_THREADS=1 python benchmarks/antmaze_failures.py RUN_DIR [RUN_DIR ...] --regime deploy --episodes 200
"""

from __future__ import annotations


import torch
from tensordict.nn import InteractionType, set_interaction_type

from torchrl_causal.lifecycle import open_run
from torchrl_causal.cli.arguments import OneLineParser, count, non_negative, non_negative_number


def classify(run_dir: str, regime: str, episodes: int, seed: int, flip_height: float) -> dict[str, float]:
    """Counts of success / flip / upright timeout, and the upright failures' final distances to the goal."""
    _, evaluator, policy = open_run(run_dir)
    env = evaluator.make_env(regime, episodes, seed)
    acting = evaluator.acting_policy(policy, env)
    acting.eval()
    maze = env.base_env
    goal = maze.layout.cell_center(torch.tensor(maze.task.goal_cell)).to(torch.float32)
    with torch.no_grad(), set_interaction_type(InteractionType.DETERMINISTIC):
        rollout = env.rollout(evaluator.cfg.env.horizon, acting, break_when_any_done=False)
    env.close()
    done = rollout["next", "done"].squeeze(-1)
    last = torch.where(done.any(1), done.float().argmax(1), torch.full((episodes,), done.shape[1] - 1))
    rows = torch.arange(episodes)
    success = rollout["next", "success"].squeeze(-1)[rows, last]
    end = rollout["next", "P"][rows, last]
    flipped = ~success & (end[:, 2] < flip_height)
    upright = ~success & ~flipped
    distance = (end[:, :2] - goal).norm(dim=-1)[upright]
    return {
        "episodes": episodes,
        "success": int(success.sum()),
        "flipped": int(flipped.sum()),
        "upright": int(upright.sum()),
        "upright_median_distance": float(distance.median()) if upright.any() else float("nan"),
        "upright_within_2m": int((distance < 2.0).sum()),
    }


def main() -> None:
    parser = OneLineParser(description=__doc__.splitlines()[0])
    parser.add_argument("runs", nargs="+", help="run directories (with checkpoints/best.pt)")
    parser.add_argument("--regime", default="deploy", choices=["train", "deploy"])
    parser.add_argument("--episodes", type=count, default=200)
    parser.add_argument("--seed", type=non_negative, default=40_000)
    parser.add_argument("--flip-height", type=non_negative_number, default=0.35)
    args = parser.parse_args()
    torch.set_num_threads(1)
    print(
        f"| run | {args.regime} episodes | success % | flipped % | upright timeout % "
        "| upright: median distance to goal (m) | upright within 2 m |"
    )
    print("|---|---:|---:|---:|---:|---:|---:|")
    for run in args.runs:
        c = classify(run, args.regime, args.episodes, args.seed, args.flip_height)
        n = c["episodes"]
        print(
            f"| {run} | {n} | {100 * c['success'] / n:.1f} | {100 * c['flipped'] / n:.1f} | {100 * c['upright'] / n:.1f} "
            f"| {c['upright_median_distance']:.1f} | {c['upright_within_2m']} |",
            flush=True,
        )


if __name__ == "__main__":
    main()
