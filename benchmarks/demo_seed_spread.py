"""How much the demo's figures and claim margins move with the seed (issue 41, item 6).

Runs ``make demo``'s five runs (the same overrides, :data:`torchrl_causal.cli.demo.DEMO_RUNS`)
once per ``--seeds`` seed, each seed in its own run root, ``--workers`` runs at a time, then
prints per seed the deploy / train success of every row and each claim check's margin (the
measured value minus the threshold, in points; negative fails), and the spread over seeds.

    OMP_NUM_THREADS=1 python benchmarks/demo_seed_spread.py --root /tmp/demo_seeds --seeds 0 1 2 3
"""

from __future__ import annotations

import argparse
import statistics
from pathlib import Path

from torchrl_causal.cli.demo import DEMO_RUNS, demo_overrides
from torchrl_causal.evaluation import aggregate, load_runs
from torchrl_causal.evaluation.metrics import EvaluationResult
from torchrl_causal.evaluation.tables import EffectTargets
from torchrl_causal.experiment import compose_config
from torchrl_causal.experiment.interrupts import run_in_processes
from torchrl_causal.lifecycle import run


def run_overrides(overrides: list[str]) -> int:
    run(compose_config(overrides))
    return 0


def claim_margins(table: dict[str, dict[str, EvaluationResult]],
                  targets: EffectTargets = EffectTargets()) -> dict[str, float]:
    """Each of :func:`~torchrl_causal.evaluation.tables.effect_checks`' claims on ``table`` as a
    margin in points: how far the measured value is on the passing side of its threshold."""
    def rate(label: str, regime: str) -> float | None:
        result = table.get(label, {}).get(regime)
        return None if result is None else 100 * result.success_rate

    margins, expert = {}, rate("expert", "deploy")
    for label in ("c_sqil", "c_iq_learn"):
        if expert is not None and rate(label, "deploy") is not None:
            margins[f"{label} deploy >= {targets.causal_fraction:.0%} of expert"] = (
                rate(label, "deploy") - targets.causal_fraction * expert)
    for label in ("bc", "gail", "sqil", "iq_learn"):
        if expert is not None and rate(label, "deploy") is not None:
            margins[f"{label} deploy <= {targets.non_causal_fraction:.0%} of expert"] = (
                targets.non_causal_fraction * expert - rate(label, "deploy"))
        if rate(label, "train") is not None and rate(f"c_{label}", "train") is not None:
            margins[f"{label} within {targets.train_gap_points:g} points of c_{label} (train)"] = (
                targets.train_gap_points - abs(rate(label, "train") - rate(f"c_{label}", "train")))
    return margins


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--root", required=True, type=Path)
    parser.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2, 3])
    parser.add_argument("--workers", type=int, default=2)
    args = parser.parse_args()
    jobs = [[*demo_overrides(algo, causal, args.root / f"seed{seed}"), f"seed={seed}"]
            for seed in args.seeds for algo, causal in DEMO_RUNS if algo == "expert"]
    run_in_processes(run_overrides, jobs, args.workers)  # the experts first: their demonstrations feed the rest
    jobs = [[*demo_overrides(algo, causal, args.root / f"seed{seed}"), f"seed={seed}"]
            for seed in args.seeds for algo, causal in DEMO_RUNS if algo != "expert"]
    if any(run_in_processes(run_overrides, jobs, args.workers)):
        raise SystemExit("a run failed or was interrupted; rerun the same command to resume")
    margins: dict[str, list[float]] = {}
    print("| seed | row | train success % | deploy success % |\n|---|---|---|---|")
    for seed in args.seeds:
        for setting, table in aggregate(load_runs(args.root / f"seed{seed}")).items():
            for label, row in table.items():
                print(f"| {seed} | {label} | {100 * row['train'].success_rate:.1f} | "
                      f"{100 * row['deploy'].success_rate:.1f} |")
            for claim, margin in claim_margins(table).items():
                margins.setdefault(claim, []).append(margin)
    print("\n| claim | margin per seed (points) | min | mean |\n|---|---|---|---|")
    for claim, values in margins.items():
        print(f"| {claim} | {', '.join(f'{v:+.1f}' for v in values)} | {min(values):+.1f} "
              f"| {statistics.mean(values):+.1f} |")


if __name__ == "__main__":
    main()
