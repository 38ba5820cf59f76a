"""The humanoid walking skill on open ground, per spread of commanded directions, side by side.

The maze turns the humanoid by up to 90 degrees at a corner and starts it facing a uniform
direction, while its observation (OGBench's) holds no yaw: a body that walks fast straight ahead
but not on uniform commands does not get round the maze. This prints, for each body given,
deterministic rollouts on four command spreads (straight ahead, within pi/4, within pi/2,
uniform: the skill's own task), speed along the command (m/s) / fraction of envs that fell, as
one markdown row per body, and each body's uniform speed as a ratio of the first body's::

    OMP_NUM_THREADS=1 python benchmarks/skill_directions.py --weights A/best_body.pt B/best_body.pt --envs 32

Each spread is ``evaluate_locomotion(body, skill="humanoid", envs=N, steps=400,
env_options={"command_spread": s})`` (the same simulations for every body: one seed). About
30 s per body (four spreads) at 32 envs on one core of a 2-core AMD EPYC.
"""

from __future__ import annotations

import math
import time
from pathlib import Path

import torch

from torchrl_causal.cli.arguments import OneLineParser, count
from torchrl_causal.experts.locomotion import evaluate_locomotion
from torchrl_causal.experts.skills import load_humanoid_locomotion_network

SPREADS: dict[str, float] = {"straight ahead": 0.0, "within pi/4": math.pi / 4, "within pi/2": math.pi / 2, "uniform": math.pi}


def main(argv: list[str] | None = None) -> None:
    parser = OneLineParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--weights", type=Path, nargs="+", required=True, help="skill bodies (state dicts) to compare")
    parser.add_argument("--envs", type=count, default=32, help="simulations per spread")
    parser.add_argument("--steps", type=count, default=400, help="control steps per simulation (40 Hz)")
    args = parser.parse_args(argv)
    missing = [str(path) for path in args.weights if not path.is_file()]
    if missing:
        parser.error(f"no such weights file: {', '.join(missing)}")
    if args.envs < 1 or args.steps < 1:
        parser.error(f"--envs and --steps must be positive, got {args.envs} and {args.steps}")
    torch.set_num_threads(1)

    print(f"| body | {' | '.join(SPREADS)} | uniform speed / first body's | wall time |")
    print(f"|---|{'---|' * len(SPREADS)}---|---|")
    first_uniform: float | None = None
    for path in args.weights:
        body = load_humanoid_locomotion_network(path)  # a command-frame body comes with its frame
        start = time.perf_counter()
        cells, uniform = [], 0.0
        for spread in SPREADS.values():
            result = evaluate_locomotion(
                body,
                skill="humanoid",
                envs=args.envs,
                steps=args.steps,
                env_options={"command_spread": spread},  # the reward's weights do not change a deterministic rollout
            )
            cells.append(f"{result['speed']:.2f} / {result['fall_rate']:.0%}")
            uniform = result["speed"]
        first_uniform = uniform if first_uniform is None else first_uniform
        ratio = uniform / first_uniform if first_uniform > 0 else float("nan")
        print(f"| {path} | {' | '.join(cells)} | {ratio:.2f} | {time.perf_counter() - start:.0f} s |", flush=True)


if __name__ == "__main__":
    main()
