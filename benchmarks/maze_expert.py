"""The Confounded AntMaze / HumanoidMaze experts beside the paper's (Table 1 / Appendix F), in both regimes.

Runs :class:`~torchrl_causal.envs.AntMazeExpert` or :class:`~torchrl_causal.envs.HumanoidMazeExpert`
(planner + a locomotion skill's weights, by default the shipped ones) for ``--episodes``
episodes per maze, regime and success radius, and prints the success rate, the mean successful
episode length and the raw E[Y] next to the paper's experts (AntMaze Medium: 87.6% / 301 ± 57
steps / -104.0, Large: 55.9% / 648 ± 99 / -255.2; HumanoidMaze Medium: 33.8% / 976 ± 410 /
-522.9, Large: 7.0% / 1463 ± 366 / -840.6)::

    OMP_NUM_THREADS=1 python benchmarks/maze_expert.py --robot ant --episodes 500 --radius 0.5 5.0 \
        --output results/antmaze_expert.md
    OMP_NUM_THREADS=1 python benchmarks/maze_expert.py --robot humanoid --episodes 500 --radius 0.45 \
        --output results/humanoidmaze_expert.md

``--falls`` (humanoid) instead rolls ``--batch`` episodes to the horizon and prints, per episode,
the first step with the head below 0.9 m (the skill's fall) and how far the torso got from the
start, the two things a walking skill must get right before the maze's success rate can move::

    OMP_NUM_THREADS=1 python benchmarks/maze_expert.py --robot humanoid --mazes medium --falls --batch 20 --weights BODY.pt
"""

from __future__ import annotations

import sys
import time
from pathlib import Path
from typing import NamedTuple

import torch

from torchrl_causal.cli.arguments import OneLineParser, count, non_negative, non_negative_number, positive_number
from torchrl_causal.envs import AntMazeEnv, HumanoidMazeEnv
from torchrl_causal.evaluation import evaluate_policy
from torchrl_causal.evaluation.paper import paper_figure
from torchrl_causal.experts import AntMazeExpert, HumanoidMazeExpert


class Robot(NamedTuple):
    env: type
    expert: type
    task: str  # the prefix of the paper's task names (torchrl_causal.evaluation.paper.PAPER_TASKS)


ROBOTS = {
    "ant": Robot(AntMazeEnv, AntMazeExpert, "antmaze"),
    "humanoid": Robot(HumanoidMazeEnv, HumanoidMazeExpert, "humanoidmaze"),
}


def paper_expert(robot: str, maze: str) -> str:
    """The paper's expert on ``maze``: success % / mean successful length ± std / raw E[Y]."""
    p = paper_figure(f"{ROBOTS[robot].task}_{maze}", "expert")
    return f"{p.success}% / {p.length_mean:.0f} ± {p.length_std:.0f} / {p.return_mean}"


def _expert_options(weights: str | None, clearance: float | None) -> dict:
    return {**({} if weights is None else {"weights": weights}), **({} if clearance is None else {"clearance": clearance})}


def evaluate(
    robot: str, maze: str, regime: str, radius: float, episodes: int, batch: int, seed: int, weights: str | None, clearance: float | None
):
    env = ROBOTS[robot].env(maze, batch_size=batch, regime=regime, seed=seed, success_radius=radius)
    expert = ROBOTS[robot].expert(env, **_expert_options(weights, clearance))
    result = evaluate_policy(env, expert, episodes=episodes, max_steps=env.horizon, regime=regime, seeds=(seed,))
    env.close()
    return result


