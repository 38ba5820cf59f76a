"""What the first joint soft-Q updates do to a warm-started actor: variants from one snapshot.

Builds an off-policy run of ``--overrides`` (by default C-SQIL with
``+recipe=goal_valued_bc_anchored`` on AntMaze-Medium), runs its warm start (behaviour
cloning, the warm-up steps collected by the cloned actor, the critic fit) and snapshots
actor, critics, targets, alpha and the optimisers. Each variant then restarts from that
snapshot, runs ``--updates`` joint updates on the warm-up's replay buffer (no new data: the
actor alone moves), and reports the train-regime success of the deterministic actor over
``--episodes`` episodes and how far its deterministic actions moved from the snapshot's
(RMS over the expert and the policy rows of fixed batches, dropout off). The baseline is
``critics_only`` (the snapshot's own actor); the ratio column is each variant's success over it.

    OMP_NUM_THREADS=1 python benchmarks/warm_start_dip.py \\
        --demos runs/recipe/_demos/antmaze_medium-h1000-cs1.0-n200-s0 --run-root /tmp/dip

Variants: ``critics_only`` (the actor held), ``anchor_actor_loss`` (the anchor scaled by
``|loss_actor|``: the recipe, ``algo.loss.bc_scale=actor_loss``), ``anchor_expert_value``
(scaled by the constant ``r_E / (1 - gamma)``: holds the cloned actor here, but a full run ends
lower, results/antmaze_medium_recipe.md), ``anchor_expert_value_x6`` (weight 2.5 instead of
0.4), ``no_anchor``, ``actor_lr_div10`` (the recipe with the actor's learning rate / 10),
``no_goal_value`` (the recipe with the goal worth 0, the paper's objective, from the same
snapshot) and ``critic_fit_x5`` (the recipe after 20000 more critic-only updates: is the dip the
critics' distance from the goal-valued fixed point, which 5000 updates do not close?).
"""

from __future__ import annotations

import copy
import time
from typing import NamedTuple

import torch
from torchrl.envs.utils import ExplorationType, set_exploration_type

from torchrl_causal.cli.arguments import OneLineParser, count
from torchrl_causal.evaluation.evaluator import Evaluator
from torchrl_causal.experiment.builders import make_window
from torchrl_causal.experiment.config import compose_config
from torchrl_causal.experiment.run_directory import RunDirectory
from torchrl_causal.objectives.utils import eval_mode
from torchrl_causal.trainers.off_policy import OffPolicyILTrainer

DEFAULT_OVERRIDES = ["env=antmaze_medium", "+row=c_sqil", "scale=cpu_ant", "+recipe=goal_valued_bc_anchored"]


class Variant(NamedTuple):
    bc_weight: float | None
    bc_scale: str
    actor_lr_factor: float = 1.0
    actor_moves: bool = True
    goal_value: str | None = "expert"
    extra_critic_updates: int = 0  # critic-only updates before the joint ones


VARIANTS = {
    "critics_only": Variant(0.4, "expert_value", actor_moves=False),
    "anchor_actor_loss": Variant(0.4, "actor_loss"),
    "anchor_expert_value": Variant(0.4, "expert_value"),
    "anchor_expert_value_x6": Variant(2.5, "expert_value"),
    "no_anchor": Variant(None, "expert_value"),
    "actor_lr_div10": Variant(0.4, "actor_loss", actor_lr_factor=0.1),
    "no_goal_value": Variant(0.4, "actor_loss", goal_value=None),
    "critic_fit_x5": Variant(0.4, "actor_loss", extra_critic_updates=20_000),
}


def deterministic_actions(trainer: OffPolicyILTrainer, batches: list) -> list[torch.Tensor]:
    with torch.no_grad(), eval_mode(trainer.policy), set_exploration_type(ExplorationType.DETERMINISTIC):
        return [trainer.policy(batch.select(*trainer.policy.in_keys).clone())["action"] for batch in batches]


def main() -> None:
    parser = OneLineParser(description=__doc__.splitlines()[0])
    parser.add_argument("--demos", required=True, help="a collected demonstrations folder (demos.path)")
    parser.add_argument("--run-root", required=True, help="a scratch folder for the replay buffer")
    parser.add_argument("--overrides", nargs="*", default=DEFAULT_OVERRIDES)
    parser.add_argument("--updates", type=count, default=500)
    parser.add_argument("--episodes", type=count, default=20)
    parser.add_argument("--variants", nargs="+", default=list(VARIANTS), choices=list(VARIANTS))
    args = parser.parse_args()
    torch.set_num_threads(1)
    torch.manual_seed(0)
    cfg = compose_config([*args.overrides, f"demos.path={args.demos}", f"run_root={args.run_root}", "progress_bar=false"])
    if not cfg.algo.get("warm_start"):
        parser.error("the overrides need algo.warm_start (e.g. +recipe=goal_valued_bc_anchored)")
    window = make_window(cfg)
    evaluator = Evaluator(cfg, window)
    trainer = OffPolicyILTrainer(cfg, RunDirectory(cfg.run_dir), window, evaluator.periodic)
    trainer.setup()
    start = time.perf_counter()
    while trainer.update.updates == 0:  # behaviour cloning, warm-up steps, critic fit, first updates
        trainer.train_step()
    print(
        f"{' '.join(args.overrides)}: warm start done in {time.perf_counter() - start:.0f} s "
        f"({trainer.progress} env steps, {trainer.update.updates} joint updates)",
        flush=True,
    )
    loss, update = trainer.loss, trainer.update
    snapshot = copy.deepcopy(loss.state_dict()), copy.deepcopy(update.state_dict())
    fixed = [trainer.sample_batch() for _ in range(20)]
    reference = deterministic_actions(trainer, fixed)
    rows = [(batch["expert"].squeeze(-1), ~batch["expert"].squeeze(-1)) for batch in fixed]
    print(f"| variant | success ({args.episodes} episodes) | / critics_only | action move, expert rows (RMS) | policy rows | seconds |")
    print("|---|---|---|---|---|---|")
    baseline = None
    for name in args.variants:
        variant = VARIANTS[name]
        loss.load_state_dict(snapshot[0])
        update.load_state_dict(snapshot[1])
        loss.bc_weight, loss.bc_scale, loss.goal_value = variant.bc_weight, variant.bc_scale, variant.goal_value
        for group in update.actor_optimizer.param_groups:
            group["lr"] *= variant.actor_lr_factor
        torch.manual_seed(1)
        start = time.perf_counter()
        for _ in range(variant.extra_critic_updates):
            update.critic_step(trainer.sample_batch())
        for _ in range(args.updates):
            (update if variant.actor_moves else update.critic_step)(trainer.sample_batch())
        seconds = time.perf_counter() - start
        moved = [(now - before).pow(2).mean(-1).sqrt() for now, before in zip(deterministic_actions(trainer, fixed), reference)]
        expert_move = torch.cat([m[e] for m, (e, _) in zip(moved, rows)]).mean().item()
        policy_move = torch.cat([m[p] for m, (_, p) in zip(moved, rows)]).mean().item()
        success = evaluator.evaluate(trainer.policy, "train", args.episodes, 123).success_rate
        baseline = success if name == "critics_only" else baseline
        ratio = f"{success / baseline:.2f}" if baseline else "n/a"
        print(f"| {name} | {100 * success:.0f}% | {ratio} | {expert_move:.3f} | {policy_move:.3f} | {seconds:.0f} |", flush=True)
    trainer.close()


if __name__ == "__main__":
    main()
