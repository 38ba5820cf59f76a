"""Gradient updates per second of SQILLoss and IQLearnLoss beside plain TorchRL SACLoss.

One "update" is what a trainer does per gradient step: loss forward, summed backward,
one Adam step over all loss parameters and one SoftUpdate of the target critics. All
variants share the same actor / critic architecture, batch and optimizer settings; plain
SACLoss gets the same critic loss ("l2") and alpha clamp so the ratio isolates what the
imitation losses add. IQ-Learn's K policy samples of V(z') go through the twin critics
as one batched pass of K * batch rows: TorchRL's vmap over the critics by default, a
loop over the two critics with ``deactivate_vmap=True`` (SACLoss's own switch, which
also loops SAC's other critic passes). Timings are interleaved (every variant, then the
next round, with the order rotated each round) and every ratio is the median over
rounds of (variant rate / SAC rate in the same round), which keeps the comparison fair
on a shared machine.

    python benchmarks/loss_throughput.py --config both --threads 1
"""

from __future__ import annotations

import argparse
import statistics
import time
import warnings
from dataclasses import dataclass

import torch
from tensordict import TensorDict
from torchrl.data import Bounded
from torchrl.objectives import SACLoss, SoftUpdate
from tqdm import tqdm

from torchrl_causal.cli.arguments import OneLineParser, count, non_negative
from torchrl_causal.modules import make_qvalue_network, make_tanh_gaussian_actor
from torchrl_causal.objectives import ALPHA_CLAMP, IQLearnLoss, SQILLoss


@dataclass(frozen=True)
class Config:
    name: str
    observation_dim: int
    action_dim: int
    hidden: int
    num_blocks: int
    batch: int
    updates: int  # timed updates per variant per round


CONFIGS = {
    # Paper's networks (Appendix E: width 256, 3 residual blocks, actor dropout 0.05) at
    # the paper's batch size 256; 8-dim actions as the ant, a 128-dim causal encoding.
    "paper": Config("paper", observation_dim=128, action_dim=8, hidden=256, num_blocks=3, batch=256, updates=5),
    "small": Config("small", observation_dim=16, action_dim=2, hidden=64, num_blocks=1, batch=64, updates=25),
    # scale=cpu_ant on Confounded AntMaze: the 355-dim causal window, 128 x 2 networks.
    "antmaze": Config("antmaze", observation_dim=355, action_dim=8, hidden=128, num_blocks=2, batch=256, updates=5),
}


class Materialised(torch.nn.Module):
    """Copies every input to its full size before the wrapped critic: the cost of the
    K-sample pass when the state is projected once per sample (the critics before the
    shared-input projection of ``ResidualMLP``)."""

    def __init__(self, body: torch.nn.Module) -> None:
        super().__init__()
        self.body = body

    def forward(self, *inputs: torch.Tensor) -> torch.Tensor:
        return self.body(*(t.contiguous() for t in inputs))


def materialised(make_loss):
    def make(actor, qvalue):
        qvalue.module = Materialised(qvalue.module)
        return make_loss(actor, qvalue)

    return make


CLOCKS = {"cpu": time.process_time, "wall": time.perf_counter}


