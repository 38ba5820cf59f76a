"""What ``+recipe=goal_valued_bc_anchored`` costs per update: the plain loss against the
recipe's (goal value + behaviour-cloning anchor), same networks, one process, one thread.

    cd benchmarks && OMP_NUM_THREADS=1 python recipe_update_cost.py [--size 128x2] [--compile]

The two updates alternate over ``--rounds`` rounds in one process, so the machine's load
affects both alike; a figure is the median over rounds and the ratio the median of the
per-round ratios (recipe / plain: 1.0 is free; the issue's bound is >= 0.85). The
recipe's warm start (behaviour cloning, the critic fit) runs once before training and is
not an update cost. The batch and the update are ``gpu_throughput.py``'s, at AntMaze's
355-dim window.
"""

from __future__ import annotations

import statistics

import torch
from antmaze_update_sizes import ANTMAZE_WINDOW_DIM
from gpu_throughput import make_batch, make_update, timed_rate

from torchrl_causal.cli.arguments import OneLineParser, count

PAIRS = {"SQILLoss": "SQILLoss recipe", "IQLearnLoss K=16": "IQLearnLoss K=16 recipe"}


def main() -> None:
    parser = OneLineParser(description=__doc__.splitlines()[0])
    parser.add_argument("--updates", type=count, default=20)
    parser.add_argument("--rounds", type=count, default=5)
    parser.add_argument("--size", default="128x2", help="WIDTHxBLOCKS of actor and critics")
    parser.add_argument("--losses", nargs="+", default=list(PAIRS), choices=list(PAIRS))
    parser.add_argument("--compile", action="store_true")
    args = parser.parse_args()
    torch.set_num_threads(1)
    hidden, blocks = (int(x) for x in args.size.split("x"))
    cpu, generator = torch.device("cpu"), torch.Generator().manual_seed(0)
    batches = [make_batch(cpu, generator, ANTMAZE_WINDOW_DIM) for _ in range(args.updates)]
    print(
        f"Updates per CPU-second, {ANTMAZE_WINDOW_DIM}-dim input, batch 256, {args.size} networks, 1 thread, "
        f"{'compiled' if args.compile else 'eager'}, {args.rounds} alternating rounds of {args.updates} updates"
    )
    print("| loss | plain updates/s | recipe updates/s | recipe / plain |")
    print("|---|---|---|---|")
    for plain in args.losses:
        updates = {
            name: make_update(name, cpu, args.compile, observation_dim=ANTMAZE_WINDOW_DIM, hidden=hidden, num_blocks=blocks)
            for name in (plain, PAIRS[plain])
        }
        for update in updates.values():
            timed_rate(update, batches[:3], cpu, "cpu")  # warm-up (and compilation)
        rates = {name: [] for name in updates}
        for _ in range(args.rounds):
            for name, update in updates.items():
                rates[name].append(timed_rate(update, batches, cpu, "cpu"))
        ratio = statistics.median(r / p for r, p in zip(rates[PAIRS[plain]], rates[plain]))
        print(
            f"| {plain} | {statistics.median(rates[plain]):.1f} | {statistics.median(rates[PAIRS[plain]]):.1f} | {ratio:.2f} |", flush=True
        )


if __name__ == "__main__":
    main()
