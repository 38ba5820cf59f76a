"""How well a trained GAIL run's discriminator tells expert from policy transitions.

Loads a GAIL run's last (or best) checkpoint, collects two rounds with its policy, and
scores the discriminator on the second round and on expert rows set aside: accuracy at
logit 0, the two-sided binary cross-entropy (2 ln 2 = 1.386 at chance) and the mean
logit on each side. Then it trains the discriminator on the first round and the
other expert rows (the trainer's own loss, fresh Adam moments; in memory only) and scores it again
after each of ``--steps`` (``--lr``, by default the run's initial discriminator
learning rate): the baseline is the discriminator the run left, the ratio is how many
times further below chance its BCE falls. A discriminator far
from what a few more steps reach on fixed data is undertrained, and its reward
(its logit) is mostly noise to PPO.

    python benchmarks/gail_discriminator_probe.py runs/table3/rovermaze_medium/h1000-cs1.0-k10/gail/seed0

Nothing is written to the run directory.
"""

from __future__ import annotations

import math

import torch
import torch.nn.functional as F
from hydra.utils import get_class
from tensordict import TensorDictBase

from torchrl_causal.cli.arguments import OneLineParser, count, non_negative, positive_number
from torchrl_causal.experiment import RunDirectory
from torchrl_causal.experiment.builders import TRANSITION_KEYS, make_window
from torchrl_causal.objectives import GAILDiscriminatorLoss, gail_discriminator_batch
from torchrl_causal.objectives.utils import eval_mode
from torchrl_causal.trainers import GAILTrainer

CHANCE_BCE = 2 * math.log(2)


def draw(rows: TensorDictBase, size: int, generator: torch.Generator) -> TensorDictBase:
    return rows[torch.randint(rows.numel(), (size,), generator=generator)]


@torch.no_grad()
def score(loss: GAILDiscriminatorLoss, expert: TensorDictBase, policy: TensorDictBase) -> dict[str, float]:
    """Accuracy, BCE and mean logits of ``loss``'s discriminator on equally many expert and policy rows."""
    network = loss.discriminator_network
    logits_key = loss.tensor_keys.discriminator_pred
    with eval_mode(network):
        expert_logits = network(expert.clone()).get(logits_key)
        policy_logits = network(policy.clone()).get(logits_key)
    bce = F.binary_cross_entropy_with_logits(expert_logits, torch.ones_like(expert_logits)) + F.binary_cross_entropy_with_logits(
        policy_logits, torch.zeros_like(policy_logits)
    )
    accuracy = ((expert_logits > 0).float().mean() + (policy_logits < 0).float().mean()) / 2
    return {
        "accuracy": accuracy.item(),
        "bce": bce.item(),
        "expert_logit": expert_logits.mean().item(),
        "policy_logit": policy_logits.mean().item(),
    }


def main() -> None:
    parser = OneLineParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("run_dir")
    parser.add_argument("--checkpoint", choices=("last", "best"), default="last")
    parser.add_argument("--steps", type=count, nargs="+", default=[2, 16, 50, 200])
    parser.add_argument("--lr", type=positive_number, default=None, help="defaults to algo.discriminator_optimizer.lr")
    parser.add_argument("--eval-rows", type=count, default=4096)
    parser.add_argument("--seed", type=non_negative, default=0)
    args = parser.parse_args()
    torch.set_num_threads(1)
    run = RunDirectory(args.run_dir)
    cfg = run.read_config()
    trainer_class = get_class(cfg.algo.trainer)
    if not issubclass(trainer_class, GAILTrainer):
        raise SystemExit(f"error: {args.run_dir} is a {cfg.algo.name} run, not GAIL")
    state = run.load_checkpoint(best=args.checkpoint == "best")
    if state is None:
        raise SystemExit(f"error: {args.run_dir} has no {args.checkpoint} checkpoint")
    trainer = trainer_class(cfg, run, make_window(cfg), lambda policy: None)
    trainer.setup()
    trainer.load_state_dict(state)
    rounds = [trainer.discriminator_rows(next(trainer.rollouts).reshape(-1).select(*TRANSITION_KEYS)) for _ in range(2)]
    generator = torch.Generator().manual_seed(args.seed)
    expert_order = torch.randperm(trainer.expert.numel(), generator=generator)
    expert_train = trainer.expert[expert_order[args.eval_rows :]]
    held_out = (trainer.expert[expert_order[: args.eval_rows]], draw(rounds[1], args.eval_rows, generator))
    print(
        f"{args.run_dir} ({args.checkpoint} checkpoint, {trainer.progress} rounds): "
        f"{trainer.expert.numel()} expert rows, {rounds[0].numel()} policy rows per round; "
        f"chance BCE {CHANCE_BCE:.3f}"
    )

    def report(label: str, result: dict[str, float], baseline: dict[str, float]) -> None:
        ratio = (CHANCE_BCE - result["bce"]) / max(CHANCE_BCE - baseline["bce"], 1e-9)
        print(
            f"{label:>22}: accuracy {100 * result['accuracy']:5.1f}%  BCE {result['bce']:.3f}  "
            f"logit expert {result['expert_logit']:+.2f} policy {result['policy_logit']:+.2f}  "
            f"separation from chance {ratio:.1f}x the run's"
        )

    baseline = score(trainer.losses.discriminator, *held_out)
    report("as the run left it", baseline, baseline)
    loss = trainer.losses.discriminator
    lr = args.lr if args.lr is not None else float(cfg.algo.discriminator_optimizer.lr)
    run_lr = trainer.discriminator_optimizer.param_groups[0]["lr"]
    print(f"training on the first round's rows, lr {lr:g} (the run's was {run_lr:g} at the checkpoint)")
    optimizer = torch.optim.Adam(loss.parameters(), lr=lr)
    batch_size = int(cfg.algo.discriminator_batch_size)
    for step in range(1, max(args.steps) + 1):
        batch = gail_discriminator_batch(loss, draw(expert_train, batch_size, generator), draw(rounds[0], batch_size, generator))
        optimizer.zero_grad(set_to_none=True)
        loss(batch)["loss"].backward()
        optimizer.step()
        if step in args.steps:
            report(f"+{step} steps", score(loss, *held_out), baseline)
    trainer.close()


if __name__ == "__main__":
    main()
