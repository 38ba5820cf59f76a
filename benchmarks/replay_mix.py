"""Sampling the expert/policy mix of an off-policy update: two buffers and ``torch.cat``
(what ``OffPolicyILTrainer.sample_batch`` does) against TorchRL's ``ReplayBufferEnsemble``
over the same two buffers, in one process, ratio printed.

The buffers are laid out as the trainer lays them out: the expert half in a
``LazyTensorStorage`` of demonstrations, the policy half in a ``LazyMemmapStorage``, each
transition a windowed observation (355 features, AntMaze at k = 10), an action, the next
observation, reward, done flags and the ``"expert"`` label; 128 + 128 transitions per batch.

Run (the figures in docs/design.md)::

    OMP_NUM_THREADS=1 python benchmarks/replay_mix.py
"""

from __future__ import annotations

import tempfile
import time

import torch
from tensordict import TensorDict
from torchrl.data import LazyMemmapStorage, LazyTensorStorage, ReplayBufferEnsemble, TensorDictReplayBuffer

from torchrl_causal.cli.arguments import OneLineParser, count


def transitions(n: int, expert: bool, features: int = 355, actions: int = 8) -> TensorDict:
    return TensorDict(
        {
            "observation": torch.randn(n, features),
            "action": torch.rand(n, actions) * 2 - 1,
            "expert": torch.full((n, 1), expert),
            "next": {"observation": torch.randn(n, features), "reward": torch.zeros(n, 1), "done": torch.zeros(n, 1, dtype=torch.bool)},
        },
        batch_size=[n],
    )


def timed(sample, reps: int) -> float:
    for _ in range(20):  # warm-up
        sample()
    start = time.perf_counter()
    for _ in range(reps):
        sample()
    return (time.perf_counter() - start) / reps


def main() -> None:
    parser = OneLineParser(description=__doc__.splitlines()[0])
    parser.add_argument("--reps", type=count, default=2000)
    parser.add_argument("--half", type=count, default=128)
    args = parser.parse_args()
    torch.manual_seed(0)
    with tempfile.TemporaryDirectory() as scratch:
        expert = TensorDictReplayBuffer(storage=LazyTensorStorage(20_000), batch_size=args.half)
        expert.extend(transitions(20_000, True))
        policy = TensorDictReplayBuffer(storage=LazyMemmapStorage(100_000, scratch_dir=scratch), batch_size=args.half)
        policy.extend(transitions(100_000, False))
        ensemble = ReplayBufferEnsemble(expert, policy, batch_size=2 * args.half, sample_from_all=True)
        batch = ensemble.sample()
        print(f"ensemble batch: {type(batch).__name__}, batch size {tuple(batch.batch_size)}, keys {sorted(batch.keys())}")
        two = timed(lambda: torch.cat([expert.sample(), policy.sample()], dim=0), args.reps)
        ens = timed(ensemble.sample, args.reps)
        # the ensemble's stacked batch made flat, as a loss reads it
        flat = timed(lambda: ensemble.sample().reshape(-1).to_tensordict(), args.reps)
    print(f"two buffers + torch.cat: {1e6 * two:.0f} us per batch of {2 * args.half}")
    print(f"ReplayBufferEnsemble.sample: {ens / two:.2f}x that ({1e6 * ens:.0f} us)")
    print(f"ReplayBufferEnsemble.sample, flattened to one TensorDict: {flat / two:.2f}x that ({1e6 * flat:.0f} us)")


if __name__ == "__main__":
    main()
