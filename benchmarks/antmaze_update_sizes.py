"""Off-policy updates per CPU-second on the AntMaze window input, by network size and
loss, eager and compiled: why ``scale=cpu_ant`` uses 128 x 2 networks and ``compile=true``.

    OMP_NUM_THREADS=1 python benchmarks/antmaze_update_sizes.py [--losses SQILLoss "IQLearnLoss K=16"] [--compile]

The input is Confounded AntMaze's causal window at k = 10 (355 dims: 25 state dims at
lags 0..10, W excluded, 8 action dims at lags 1..10); ``--observation-dim 64`` gives
RoverMaze's (P and L at lags 0..10, the action at 1..10). The batch, the losses and the
update step are ``gpu_throughput.py``'s.

Each loss and network size is measured in a fresh interpreter, as a training run has it:
one update per process (compiled state is process-wide, and several compiled updates in
one process slowed even the eager ones by up to 2x here). Within that process the eager
and, with ``--compile``, the compiled update alternate over ``--rounds`` rounds; the
compilation happens in a warm-up that is timed separately. A figure is the median over
rounds, the compiled / eager ratio the median of per-round ratios (one process, so the
machine's load affects both alike), and the ratio against the first size divides medians
of separate processes.
"""

from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys
import time

import torch
from gpu_throughput import LOSSES, make_batch, make_update, timed_rate

from torchrl_causal.cli.arguments import OneLineParser, count

ANTMAZE_WINDOW_DIM = 25 * 11 + 8 * 10
SIZES = ("256x3", "128x2", "64x2")


def measure(loss: str, size: str, observation_dim: int, compiled: bool, updates: int, rounds: int) -> dict:
    """Rates of one loss and size, eager (and compiled), in this process."""
    torch.set_num_threads(1)
    hidden, blocks = (int(x) for x in size.split("x"))
    cpu, generator = torch.device("cpu"), torch.Generator().manual_seed(0)
    batches = [make_batch(cpu, generator, observation_dim) for _ in range(updates)]
    variants = (False, True) if compiled else (False,)
    steps, warmup = {}, {}
    for variant in variants:
        steps[variant] = make_update(loss, cpu, variant, observation_dim=observation_dim, hidden=hidden, num_blocks=blocks)
        start = time.perf_counter()
        timed_rate(steps[variant], batches[:3], cpu, "cpu")  # compiles a compiled update
        warmup[variant] = time.perf_counter() - start
    rates = {variant: [] for variant in variants}
    for _ in range(rounds):
        for variant in variants:
            rates[variant].append(timed_rate(steps[variant], batches, cpu, "cpu"))
    return {
        "eager": statistics.median(rates[False]),
        "compiled": statistics.median(rates[True]) if compiled else None,
        "speedup": statistics.median(c / e for c, e in zip(rates[True], rates[False])) if compiled else None,
        "warmup": warmup.get(True),
    }


def main() -> None:
    parser = OneLineParser(description=__doc__.splitlines()[0])
    parser.add_argument("--updates", type=count, default=20)
    parser.add_argument("--rounds", type=count, default=3)
    parser.add_argument("--losses", nargs="+", default=["SQILLoss"], choices=sorted(LOSSES))
    parser.add_argument("--sizes", nargs="+", default=list(SIZES), help="WIDTHxBLOCKS; the first is the baseline")
    parser.add_argument("--observation-dim", type=count, default=ANTMAZE_WINDOW_DIM)
    parser.add_argument("--compile", action="store_true", help="also measure compile=True")
    parser.add_argument("--one", nargs=2, metavar=("LOSS", "SIZE"), help=argparse.SUPPRESS)  # the child process
    args = parser.parse_args()
    if args.one:
        print(json.dumps(measure(*args.one, args.observation_dim, args.compile, args.updates, args.rounds)))
        return
    results = {}
    for loss in args.losses:
        for size in args.sizes:
            print(f"measuring {loss} {size}", file=sys.stderr, flush=True)
            child = [
                sys.executable,
                __file__,
                "--one",
                loss,
                size,
                "--observation-dim",
                str(args.observation_dim),
                "--updates",
                str(args.updates),
                "--rounds",
                str(args.rounds),
            ] + (["--compile"] if args.compile else [])
            output = subprocess.run(child, check=True, capture_output=True, text=True).stdout
            results[loss, size] = json.loads(output.strip().splitlines()[-1])
    print(
        f"Updates per CPU-second, {args.observation_dim}-dim input, batch 256, 1 thread, one process per row, "
        f"{args.rounds} rounds of {args.updates} updates"
    )
    print(
        f"| loss | networks | eager updates/s | eager vs {args.sizes[0]} | compiled updates/s | compiled / eager "
        "| compiling (s) | hours for 100k updates, best |"
    )
    print("|---|---|---|---|---|---|---|---|")
    for (loss, size), r in results.items():
        base = results[loss, args.sizes[0]]["eager"]
        best = max(r["eager"], r["compiled"] or 0.0)
        compiled = f"{r['compiled']:.1f} | {r['speedup']:.2f} | {r['warmup']:.0f}" if r["compiled"] is not None else "— | — | —"
        print(
            f"| {loss} | {size.replace('x', ' x ')} | {r['eager']:.1f} | {r['eager'] / base:.2f} | {compiled} "
            f"| {100_000 / best / 3600:.1f} |"
        )


if __name__ == "__main__":
    main()
