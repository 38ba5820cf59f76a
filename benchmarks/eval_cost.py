"""CPU time of an evaluation that steps every env vs one that stops simulating ended episodes.

Opens a run directory (a trained policy, or an expert row), builds its evaluation env as
``python -m torchrl_causal.evaluate`` does, and runs the same episodes (same env seed) with
:func:`~torchrl_causal.evaluation.evaluate_policy` twice per repeat, alternating
``skip_finished=False`` (every env stepped until the round's last episode ends, the former
loop) and ``skip_finished=True`` (ended episodes not simulated). Each evaluation is timed by
this process's CPU time (``time.process_time``: what the other jobs on a shared machine do not
inflate as they do the wall clock), imports and the policy's loading left out; the per-episode
records of both are checked equal (success, return, length, trajectory), exactly.

Usage:
    python benchmarks/eval_cost.py --run-dir <run> [--regime deploy] [--episodes 50]
        [--num-envs <the run's eval.num_envs>] [--seed 30000] [--repeats 2]
"""

from __future__ import annotations

import time

import torch

from torchrl_causal.cli.arguments import OneLineParser, count, non_negative
from torchrl_causal.evaluation.metrics import evaluate_policy
from torchrl_causal.experiment.device import for_cpu_env
from torchrl_causal.experiment.provenance import cpu_model
from torchrl_causal.lifecycle import open_run


def main() -> None:
    parser = OneLineParser(description=__doc__.splitlines()[0])
    parser.add_argument("--run-dir", required=True)
    parser.add_argument("--regime", default="deploy")
    parser.add_argument("--episodes", type=count, default=50)
    parser.add_argument("--num-envs", type=count, default=None)
    parser.add_argument("--seed", type=non_negative, default=30_000)
    parser.add_argument("--repeats", type=count, default=2)
    args = parser.parse_args()
    torch.set_num_threads(1)
    _, evaluator, policy = open_run(args.run_dir)
    cfg = evaluator.cfg
    num_envs = min(args.num_envs or cfg.eval.num_envs, args.episodes)
    times: dict[bool, list[float]] = {False: [], True: []}
    records = {}
    for _ in range(args.repeats):
        for skip in (False, True):
            env = evaluator.make_env(args.regime, num_envs, args.seed)
            acting = evaluator.acting_policy(policy, env)
            if isinstance(acting, torch.nn.Module):
                acting.eval()
            start = time.process_time()
            result = evaluate_policy(
                env,
                for_cpu_env(acting),
                episodes=args.episodes,
                max_steps=cfg.env.horizon,
                regime=args.regime,
                position_key=cfg.env.position_key,
                trajectories=args.episodes,
                skip_finished=skip,
            )
            times[skip].append(time.process_time() - start)
            env.close()
            record = (result.successes, result.returns, result.lengths, [list(map(list, p)) for p in result.trajectories])
            if records.setdefault(skip, record) != record:
                raise AssertionError("an evaluation did not repeat itself")
    identical = records[False] == records[True]
    live = sum(result.lengths)
    best = {skip: min(values) for skip, values in times.items()}
    print(f"CPU: {cpu_model()}; torch threads 1")
    print(f"run {args.run_dir} [{args.regime}] {args.episodes} episodes, {num_envs} envs, seed {args.seed}")
    print(f"success {100 * result.success_rate:.1f}%, live env steps {live} of {args.episodes * cfg.env.horizon} at most")
    print(f"every env stepped:     CPU s {', '.join(f'{t:.2f}' for t in times[False])} (best {best[False]:.2f})")
    print(f"ended episodes skipped: CPU s {', '.join(f'{t:.2f}' for t in times[True])} (best {best[True]:.2f})")
    print(f"ratio (best) {best[True] / best[False]:.3f}: {100 * (1 - best[True] / best[False]):.1f}% less CPU time")
    print(f"per-episode records identical: {identical}")
    if not identical:
        raise SystemExit(1)


if __name__ == "__main__":
    main()