def make_batch(config: Config, generator: torch.Generator) -> TensorDict:
    n = config.batch
    flags = torch.zeros(n, 1, dtype=torch.bool)
    flags[: n // 2] = True
    return TensorDict(
        {
            "observation": torch.randn(n, config.observation_dim, generator=generator),
            "action": torch.rand(n, config.action_dim, generator=generator) * 2 - 1,
            "expert": flags,
            "next": {
                "observation": torch.randn(n, config.observation_dim, generator=generator),
                "reward": flags.float(),  # read by plain SAC only
                "done": torch.zeros(n, 1, dtype=torch.bool),
                "terminated": torch.zeros(n, 1, dtype=torch.bool),
            },
        },
        [n],
    )


class Trainer:
    """One loss with its own copy of the networks, optimizer and target updater."""

    def __init__(self, name: str, make_loss, config: Config, seed: int) -> None:
        torch.manual_seed(seed)
        spec = Bounded(-1.0, 1.0, shape=(config.action_dim,))
        actor = make_tanh_gaussian_actor(config.observation_dim, spec, hidden=config.hidden, num_blocks=config.num_blocks, dropout=0.05)
        qvalue = make_qvalue_network(config.observation_dim, spec, hidden=config.hidden, num_blocks=config.num_blocks)
        self.name = name
        self.loss = make_loss(actor, qvalue)
        self.loss.make_value_estimator(gamma=0.99)
        self.optimizer = torch.optim.Adam(self.loss.parameters(), lr=3e-4)
        self.target_updater = SoftUpdate(self.loss, tau=0.005)

    def update(self, batch: TensorDict) -> None:
        out = self.loss(batch)
        self.optimizer.zero_grad(set_to_none=True)
        (out["loss_actor"] + out["loss_qvalue"] + out["loss_alpha"]).backward()
        self.optimizer.step()
        self.target_updater.step()

    def rate(self, batches: list[TensorDict], clock=time.process_time) -> float:
        start = clock()
        for batch in batches:
            self.update(batch)
        return len(batches) / (clock() - start)


def variants() -> dict[str, callable]:
    clamp = {"min_alpha": ALPHA_CLAMP[0], "max_alpha": ALPHA_CLAMP[1]}
    return {
        "SACLoss (TorchRL)": lambda a, q: SACLoss(a, q, loss_function="l2", **clamp),
        "SACLoss, deactivate_vmap": lambda a, q: SACLoss(a, q, loss_function="l2", deactivate_vmap=True, **clamp),
        "SQILLoss": lambda a, q: SQILLoss(a, q),
        "IQLearnLoss K=16": lambda a, q: IQLearnLoss(a, q, num_value_samples=16),
        "IQLearnLoss K=16, deactivate_vmap": lambda a, q: IQLearnLoss(a, q, num_value_samples=16, deactivate_vmap=True),
        "IQLearnLoss K=1": lambda a, q: IQLearnLoss(a, q, num_value_samples=1),
        "IQLearnLoss K=16, state copied per sample": materialised(lambda a, q: IQLearnLoss(a, q, num_value_samples=16)),
        "IQLearnLoss K=16, variant=iq_learn": lambda a, q: IQLearnLoss(a, q, num_value_samples=16, variant="iq_learn"),
    }


def run(config: Config, rounds: int, warmup: int, clock) -> list[tuple[str, float, float]]:
    updates = config.updates
    generator = torch.Generator().manual_seed(0)
    batches = [make_batch(config, generator) for _ in range(updates)]
    trainers = [Trainer(name, make, config, seed=0) for name, make in variants().items()]
    for trainer in trainers:
        trainer.rate(batches[:warmup])
    rates = {t.name: [] for t in trainers}
    for r in tqdm(range(rounds), desc=f"{config.name} rounds"):
        order = trainers[r % len(trainers) :] + trainers[: r % len(trainers)]
        for trainer in order:
            rates[trainer.name].append(trainer.rate(batches, clock))
    baseline = rates[trainers[0].name]
    return [
        (
            name,
            statistics.median(values),
            statistics.median(v / b for v, b in zip(values, baseline)),
        )
        for name, values in rates.items()
    ]


def main() -> None:
    parser = OneLineParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--config", choices=[*CONFIGS, "both", "all"], default="both", help="both: paper and small; all: every config")
    parser.add_argument("--threads", type=count, default=1, help="torch intra-op threads (default 1)")
    parser.add_argument("--rounds", type=count, default=7)
    parser.add_argument("--warmup", type=non_negative, default=3)
    parser.add_argument(
        "--clock",
        choices=list(CLOCKS),
        default="cpu",
        help="cpu: updates per CPU-second of this process (robust when other jobs share the cores); wall: wall-clock",
    )
    args = parser.parse_args()
    torch.set_num_threads(args.threads)
    warnings.filterwarnings("ignore", category=UserWarning)
    names = {"both": ["paper", "small"], "all": list(CONFIGS)}.get(args.config, [args.config])
    targets = {"SQILLoss": 0.95, "IQLearnLoss K=16": 0.6, "IQLearnLoss K=16, deactivate_vmap": 0.6}
    print(f"torch {torch.__version__}, threads={torch.get_num_threads()}, rounds={args.rounds}, clock={args.clock}")
    for name in names:
        config = CONFIGS[name]
        results = run(config, args.rounds, args.warmup, CLOCKS[args.clock])
        print(
            f"\n### {config.name}: obs {config.observation_dim}, act {config.action_dim}, width {config.hidden}, "
            f"blocks {config.num_blocks}, batch {config.batch}, {config.updates} updates/variant/round\n"
        )
        print("| loss | updates/s (median) | ratio vs SACLoss (median of per-round ratios) | target |")
        print("|---|---|---|---|")
        for variant, rate, ratio in results:
            target = targets.get(variant)
            verdict = "" if target is None else f"≥ {target} ({'met' if ratio >= target else 'MISSED'})"
            print(f"| {variant} | {rate:.1f} | {ratio:.3f} | {verdict} |")


if __name__ == "__main__":
    main()
