"""What a training run costs, part by part, and how far its update is from the matmul floor.

    cd benchmarks && OMP_NUM_THREADS=1 python run_cost.py [--steps 16000] [HYDRA OVERRIDES...]

1. **A short real run, in this process.** The training command (by default the AntMaze-Medium
   C-SQIL recipe, ``env=antmaze_medium +row=c_sqil scale=cpu_ant +recipe=goal_valued_bc_anchored
   compile=true``, compiled as the long runs are) runs through :func:`torchrl_causal.lifecycle.run` with
   ``algo.total_steps=--steps``, a smaller warm start and fewer evaluation episodes, under a
   :class:`~torchrl_causal.experiment.timing.PartTimer`: the trainer's own parts (setup, warm
   start, compile, updates, replay sampling, collection, evaluation, checkpoints) in CPU
   seconds, each exclusive of the parts inside it. Each part is then projected to the full
   budget (``--full-steps``, the recipe's warm start, its evaluations) by what it scales with:
   the warm start by its updates, compile and setup once, updates and sampling by their
   count, evaluation by its episodes, the rest by env steps.
2. **The matmul floor, in the same process.** One thread's best ``torch.mm`` rate in fp32 and
   in bf16 (1024-square, the peak), and the matmul FLOPs of one update of the run's networks
   (the profiler's count over its forward and backward): the floor is FLOPs / peak, the
   share is floor / measured time.
3. **The update before and after, in the same process.** The recipe's update, eager, with
   the anchor's separate actor pass (``bc_separate_pass=True``, as before issue 56) and with
   the one pass, in fp32 and bf16: alternating rounds, medians, ratios of per-round medians.

CPU time (:func:`~torchrl_causal.experiment.timing.cpu_seconds`) is what a shared machine's
other jobs do not inflate much; the share of the floor is still lower on a loaded machine
(caches and memory bandwidth are shared). ``TORCHINDUCTOR_COMPILE_THREADS=1`` keeps the
compilation in this process, where it is counted.
"""

from __future__ import annotations

import os

from torchrl_causal.cli.arguments import OneLineParser, count

os.environ.setdefault("TORCHINDUCTOR_COMPILE_THREADS", "1")  # before torch: compile in-process, where it is timed

import math
import statistics
import tempfile
import time

import torch
from gpu_throughput import make_batch, make_update
from torch.profiler import ProfilerActivity, profile

from torchrl_causal.experiment import compose_config
from torchrl_causal.experiment.builders import make_imitator_env, make_window, observation_dim
from torchrl_causal.experiment.device import resolve_precision
from torchrl_causal.experiment.provenance import cpu_model
from torchrl_causal.experiment.timing import OTHER, PartTimer, cpu_seconds
from torchrl_causal.lifecycle import run

# compile=true as every long run passes it: scale=cpu_ant alone leaves the update eager.
RECIPE = ["env=antmaze_medium", "+row=c_sqil", "scale=cpu_ant", "+recipe=goal_valued_bc_anchored", "compile=true"]
PARTS = (
    "setup",
    "warm start (BC)",
    "warm start (critics)",
    "compile",
    "updates",
    "replay sampling",
    "collection",
    "evaluation",
    "checkpoints",
    OTHER,
)
PEAK_SIZE = 1024


def matmul_peak(dtype: torch.dtype, seconds: float = 2.0) -> float:
    """One thread's ``torch.mm`` rate at :data:`PEAK_SIZE` squared, FLOP per CPU second."""
    a, b = (torch.randn(PEAK_SIZE, PEAK_SIZE).to(dtype) for _ in range(2))
    torch.mm(a, b)
    count, start = 0, cpu_seconds()
    while cpu_seconds() - start < seconds:
        torch.mm(a, b)
        count += 1
    return 2 * PEAK_SIZE**3 * count / (cpu_seconds() - start)


def update_flops(update, batch) -> int:
    """Matmul FLOPs of one update (forward and backward), counted by the profiler from the
    shapes of the matmuls it runs (``with_flops``; torch's FlopCounterMode cannot track
    TensorDict modules)."""
    with profile(activities=[ProfilerActivity.CPU], with_flops=True) as profiler:
        update(batch.clone())
    return int(sum(event.flops for event in profiler.key_averages()))


