"""Env steps per wall second of the humanoid skill's PPO training, collected in 1 and in N processes.

Issue 56, item 5: with two free cores, ``--collector-workers 2`` should train at >= 1.3x the env
steps per wall second of one process (the update is the same in both). Each worker count runs
the real trainer (:func:`~torchrl_causal.experts.locomotion_ppo.train_locomotion_ppo`, one torch
thread in this process as the skill commands run) in a fresh temporary run directory, for
``--batches`` batches; the clock reads at each batch's bookkeeping, so the rate is over the
batches after the first (no worker start-up, no first-batch warm-up, no final evaluation).
The two counts alternate ``--repeats`` times; the median rate of each is reported with the ratio,
the CPU model and the load average, which says whether the cores were free: a ratio measured
on busy cores says nothing about the target.

    OMP_NUM_THREADS=1 python benchmarks/ppo_collector.py                     # the trainer's defaults: 64 envs x 64 steps
    OMP_NUM_THREADS=1 python benchmarks/ppo_collector.py --num-envs 8 --rollout-steps 16 --batches 3 --repeats 1
"""

from __future__ import annotations

import json
import os
import statistics
import tempfile
import time
from dataclasses import replace
from pathlib import Path

import torch

from torchrl_causal.command_line import OneLineParser, count
from torchrl_causal.experts.locomotion_ppo import PPOLocomotionConfig, train_locomotion_ppo
from torchrl_causal.experts.skill_run import SkillLoop


def cpu_model() -> str:
    """The CPU's model name as the kernel reports it (``platform.processor()`` is empty on Linux)."""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return "unknown"


def steps_per_second(config: PPOLocomotionConfig) -> float:
    """Env steps per wall second of ``config``'s run between its first and its last batch."""
    stamps: list[tuple[float, int]] = []
    after_batch = SkillLoop.after_batch

    def clocked(self, steps, *args, **kwargs):
        stamps.append((time.perf_counter(), steps))  # before any evaluation this batch triggers
        return after_batch(self, steps, *args, **kwargs)

    SkillLoop.after_batch = clocked
    try:
        with tempfile.TemporaryDirectory() as folder:
            train_locomotion_ppo(Path(folder) / "run", config, progress_bar=False)
    finally:
        SkillLoop.after_batch = after_batch
    (start, first), (end, last) = stamps[0], stamps[-1]
    return (last - first) / (end - start)


def main() -> None:
    parser = OneLineParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--workers", type=count, default=2, help="the process count compared with one (default 2)")
    parser.add_argument("--num-envs", type=count, default=PPOLocomotionConfig.num_envs)
    parser.add_argument("--rollout-steps", type=count, default=PPOLocomotionConfig.rollout_steps)
    parser.add_argument("--batches", type=count, default=8, help="batches per timed run (the first is not timed; >= 2)")
    parser.add_argument("--repeats", type=count, default=2, help="alternations of the two counts")
    args = parser.parse_args()
    if args.batches < 2:
        parser.error("--batches must be >= 2 (the rate is over the batches after the first)")
    torch.set_num_threads(1)
    frames = args.num_envs * args.rollout_steps
    base = PPOLocomotionConfig(
        num_envs=args.num_envs,
        rollout_steps=args.rollout_steps,
        minibatch_size=min(PPOLocomotionConfig.minibatch_size, frames),
        total_steps=args.batches * frames,
        eval_every=10 * args.batches * frames,  # only the final evaluation, after the last reading
        eval_envs=1,
        eval_steps=1,
    )
    rates: dict[int, list[float]] = {1: [], args.workers: []}
    for _ in range(args.repeats):
        for workers in rates:
            rates[workers].append(steps_per_second(replace(base, collector_workers=workers)))
    one, many = (statistics.median(rates[w]) for w in rates)
    print(
        json.dumps(
            {
                "cpu": cpu_model(),
                "cores": os.cpu_count(),
                "load_average_1_5_15": [round(x, 2) for x in os.getloadavg()],
                "frames_per_batch": frames,
                "timed_batches": args.batches - 1,
                "steps_per_s": {str(w): [round(r, 1) for r in rs] for w, rs in rates.items()},
                f"ratio_{args.workers}_vs_1": round(many / one, 3),
            },
            indent=2,
        )
    )


if __name__ == "__main__":
    main()
