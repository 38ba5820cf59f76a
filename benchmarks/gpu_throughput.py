"""Paper-size gradient updates per second on the CPU and on CUDA in one run, with ratios,
and env steps per second of a batched AntMaze collector with the policy on each device.

Updates: one update is the off-policy trainer's own step (:class:`ActorCriticUpdate`):
loss forward, one backward, gradient-norm clipping, three Adam steps (fused on CUDA), the
critic's cosine schedule and the Polyak target update, on the paper's networks (Appendix
E: width 256, 3 residual blocks, actor dropout 0.05; batch 256, half expert; a 128-dim
causal encoding and 8-dim actions as the ant's). Losses: TorchRL's ``SACLoss`` (the
baseline, ratio 1), ``SQILLoss``, ``IQLearnLoss`` with K = 16 and K = 1 samples of the
soft value. ``--compile-on cuda`` adds each loss with ``compile=True`` on the devices named
(the compilation itself is done during warm-up and not timed). Rounds interleave every variant of a device, rotating
the order; a figure is the median over rounds, a ratio the median of per-round ratios.
The CUDA-to-CPU ratio divides medians of the same variant. On CUDA the clock is wall
time with the device synchronised around each timed block; on the CPU ``--clock cpu``
(default) counts CPU time of the process, which a shared machine's other jobs do not
inflate, and ``--clock wall`` counts wall time.

Collector: TorchRL's :class:`~torchrl.collectors.Collector` (or ``MultiSyncCollector``
with ``--workers`` > 1) over the imitator's AntMaze-medium env (the causal window's
encoding, k = 10), ``--num-envs`` envs stepped in batch on the CPU, the paper's actor on
the device (``policy_device``), batches stored on the device (``storing_device``): what
the off-policy trainer runs. The figure is env steps per wall second over
``--collector-batches`` batches of ``--frames`` steps after one warm-up batch.

Commands (see results/gpu_throughput.md):

    OMP_NUM_THREADS=1 python benchmarks/gpu_throughput.py --devices cpu cuda --compile-on cuda
    OMP_NUM_THREADS=1 python benchmarks/gpu_throughput.py --part collector --devices cpu --workers 1 2
"""

from __future__ import annotations

import statistics
import tempfile
import time
import warnings
from collections.abc import Callable
from functools import partial

import torch
from tensordict import TensorDict
from torchrl.collectors import Collector, MultiSyncCollector
from torchrl.data import Bounded
from torchrl.objectives import SACLoss, SoftUpdate

from torchrl_causal.cli.arguments import OneLineParser, count, non_negative
from torchrl_causal.experiment import compose_config
from torchrl_causal.experiment.builders import make_imitator_env, make_policy, make_window
from torchrl_causal.experiment.device import CPU, resolve_device
from torchrl_causal.modules import make_qvalue_network, make_tanh_gaussian_actor
from torchrl_causal.objectives import ALPHA_CLAMP, IQLearnLoss, SQILLoss
from torchrl_causal.trainers.update import ActorCriticUpdate

OBSERVATION_DIM, ACTION_DIM, HIDDEN, BLOCKS, BATCH = 128, 8, 256, 3, 256
BASELINE = "SACLoss (TorchRL)"
LOSSES: dict[str, Callable] = {
    BASELINE: lambda actor, critic: SACLoss(actor, critic, loss_function="l2", min_alpha=ALPHA_CLAMP[0], max_alpha=ALPHA_CLAMP[1]),
    "SQILLoss": lambda actor, critic: SQILLoss(actor, critic),
    "IQLearnLoss K=16": lambda actor, critic: IQLearnLoss(actor, critic, num_value_samples=16),
    "IQLearnLoss K=1": lambda actor, critic: IQLearnLoss(actor, critic, num_value_samples=1),
    # +recipe=goal_valued_bc_anchored's loss options (the warm start runs before training).
    "SQILLoss recipe": lambda actor, critic, **options: SQILLoss(actor, critic, goal_value="expert", bc_weight=0.4, **options),
    "IQLearnLoss K=16 recipe": lambda actor, critic, **options: IQLearnLoss(
        actor, critic, num_value_samples=16, goal_value="expert", bc_weight=0.4, **options
    ),
}
TARGETS = {
    ("cuda", "SQILLoss"): ("updates/s", 300.0),
    ("cpu", "IQLearnLoss K=16"): ("ratio", 0.6),
    ("cuda", "IQLearnLoss K=16"): ("ratio", 0.9),
}


