"""Steps per second of Confounded AntMaze beside the bare gymnasium-robotics AntMaze, in one run.

All rows step the same MuJoCo model (gymnasium's ant in the gymnasium-robotics medium maze,
5 RK4 physics steps of 0.01 s per control step) under pre-drawn uniform random actions,
resetting whenever an episode ends:

* ``gymnasium-robotics AntMaze_Medium-v5``: ``gymnasium.make`` (default wrappers) stepped in
  a plain Python loop: the baseline (ratio 1).
* ``TorchRL GymEnv(AntMaze_Medium-v5)``: the same env behind TorchRL's own wrapper, stepped
  like ours: what TorchRL's per-step TensorDict machinery costs by itself.
* ``AntMazeEnv batch B``: ours, stepped with ``step_and_maybe_reset`` (what a collector
  does); the gust process, its force, the compass and the reward are computed every step.
  Batch B steps B in-process MuJoCo simulations per call and counts B env steps.

Rounds alternate between the rows so that load from other processes hits all of them
alike; each row's figure is its median over rounds of per-env steps per second, measured
in CPU time of the process (``time.process_time``), and the ratio divides it by the
baseline's. ``torch.set_num_threads(1)``: every row is single-threaded.

Run: ``OMP_NUM_THREADS=1 python benchmarks/antmaze_speed.py [--steps 300] [--rounds 7] [--batch 1 16]``
"""

from __future__ import annotations

import statistics
import time
from collections.abc import Callable

import gymnasium
import gymnasium_robotics
import numpy as np
import torch
from torchrl.envs import EnvBase, GymEnv

from torchrl_causal.cli.arguments import OneLineParser, count
from torchrl_causal.envs import AntMazeEnv

BASELINE = "gymnasium-robotics AntMaze_Medium-v5"


def gymnasium_rate(env: gymnasium.Env, actions: np.ndarray) -> float:
    """Steps per CPU second of a gymnasium env under ``actions`` (``steps x 8``)."""
    start = time.process_time()
    for action in actions:
        _, _, terminated, truncated, _ = env.step(action)
        if terminated or truncated:
            env.reset()
    return len(actions) / (time.process_time() - start)


def torchrl_rate(env: EnvBase, actions: torch.Tensor) -> float:
    """Per-env steps per CPU second of a TorchRL env under ``actions`` (``steps x batch x 8``)."""
    td = env.reset()
    start = time.process_time()
    for action in actions:
        td["action"] = action.reshape(env.action_spec.shape)
        _, td = env.step_and_maybe_reset(td)
    return actions.shape[0] * actions.shape[1] / (time.process_time() - start)


def main() -> None:
    parser = OneLineParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=count, default=300, help="control steps per round (per env)")
    parser.add_argument("--rounds", type=count, default=7)
    parser.add_argument("--batch", type=count, nargs="+", default=[1, 16], help="batch sizes of AntMazeEnv")
    args = parser.parse_args()
    torch.set_num_threads(1)
    gymnasium.register_envs(gymnasium_robotics)
    rng = np.random.default_rng(0)

    bare = gymnasium.make("AntMaze_Medium-v5")
    bare.reset(seed=0)
    bare_actions = rng.uniform(-1, 1, (args.steps, 8))
    wrapped = GymEnv("AntMaze_Medium-v5")
    wrapped.set_seed(0)

    def actions(batch: int) -> torch.Tensor:
        return torch.from_numpy(rng.uniform(-1, 1, (args.steps, batch, 8)).astype(np.float32))

    rows: dict[str, Callable[[], float]] = {
        BASELINE: lambda: gymnasium_rate(bare, bare_actions),
        "TorchRL GymEnv(AntMaze_Medium-v5)": (lambda a=actions(1): torchrl_rate(wrapped, a)),
    }
    for batch in args.batch:
        env = AntMazeEnv("medium", batch_size=batch, seed=0)
        rows[f"AntMazeEnv batch {batch}"] = lambda env=env, a=actions(batch): torchrl_rate(env, a)

    for run in rows.values():  # warm-up: first-call allocations and caches
        run()
    rates: dict[str, list[float]] = {name: [] for name in rows}
    for _ in range(args.rounds):
        for name, run in rows.items():
            rates[name].append(run())

    reference = statistics.median(rates[BASELINE])
    print(f"{'env':36s} {'env steps/s (median)':>21s} {'ratio':>6s}")
    for name, values in rates.items():
        median = statistics.median(values)
        print(f"{name:36s} {median:21.0f} {median / reference:6.2f}")


if __name__ == "__main__":
    main()