def update_seconds(variants: dict, batches: list, rounds: int) -> dict[str, float]:
    """Median CPU seconds per update of each variant, over alternating rounds."""
    for update in variants.values():
        for batch in batches[:3]:
            update(batch)  # warm-up
    times: dict[str, list[float]] = {name: [] for name in variants}
    for round_ in range(rounds):
        names = list(variants)
        for name in names[round_ % len(names) :] + names[: round_ % len(names)]:
            start = cpu_seconds()
            for batch in batches:
                variants[name](batch)
            times[name].append((cpu_seconds() - start) / len(batches))
    return {name: statistics.median(values) for name, values in times.items()}


def full_run_counts(cfg, total_steps: int, bc_updates: int, critic_updates: int) -> dict[str, float]:
    """What each part of a run of ``total_steps`` env steps scales with."""
    algo = cfg.algo
    updates = max(0, math.floor(algo.utd_ratio * (total_steps - algo.random_steps)))
    evaluations = total_steps // algo.eval_every + (total_steps % algo.eval_every != 0)
    return {
        "setup": 1,
        "compile": 1,
        "warm start (BC)": bc_updates,
        "warm start (critics)": critic_updates,
        "updates": updates,
        "replay sampling": updates + critic_updates,
        "evaluation": evaluations * cfg.eval.episodes + 2 * cfg.eval.final_episodes,
        "collection": total_steps,
        "checkpoints": total_steps,
        OTHER: total_steps,
    }


