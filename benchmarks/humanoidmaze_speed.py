"""Steps of HumanoidMaze by the two routes the issue weighs, for ``farm-bench`` to time side by side.

* ``--route ours``: :class:`~torchrl_causal.envs.HumanoidMazeEnv` (OGBench's humanoid model in our
  batched simulator, the SCM layer on top: tremor force, vibration sensor, reward, TorchRL
  tensordicts), stepped with ``step_and_maybe_reset`` as a collector does.
* ``--route ogbench``: OGBench's own ``humanoidmaze-medium`` env, ``--batch`` of them stepped in a
  Python loop with the tremor written to ``xfrc_applied``: only what wrapping OGBench's env
  would cost before any SCM layer, so a lower bound of that route.

Both step ``--steps`` env steps in all (split over the batch) under uniform random actions.
Time the two whole processes with::

    farm-bench -n 5 -- python benchmarks/humanoidmaze_speed.py --route ours --batch 8 \\
        --vs 'python benchmarks/humanoidmaze_speed.py --route ogbench --batch 8'
"""

from __future__ import annotations

import time

import numpy as np
import torch

from torchrl_causal.cli.arguments import OneLineParser, count


def step_ours(batch: int, steps: int) -> float:
    """Seconds spent stepping (after the set-up)."""
    from torchrl_causal.envs import HumanoidMazeEnv

    env = HumanoidMazeEnv("medium", batch_size=batch, seed=0)
    generator = torch.Generator().manual_seed(0)
    td = env.reset()
    start = time.perf_counter()
    for _ in range(steps // batch):
        td["action"] = 2 * torch.rand(env.action_spec.shape, generator=generator) - 1
        _, td = env.step_and_maybe_reset(td)
    return time.perf_counter() - start


def step_ogbench(batch: int, steps: int) -> float:
    """Seconds spent stepping (after the set-up)."""
    import ogbench

    envs = [ogbench.make_env_and_datasets("humanoidmaze-medium-navigate-v0", env_only=True) for _ in range(batch)]
    rng = np.random.default_rng(0)
    torso = envs[0].unwrapped.model.body("torso").id
    for env in envs:
        env.reset(seed=0, options={"task_id": 1})
    start = time.perf_counter()
    for _ in range(steps // batch):
        for env in envs:
            env.unwrapped.data.xfrc_applied[torso, :2] = rng.uniform(-5, 5, 2) * (rng.random() < 0.05)
            _, _, terminated, truncated, _ = env.step(rng.uniform(-1, 1, 21))
            if terminated or truncated:
                env.reset(options={"task_id": 1})
    return time.perf_counter() - start


def main() -> None:
    parser = OneLineParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--route", choices=("ours", "ogbench"), required=True)
    parser.add_argument("--batch", type=count, default=8)
    parser.add_argument("--steps", type=count, default=16_000, help="env steps in all")
    args = parser.parse_args()
    torch.set_num_threads(1)
    stepping = (step_ours if args.route == "ours" else step_ogbench)(args.batch, args.steps)
    print(f"{args.route} batch {args.batch}: {args.steps / stepping:.0f} env steps/s (stepping only)")


if __name__ == "__main__":
    main()
