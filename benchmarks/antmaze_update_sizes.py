"""SQIL updates per CPU-second on the AntMaze window input, by network size, against the
paper's 256 x 3 in the same run: why ``scale=cpu_ant`` uses 128 x 2 networks.

    OMP_NUM_THREADS=1 python benchmarks/antmaze_update_sizes.py

The input is Confounded AntMaze's causal window at k = 10 (355 dims: 25 state dims at
lags 0..10, W excluded, 8 action dims at lags 1..10); the batch, the losses and the update step are
``gpu_throughput.py``'s. Each figure is the median over rounds; the ratio is against
256 x 3 within each round.
"""

from __future__ import annotations

import argparse
import statistics

import torch

from gpu_throughput import make_batch, make_update, timed_rate

ANTMAZE_WINDOW_DIM = 25 * 11 + 8 * 10
SIZES = ((256, 3), (128, 2), (64, 2))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--updates", type=int, default=20)
    parser.add_argument("--rounds", type=int, default=3)
    args = parser.parse_args()
    torch.set_num_threads(1)
    cpu, generator = torch.device("cpu"), torch.Generator().manual_seed(0)
    updates = {size: make_update("SQILLoss", cpu, False, observation_dim=ANTMAZE_WINDOW_DIM, hidden=size[0],
                                 num_blocks=size[1]) for size in SIZES}
    batches = [make_batch(cpu, generator, ANTMAZE_WINDOW_DIM) for _ in range(args.updates)]
    for update in updates.values():
        timed_rate(update, batches[:3], cpu, "cpu")  # warm-up
    rates = {size: [] for size in SIZES}
    for _ in range(args.rounds):
        for size, update in updates.items():
            rates[size].append(timed_rate(update, batches, cpu, "cpu"))
    print(f"SQIL updates per CPU-second, {ANTMAZE_WINDOW_DIM}-dim input, batch 256, 1 thread, {args.rounds} rounds")
    print("| networks | updates/s | ratio vs 256 x 3 | hours for 100k updates |")
    print("|---|---|---|---|")
    for size in SIZES:
        rate = statistics.median(rates[size])
        ratio = statistics.median(r / base for r, base in zip(rates[size], rates[SIZES[0]]))
        print(f"| {size[0]} x {size[1]} | {rate:.1f} | {ratio:.2f} | {100_000 / rate / 3600:.1f} |")


if __name__ == "__main__":
    main()