def falls_and_reach(maze: str, batch: int, seed: int, weights: str | None, clearance: float | None, fall_height: float = 0.9) -> None:
    """Prints each humanoid episode's first fall (step, or -), its distance from the start (m) at its
    end, and its distance to the goal at the end and at its closest (a body that walks the path but
    misses the success radius shows here)."""
    env = HumanoidMazeEnv(maze, batch_size=batch, regime="train", seed=seed, success_radius=0.45)
    expert = HumanoidMazeExpert(env, **_expert_options(weights, clearance))
    td = env.reset()
    start = td["P"].clone()
    with torch.no_grad():
        rollout = env.rollout(env.horizon, expert, tensordict=td, auto_reset=False, break_when_any_done=False)
    env.close()
    done = rollout["next", "done"].squeeze(-1)
    last = torch.where(done.any(1), done.float().argmax(1), torch.full((batch,), done.shape[1] - 1))
    # The envs step on after a success (no reset): only the episode's own steps count.
    within = torch.arange(done.shape[1]) <= last[:, None]
    fallen = (rollout["next", "H"][..., 0] < fall_height) & within
    first_fall = torch.where(fallen.any(1), fallen.float().argmax(1), -1)
    end = rollout["next", "P"][torch.arange(batch), last]
    reached = rollout["next", "success"].squeeze(-1).any(1)
    goal = torch.as_tensor(env.goal_xy, dtype=end.dtype)
    to_goal = (rollout["next", "P"][..., :2] - goal).norm(dim=-1)
    closest = torch.where(within, to_goal, torch.inf).min(1).values
    for index in range(batch):
        fall = "-" if first_fall[index] < 0 else str(int(first_fall[index]))
        walked = float((end[index] - start[index]).norm())
        print(
            f"episode {index}: success {bool(reached[index])}, first fall {fall}, {walked:.1f} m from the start, "
            f"{float(to_goal[index, last[index]]):.1f} m from the goal at step {int(last[index]) + 1} "
            f"(closest {float(closest[index]):.1f} m)"
        )
    steps = sorted(int(last[index]) + 1 for index in range(batch) if reached[index])
    upright_failures = ~reached & (first_fall < 0)
    print(
        f"{maze}: {int(reached.sum())} of {batch} reached the goal (at steps {steps}), {int((first_fall >= 0).sum())} fell; "
        f"closest approach of the upright failures (m): {sorted(round(float(d), 1) for d in closest[upright_failures])}"
    )


def main() -> None:
    parser = OneLineParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--robot", choices=sorted(ROBOTS), default="ant")
    parser.add_argument("--mazes", nargs="+", default=["medium", "large"])
    parser.add_argument("--regimes", nargs="+", default=["train", "deploy"])
    parser.add_argument("--radius", nargs="+", type=positive_number, default=[0.5, 5.0], help="success radii (m)")
    parser.add_argument("--episodes", type=count, default=500)
    parser.add_argument("--batch", type=count, default=50, help="parallel episodes")
    parser.add_argument("--seed", type=non_negative, default=0)
    parser.add_argument("--weights", default=None, help="locomotion state dict (default: the shipped one)")
    parser.add_argument(
        "--clearance", type=non_negative_number, default=None, help="the planner's line-of-sight half-width (m; default: the expert's)"
    )
    parser.add_argument("--output", default=None, help="write the markdown table here too")
    parser.add_argument("--falls", action="store_true", help="humanoid: per-episode first fall and distance walked instead")
    args = parser.parse_args()
    torch.set_num_threads(1)
    if args.falls:
        if args.robot != "humanoid":
            parser.error("--falls reads the humanoid's head height: use it with --robot humanoid")
        for maze in args.mazes:
            falls_and_reach(maze, args.batch, args.seed, args.weights, args.clearance)
        return

    lines = [
        "| maze | radius (m) | regime | episodes | success % (± SE) | mean successful length (± std) | raw E[Y] (± std) "
        "| paper: success / length / E[Y] |",
        "| --- | ---: | --- | ---: | ---: | ---: | ---: | --- |",
    ]
    robot = ROBOTS[args.robot]
    start = time.time()
    for maze in args.mazes:
        for radius in args.radius:
            for regime in args.regimes:
                r = evaluate(args.robot, maze, regime, radius, args.episodes, args.batch, args.seed, args.weights, args.clearance)
                paper = paper_expert(args.robot, maze) if regime == "train" else "—"
                lines.append(
                    f"| {maze} | {radius:g} | {regime} | {r.n_episodes} | {100 * r.success_rate:.1f} ± "
                    f"{100 * r.success_se:.1f} | {r.ep_len_mean:.0f} ± {r.ep_len_std:.0f} | "
                    f"{r.return_mean:.1f} ± {r.return_std:.1f} | {paper} |"
                )
                print(lines[-1], flush=True)
    table = "\n".join(lines)
    command = "OMP_NUM_THREADS=1 python " + " ".join(sys.argv)
    print(f"\n{table}\n\n{time.time() - start:.0f} s")
    if args.output:
        Path(args.output).write_text(
            f"# Confounded {robot.env.__name__.removesuffix('Env')} expert (planner + trained locomotion skill)\n\n"
            f"Command ({time.time() - start:.0f} s on one core of a 2-core CPU machine):\n\n```\n{command}\n```\n\n"
            f"Seed {args.seed}; {args.episodes} episodes per row (the first episode of each of {args.batch} "
            f"parallel envs per round), horizon {robot.env.default_horizon}, deterministic expert.\n\n" + table + "\n"
        )


if __name__ == "__main__":
    main()