def make_batch(
    device: torch.device, generator: torch.Generator, observation_dim: int = OBSERVATION_DIM, action_dim: int = ACTION_DIM
) -> TensorDict:
    expert = (torch.arange(BATCH) < BATCH // 2).unsqueeze(-1)
    return TensorDict(
        {
            "observation": torch.randn(BATCH, observation_dim, generator=generator),
            "action": torch.rand(BATCH, action_dim, generator=generator) * 2 - 1,
            "expert": expert,
            "next": {
                "observation": torch.randn(BATCH, observation_dim, generator=generator),
                "reward": expert.float(),  # read by plain SACLoss only
                "done": torch.zeros(BATCH, 1, dtype=torch.bool),
                "terminated": torch.zeros(BATCH, 1, dtype=torch.bool),
            },
        },
        [BATCH],
    ).to(device)


def make_update(
    name: str,
    device: torch.device,
    compile: bool,
    *,
    observation_dim: int = OBSERVATION_DIM,
    hidden: int = HIDDEN,
    num_blocks: int = BLOCKS,
    action_dim: int = ACTION_DIM,
    precision: str = "fp32",
    **loss_options,
) -> ActorCriticUpdate:
    """``name``'s update (:data:`LOSSES`; the recipe losses take ``loss_options``, e.g.
    ``bc_separate_pass=True``), its matmuls in ``precision``."""
    torch.manual_seed(0)
    spec = Bounded(-1.0, 1.0, shape=(action_dim,))
    actor = make_tanh_gaussian_actor(observation_dim, spec, hidden=hidden, num_blocks=num_blocks, dropout=0.05)
    critic = make_qvalue_network(observation_dim, spec, hidden=hidden, num_blocks=num_blocks)
    loss = LOSSES[name](actor.to(device), critic.to(device), **loss_options)
    loss.make_value_estimator(gamma=0.99)
    adam = partial(torch.optim.Adam, lr=3e-4)
    return ActorCriticUpdate(
        loss.to(device),
        actor_optimizer=adam,
        critic_optimizer=adam,
        alpha_optimizer=adam,
        target_update=partial(SoftUpdate, tau=0.005),
        max_grad_norm=1.0,
        critic_scheduler=torch.optim.lr_scheduler.CosineAnnealingLR,
        cosine_updates=500_000,
        compile=compile,
        precision=precision,
    )


def timed_rate(update: ActorCriticUpdate, batches: list[TensorDict], device: torch.device, clock: str) -> float:
    synchronize = torch.cuda.synchronize if device.type == "cuda" else (lambda: None)
    now = time.process_time if clock == "cpu" and device.type == "cpu" else time.perf_counter
    synchronize()
    start = now()
    for batch in batches:
        update(batch)
    synchronize()
    return len(batches) / (now() - start)


def syncs_per_update(update: ActorCriticUpdate, batch: TensorDict, count: int = 5) -> float:
    """Host-device synchronisations per update on CUDA (``torch.cuda.set_sync_debug_mode``)."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        torch.cuda.set_sync_debug_mode("warn")
        try:
            for _ in range(count):
                update(batch)
        finally:
            torch.cuda.set_sync_debug_mode("default")
    return sum("synchronizing" in str(w.message) for w in caught) / count


def update_rates(
    device: torch.device, losses: list[str], compile: bool, rounds: int, per_round: int, warmup: int, clock: str
) -> dict[str, dict[str, float]]:
    generator = torch.Generator().manual_seed(0)
    batches = [make_batch(device, generator) for _ in range(per_round)]
    variants = [(name, False) for name in losses] + ([(name, True) for name in losses] if compile else [])
    updates = {}
    for name, compiled in variants:
        label = f"{name}{' compiled' if compiled else ''}"
        print(f"[{device}] building and warming up {label}", flush=True)
        updates[label] = make_update(name, device, compiled)
        for _ in range(warmup):  # the first calls of a compiled update compile it
            updates[label](batches[0])
    rates: dict[str, list[float]] = {label: [] for label in updates}
    labels = list(updates)
    for r in range(rounds):
        for label in labels[r % len(labels) :] + labels[: r % len(labels)]:
            rates[label].append(timed_rate(updates[label], batches, device, clock))
        print(
            f"[{device}] round {r + 1}/{rounds}: " + ", ".join(f"{label} {values[-1]:.1f}/s" for label, values in rates.items()), flush=True
        )
    baseline = rates[BASELINE]
    out = {
        label: {"rate": statistics.median(values), "ratio": statistics.median(v / b for v, b in zip(values, baseline))}
        for label, values in rates.items()
    }
    if device.type == "cuda":
        for label, update in updates.items():
            out[label]["syncs"] = syncs_per_update(update, batches[0])
    return out


def collector_rate(device: torch.device, workers: int, num_envs: int, frames: int, batches: int) -> float:
    """Env steps per wall second of the off-policy trainer's collector on AntMaze-medium."""
    with tempfile.TemporaryDirectory() as root:
        cfg = compose_config(
            [
                "env=antmaze_medium",
                "scale=paper",
                "algo=sqil",
                f"run_root={root}",
                f"algo.num_envs={num_envs}",
                f"collector_workers={workers}",
            ]
        )
        window = make_window(cfg)
        env = make_imitator_env(cfg, window, "train", num_envs // workers, 0)
        policy = make_policy(cfg, env).to(device)
        devices = dict(env_device=CPU, policy_device=device, storing_device=device)
        if workers == 1:
            collector = Collector(env, policy, frames_per_batch=frames, total_frames=-1, auto_register_policy_transforms=False, **devices)
        else:
            make = partial(make_imitator_env, cfg, window, "train", num_envs // workers, 0)
            collector = MultiSyncCollector(
                [make] * workers,
                policy,
                frames_per_batch=frames,
                total_frames=-1,
                cat_results="stack",
                auto_register_policy_transforms=False,
                **devices,
            )
        collector.set_seed(0)
        iterator = iter(collector)
        next(iterator)  # warm-up: worker start, first reset
        start = time.perf_counter()
        steps = sum(next(iterator).numel() for _ in range(batches))
        elapsed = time.perf_counter() - start
        collector.shutdown()
        env.close()
    return steps / elapsed


def print_updates(results: dict[str, dict[str, dict[str, float]]]) -> None:
    print(
        f"\n### Updates per second, paper networks (obs {OBSERVATION_DIM}, act {ACTION_DIM}, width {HIDDEN}, "
        f"{BLOCKS} blocks, batch {BATCH})\n"
    )
    devices = list(results)
    header = "| loss | " + " | ".join(f"{d} updates/s | {d} ratio vs SACLoss" for d in devices)
    if "cpu" in results and len(devices) > 1:
        header += " | " + " | ".join(f"{d} / cpu" for d in devices if d != "cpu")
    if "cuda" in results:
        header += " | cuda host syncs per update"
    print(header + " |")
    print("|---" * (header.count("|")) + "|")
    for label in results[devices[0]]:
        cells = []
        for device in devices:
            row = results[device].get(label)
            cells += ["—", "—"] if row is None else [f"{row['rate']:.1f}", f"{row['ratio']:.3f}"]
        if "cpu" in results and len(devices) > 1:
            cells += [
                f"{results[d][label]['rate'] / results['cpu'][label]['rate']:.1f}×"
                if label in results[d] and label in results["cpu"]
                else "—"
                for d in devices
                if d != "cpu"
            ]
        if "cuda" in results:
            cells.append(f"{results['cuda'][label]['syncs']:.1f}" if label in results["cuda"] else "—")
        print(f"| {label} | " + " | ".join(cells) + " |")
    print()
    for (device, label), (kind, target) in TARGETS.items():
        if device in results and label in results[device]:
            value = results[device][label]["rate" if kind == "updates/s" else "ratio"]
            print(f"- target {label} on {device}: {kind} ≥ {target:g}: {value:.3g} ({'met' if value >= target else 'MISSED'})")


def main() -> None:
    parser = OneLineParser(description=__doc__.splitlines()[0])
    parser.add_argument("--part", choices=["updates", "collector", "both"], default="both")
    parser.add_argument(
        "--devices", nargs="+", default=["cpu", "cuda"], help="devices to measure; one this machine lacks is reported as unmeasured"
    )
    parser.add_argument(
        "--compile-on", nargs="*", default=[], metavar="DEVICE", help="devices on which each loss is also timed with compile=True"
    )
    parser.add_argument(
        "--losses",
        nargs="+",
        choices=list(LOSSES),
        default=list(LOSSES),
        help=f"losses to time ({BASELINE!r}, the baseline, is always timed)",
    )
    parser.add_argument("--rounds", type=count, default=5)
    parser.add_argument("--updates", type=count, default=5, help="timed updates per variant per round (CPU)")
    parser.add_argument("--cuda-updates", type=count, default=200, help="timed updates per variant per round (CUDA)")
    parser.add_argument("--warmup", type=non_negative, default=3)
    parser.add_argument("--clock", choices=["cpu", "wall"], default="cpu", help="clock of the CPU half")
    parser.add_argument("--threads", type=count, default=1)
    parser.add_argument("--workers", type=count, nargs="+", default=[1], help="collector env processes")
    parser.add_argument("--num-envs", type=count, default=8)
    parser.add_argument("--frames", type=count, default=400, help="env steps per collector batch")
    parser.add_argument("--collector-batches", type=count, default=3)
    args = parser.parse_args()
    torch.set_num_threads(args.threads)
    warnings.filterwarnings("ignore", category=UserWarning)
    print(
        f"torch {torch.__version__}, threads {torch.get_num_threads()}, CUDA "
        f"{torch.cuda.get_device_name(0) if torch.cuda.is_available() else 'unavailable'}"
    )
    devices = {}
    for name in args.devices:
        try:
            devices[name] = resolve_device(name)
        except ValueError as err:
            print(f"- {name}: unmeasured ({err})")
    if args.part in ("updates", "both"):
        losses = [BASELINE, *(name for name in args.losses if name != BASELINE)]
        results = {
            name: update_rates(
                device,
                losses,
                name in args.compile_on,
                args.rounds,
                args.cuda_updates if device.type == "cuda" else args.updates,
                args.warmup,
                args.clock,
            )
            for name, device in devices.items()
        }
        if results:
            print_updates(results)
    if args.part in ("collector", "both"):
        print(f"\n### AntMaze-medium collector, {args.num_envs} envs, {args.frames} steps per batch, paper actor\n")
        print("| policy device | env processes | env steps/s | ratio vs cpu, 1 process |")
        print("|---|---|---|---|")
        baseline = None
        for name, device in devices.items():
            for workers in args.workers:
                rate = collector_rate(device, workers, args.num_envs, args.frames, args.collector_batches)
                baseline = rate if baseline is None and name == "cpu" and workers == 1 else baseline
                ratio = f"{rate / baseline:.2f}" if baseline else "—"
                print(f"| {name} | {workers} | {rate:.0f} | {ratio} |", flush=True)


if __name__ == "__main__":
    main()
