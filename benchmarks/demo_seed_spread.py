"""How much the demo's figures and claim margins move with the seed (issue 41, item 6).

Runs ``make demo``'s five runs (the same overrides, :data:`torchrl_causal.cli.demo.DEMO_RUNS`)
once per ``--seeds`` seed with ``seed=S demos.seed=S`` (a machine with another CPU draws other
demonstrations and other training draws, so both move), each seed in its own run root, ``--workers`` runs at a time, then
prints per seed the deploy / train success of every row and each claim check's margin (the
measured value minus the threshold, in points; negative fails), and the spread over seeds.

    OMP_NUM_THREADS=1 python benchmarks/demo_seed_spread.py --root /tmp/demo_seeds --seeds 0 1 2 3
"""

from __future__ import annotations

import statistics
from pathlib import Path

from torchrl_causal.cli.arguments import OneLineParser, count, non_negative
from torchrl_causal.cli.demo import DEMO_RUNS, demo_overrides
from torchrl_causal.evaluation import aggregate, effect_checks, load_runs
from torchrl_causal.experiment import compose_config
from torchrl_causal.experiment.interrupts import run_in_processes
from torchrl_causal.lifecycle import run


def run_overrides(overrides: list[str]) -> int:
    run(compose_config(overrides))
    return 0


def main() -> None:
    parser = OneLineParser(description=__doc__.splitlines()[0])
    parser.add_argument("--root", required=True, type=Path)
    parser.add_argument("--seeds", type=non_negative, nargs="+", default=[0, 1, 2, 3])
    parser.add_argument("--workers", type=count, default=2)
    args = parser.parse_args()
    jobs = [
        [*demo_overrides(algo, causal, args.root / f"seed{seed}"), f"seed={seed}", f"demos.seed={seed}"]
        for seed in args.seeds
        for algo, causal in DEMO_RUNS
        if algo == "expert"
    ]
    run_in_processes(run_overrides, jobs, args.workers)  # the experts first: their demonstrations feed the rest
    jobs = [
        [*demo_overrides(algo, causal, args.root / f"seed{seed}"), f"seed={seed}", f"demos.seed={seed}"]
        for seed in args.seeds
        for algo, causal in DEMO_RUNS
        if algo != "expert"
    ]
    if any(run_in_processes(run_overrides, jobs, args.workers)):
        raise SystemExit("a run failed or was interrupted; rerun the same command to resume")
    margins: dict[str, list[float]] = {}
    print("| seed | row | train success % | deploy success % |\n|---|---|---|---|")
    for seed in args.seeds:
        for setting, table in aggregate(load_runs(args.root / f"seed{seed}")).items():
            for label, row in table.items():
                print(f"| {seed} | {label} | {100 * row['train'].success_rate:.1f} | {100 * row['deploy'].success_rate:.1f} |")
            for check in effect_checks(table):
                margins.setdefault(check.claim, []).append(check.margin)
    print("\n| claim | margin per seed (points) | min | mean |\n|---|---|---|---|")
    for claim, values in margins.items():
        print(f"| {claim} | {', '.join(f'{v:+.1f}' for v in values)} | {min(values):+.1f} | {statistics.mean(values):+.1f} |")


if __name__ == "__main__":
    main()