def main() -> None:
    parser = OneLineParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=count, default=16_000, help="env steps of the short run")
    parser.add_argument("--full-steps", type=count, default=400_000, help="the budget projected to")
    parser.add_argument("--bc-updates", type=count, default=2000, help="the short run's warm start: behaviour-cloning updates")
    parser.add_argument("--critic-updates", type=count, default=500, help="the short run's warm start: critic updates")
    parser.add_argument("--eval-episodes", type=count, default=10, help="the short run's periodic and final evaluation episodes")
    parser.add_argument("--eval-every", type=count, default=8000)
    parser.add_argument("--updates", type=count, default=20, help="updates per round of the before/after comparison")
    parser.add_argument("--rounds", type=count, default=5)
    parser.add_argument("--skip-run", action="store_true", help="only the floor and the before/after comparison")
    parser.add_argument("overrides", nargs="*", help="the training command's overrides (default: the AntMaze-Medium C-SQIL recipe)")
    args = parser.parse_args()
    torch.set_num_threads(1)
    command = args.overrides or RECIPE
    full_cfg = compose_config(command)
    print(f"CPU: {cpu_model()}, {os.cpu_count()} cores; torch {torch.__version__}, 1 thread; command: {' '.join(command)}")

    if not args.skip_run:
        root = tempfile.mkdtemp(prefix="run_cost_")
        short = [
            *command,
            f"algo.total_steps={args.steps}",
            f"algo.eval_every={args.eval_every}",
            f"algo.warm_start.bc_updates={args.bc_updates}",
            f"algo.warm_start.critic_updates={args.critic_updates}",
            f"eval.episodes={args.eval_episodes}",
            f"eval.final_episodes={args.eval_episodes}",
            f"eval.num_envs={args.eval_episodes}",
            "eval.trajectories=0",
            "progress_bar=false",
            f"run_root={root}",
            "demos.path=" + str(full_cfg.demos.path),  # the recipe's demonstration set, collected once
        ]
        cfg = compose_config(short)
        timer = PartTimer()
        start = time.perf_counter()
        with timer.recording():
            run(cfg)
        wall = time.perf_counter() - start
        done = full_run_counts(cfg, args.steps, args.bc_updates, args.critic_updates)
        warm = full_cfg.algo.get("warm_start") or {}
        full = full_run_counts(full_cfg, args.full_steps, int(warm.get("bc_updates", 0)), int(warm.get("critic_updates", 0)))
        projected = {part: timer.cpu.get(part, 0.0) / done[part] * full[part] if done[part] else 0.0 for part in PARTS}
        total = sum(projected.values())
        print(
            f"\nShort run: {args.steps} env steps, {done['updates']} updates, {wall / 60:.1f} wall-min, {timer.total_cpu / 60:.1f} CPU-min"
        )
        print(f"| part | CPU s (short run) | calls | per unit | projected to {args.full_steps} steps, CPU-min | share |")
        print("|---|---|---|---|---|---|")
        for part in PARTS:
            seconds = timer.cpu.get(part, 0.0)
            unit = f"{1e3 * seconds / done[part]:.2f} ms" if done[part] else "-"
            share = projected[part] / total
            print(f"| {part} | {seconds:.1f} | {timer.calls.get(part, 0)} | {unit} | {projected[part] / 60:.1f} | {share:.0%} |")
        print(f"| total | {timer.total_cpu:.1f} | | | {total / 60:.1f} | 100% |")
        compiled_update = timer.cpu.get("updates", 0.0) / max(1, done["updates"])
    else:
        compiled_update = None

    # The run's networks and input, for the floor and the comparison.
    window = make_window(full_cfg)
    env = make_imitator_env(full_cfg, window, "train", 1, 0)
    obs_dim, action_dim = observation_dim(env), int(env.action_spec.shape[-1])
    env.close()
    sizes = dict(
        observation_dim=obs_dim, action_dim=action_dim, hidden=full_cfg.algo.actor.hidden, num_blocks=full_cfg.algo.actor.num_blocks
    )
    generator = torch.Generator().manual_seed(0)
    batches = [make_batch(torch.device("cpu"), generator, obs_dim, action_dim) for _ in range(args.updates)]
    name = "SQILLoss recipe"
    variants = {
        "two-pass anchor, fp32 (before)": make_update(name, torch.device("cpu"), False, bc_separate_pass=True, **sizes),
        "one-pass anchor, fp32": make_update(name, torch.device("cpu"), False, **sizes),
        "two-pass anchor, bf16": make_update(name, torch.device("cpu"), False, bc_separate_pass=True, precision="bf16", **sizes),
        "one-pass anchor, bf16 (after)": make_update(name, torch.device("cpu"), False, precision="bf16", **sizes),
    }
    flops = {variant: update_flops(update, batches[0]) for variant, update in variants.items()}
    peaks = {"fp32": matmul_peak(torch.float32), "bf16": matmul_peak(torch.bfloat16)}
    seconds = update_seconds(variants, batches, args.rounds)
    fp32, bf16 = peaks["fp32"] / 1e9, peaks["bf16"] / 1e9
    print(f"\nMatmul peak, one thread, {PEAK_SIZE}-square torch.mm: fp32 {fp32:.0f} GFLOP/s, bf16 {bf16:.0f} GFLOP/s")
    print(
        f"Updates: batch 256, {obs_dim}-dim input, {action_dim}-dim action, {sizes['hidden']} x {sizes['num_blocks']} networks, "
        f"eager, {args.rounds} alternating rounds of {args.updates}"
    )
    print("| update | matmul GFLOP | ms per update | floor, ms | share of the floor | speed vs before |")
    print("|---|---|---|---|---|---|")
    before = seconds["two-pass anchor, fp32 (before)"]
    for variant, value in seconds.items():
        floor = flops[variant] / peaks["bf16" if "bf16" in variant else "fp32"]
        gflop, share, speed = flops[variant] / 1e9, floor / value, before / value
        print(f"| {variant} | {gflop:.3f} | {1e3 * value:.2f} | {1e3 * floor:.2f} | {share:.0%} | {speed:.2f}x |")
    if compiled_update is not None:
        precision = resolve_precision(full_cfg.algo.get("precision"))
        floor = flops["one-pass anchor, fp32"] / peaks[precision]
        print(
            f"| the short run's update (compiled, {precision}, one-pass, sampling aside) | {flops['one-pass anchor, fp32'] / 1e9:.3f} | "
            f"{1e3 * compiled_update:.2f} | {1e3 * floor:.2f} | {floor / compiled_update:.0%} | {before / compiled_update:.2f}x |"
        )


if __name__ == "__main__":
    main()
