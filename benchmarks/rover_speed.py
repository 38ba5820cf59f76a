"""Env steps per second of Confounded RoverMaze beside its bare physics, in one run.

Rows, all at the same batch size on the medium maze, under pre-drawn uniform random actions:

* ``bare rover physics``: :func:`~torchrl_causal.envs.rover_maze.rover_dynamics` alone in a
  plain loop, no gust, no compass, no reward: the bare-minimum baseline (ratio 1).
* ``SCM step, raw functions``: what one env step computes, without TorchRL: the gust
  process, the physics under the gust and the heading slip, the compass, the reward and
  the success test.
* ``RoverMazeEnv`` via ``step_and_maybe_reset``: the TorchRL env, stepped as a collector
  does (TensorDicts, specs, partial resets of finished episodes).

Rounds alternate between the rows so that load from other processes hits all of them
alike; each row's figure is its median over rounds of env steps (batch x steps) per CPU
second of the process (``time.process_time``); the ratio divides it by the baseline's.

With ``--expert N``, also measures :class:`~torchrl_causal.envs.RoverExpert` over ``N``
episodes per maze (train regime; its success rate and mean successful episode length).

Run: ``OMP_NUM_THREADS=1 python benchmarks/rover_speed.py [--batch 256] [--steps 400] [--rounds 5] [--threads 1] [--expert 256]``
"""

from __future__ import annotations

import math
import statistics
import time
from collections.abc import Callable

import torch

from torchrl_causal.cli.arguments import OneLineParser, count, non_negative
from torchrl_causal.envs import RoverMazeEnv
from torchrl_causal.envs.rover_maze import rover_dynamics, unit_heading
from torchrl_causal.experts import RoverExpert


def bare_physics(env: RoverMazeEnv, actions: torch.Tensor) -> float:
    position = env.start_position.expand(actions.shape[1], 2).clone()
    heading = torch.zeros(actions.shape[1], 1)
    speed = torch.zeros(actions.shape[1], 1)
    calm = torch.zeros(actions.shape[1], 2)
    start = time.process_time()
    for action in actions:
        position, heading, speed = rover_dynamics(position, heading, speed, action, calm, env.layout, env.params)
    return actions.numel() / 2 / (time.process_time() - start)


def raw_scm_step(env: RoverMazeEnv, actions: torch.Tensor) -> float:
    batch = actions.shape[1]
    generator = torch.Generator().manual_seed(0)
    position = env.start_position.expand(batch, 2).clone()
    heading, speed = torch.zeros(batch, 1), torch.zeros(batch, 1)
    gust = env.gust_process.draw((batch,), generator=generator)
    step_count = torch.zeros(batch, 1, dtype=torch.long)
    start = time.process_time()
    for action in actions:
        slip = env.params.heading_noise * torch.randn(heading.shape, generator=generator)
        position, heading, speed = rover_dynamics(position, heading, speed, action, gust, env.layout, env.params, slip)
        distance = (position - env.goal_position).norm(dim=-1, keepdim=True)
        success = distance < env.params.goal_radius
        reward = success.float() - env.gust_process.exposure(gust) * (1 + env.metres_per_unit * distance / 25)
        step_count = step_count + 1
        gust = env.gust_process.advance(gust, step_count, generator=generator)
        compass = env.compass.read(unit_heading(heading), gust, rotation=math.pi, generator=generator)
    del reward, success, compass
    return actions.numel() / 2 / (time.process_time() - start)


def torchrl_env(env: RoverMazeEnv, actions: torch.Tensor) -> float:
    td = env.reset()
    start = time.process_time()
    for action in actions:
        td["action"] = action
        _, td = env.step_and_maybe_reset(td)
    return actions.numel() / 2 / (time.process_time() - start)


@torch.no_grad()
def expert_report(maze: str, episodes: int) -> str:
    """The expert's success rate and mean successful length over ``episodes`` first episodes."""
    env = RoverMazeEnv(maze=maze, batch_size=(episodes,), regime="train", seed=0)
    expert = RoverExpert(env, seed=0)
    td = env.reset()
    first_success = torch.zeros(episodes, dtype=torch.long)
    for t in range(env.horizon):
        step = env.step(expert(td))
        newly = step["next", "success"].squeeze(-1) & (first_success == 0)
        first_success[newly] = t + 1
        if (first_success > 0).all():
            break
        td = step["next"]
    reached = first_success > 0
    lengths = first_success[reached].float()
    return (
        f"| {maze} | {episodes} | {reached.float().mean().item():.3f} | {lengths.mean().item():.1f} "
        f"| {int(lengths.min())}-{int(lengths.max())} |"
    )


def main() -> None:
    parser = OneLineParser(description=__doc__.splitlines()[0])
    parser.add_argument("--batch", type=count, default=256)
    parser.add_argument("--steps", type=count, default=400)
    parser.add_argument("--rounds", type=count, default=5)
    parser.add_argument("--threads", type=count, default=1)
    parser.add_argument("--expert", type=non_negative, default=0, help="episodes per maze for the expert report")
    args = parser.parse_args()
    torch.set_num_threads(args.threads)
    env = RoverMazeEnv(maze="medium", batch_size=(args.batch,), regime="deploy", seed=0)
    actions = torch.rand(args.steps, args.batch, 2, generator=torch.Generator().manual_seed(0)) * 2 - 1
    rows: dict[str, Callable[[RoverMazeEnv, torch.Tensor], float]] = {
        "bare rover physics (baseline)": bare_physics,
        "SCM step, raw functions": raw_scm_step,
        f"RoverMazeEnv batch {args.batch}, step_and_maybe_reset": torchrl_env,
    }
    rates: dict[str, list[float]] = {name: [] for name in rows}
    for _ in range(args.rounds):
        for name, measure in rows.items():
            rates[name].append(measure(env, actions))
    baseline = statistics.median(rates["bare rover physics (baseline)"])
    print(f"batch {args.batch}, {args.steps} steps x {args.rounds} rounds, torch threads {args.threads}")
    print("| row | env steps/s | ratio |\n| --- | ---: | ---: |")
    for name, values in rates.items():
        rate = statistics.median(values)
        print(f"| {name} | {rate:,.0f} | {rate / baseline:.2f} |")
    if args.expert:
        print("\n| maze | episodes | expert success | mean successful length | range |\n| --- | ---: | ---: | ---: | ---: |")
        for maze in ("u", "medium", "large"):
            print(expert_report(maze, args.expert))


if __name__ == "__main__":
    main()
