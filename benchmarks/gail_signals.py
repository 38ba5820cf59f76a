"""GAIL's training signals, round by round, for a few rounds of a fresh run (no run directory kept).

Builds a GAIL trainer from the config that ``overrides`` compose (``key=value`` as for
``torchrl_causal.train``), runs ``--rounds`` rounds of its own ``train_step`` and prints,
per round, what tells a learning GAIL from a stuck one:

* ``succ``: the share of the round's finished episodes that reached the goal (the
  stochastic policy that collects, not the evaluation's deterministic one);
* ``D acc`` / ``logit E, pi``: the discriminator's balanced accuracy at logit 0 and its
  mean logit on fresh expert rows and on the round's policy rows, after its update;
* ``r mean, std``: the reward PPO reads (the discriminator's, ``algo.loss.reward``);
* ``|g| actor, critic``: gradient norms of the actor's and the critic's loss on the
  round's first PPO minibatch, before the joint clipping at ``algo.max_grad_norm``
  (a critic norm far above it shrinks every actor step with it);
* ``scale``: the actor's mean pre-tanh standard deviation; ``KL``: the mean
  ``log pi_old(a) - log pi_new(a)`` over the round's actions after the PPO epochs;
* ``BC nll``: the actor's mean negative log-likelihood of the expert's actions.

    python benchmarks/gail_signals.py --rounds 5 env=antmaze_medium +row=c_gail scale=cpu_ant \\
        algo.episodes_per_round=4 demos.episodes=30 [+recipe=gail_bc_start]

It writes only the demonstrations (under ``run_root``, as a run would) and a scratch run
directory in a fresh temporary folder that it removes.
"""

from __future__ import annotations

import tempfile
import time

import torch
from gail_discriminator_probe import score
from hydra.utils import get_class
from tensordict import TensorDictBase

from torchrl_causal.cli.arguments import OneLineParser, count
from torchrl_causal.evaluation.evaluator import Evaluator
from torchrl_causal.experiment import RunDirectory, compose_config
from torchrl_causal.experiment.builders import make_window
from torchrl_causal.trainers import GAILTrainer


def grad_norm(loss: torch.Tensor, params: list[torch.Tensor]) -> float:
    grads = torch.autograd.grad(loss, params, retain_graph=True, allow_unused=True)
    return torch.sqrt(sum((g.pow(2).sum() for g in grads if g is not None), torch.zeros(()))).item()


def main() -> None:
    parser = OneLineParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("overrides", nargs="*")
    parser.add_argument("--rounds", type=count, default=5)
    args = parser.parse_args()
    torch.set_num_threads(1)
    cfg = compose_config([*args.overrides, "progress_bar=false"])
    # A fresh temporary folder, never a fixed name under run_root: a user's folder of that name
    # would be deleted.
    scratch = tempfile.TemporaryDirectory(prefix="gail_signals_")
    cfg.run_dir = scratch.name
    window = make_window(cfg)
    trainer = get_class(cfg.algo.trainer)(cfg, RunDirectory(cfg.run_dir), window, Evaluator(cfg, window).periodic)
    assert isinstance(trainer, GAILTrainer), f"{cfg.algo.name} is not GAIL"
    trainer.setup()
    seen: dict[str, TensorDictBase] = {}
    update_discriminator, update_policy = trainer._update_discriminator, trainer._update_policy
    ppo = trainer.losses.policy
    actor_params = list(ppo.actor_network_params.flatten_keys().values())
    critic_params = list(ppo.critic_network_params.flatten_keys().values())

    def spy_discriminator(rows: TensorDictBase) -> torch.Tensor:
        seen["policy_rows"] = rows
        return update_discriminator(rows)

    def spy_policy(rollout: TensorDictBase) -> dict[str, torch.Tensor]:
        seen["rollout"] = rollout
        out = ppo(rollout[: cfg.algo.batch_size].clone())
        seen["g_actor"] = grad_norm(out["loss_objective"] + out["loss_entropy"], actor_params)
        seen["g_critic"] = grad_norm(out["loss_critic"], critic_params)
        return update_policy(rollout)

    trainer._update_discriminator, trainer._update_policy = spy_discriminator, spy_policy
    expert_nll = trainer.expert[torch.randperm(trainer.expert.numel(), generator=torch.Generator().manual_seed(1))[:4096]]

    def bc_nll() -> float:
        with torch.no_grad():
            dist = ppo.actor_network.get_dist(expert_nll.select(*ppo.actor_network.in_keys, strict=False))
            low, high = -1 + 1e-3, 1 - 1e-3  # the mazes' torques are in [-1, 1]
            return -dist.log_prob(expert_nll["action"].clamp(low, high)).mean().item()

    print(f"config: {' '.join(args.overrides)}; {trainer.expert.numel()} expert rows")
    print("round  succ  D acc  logit E, pi    r mean, std  |g| actor, critic  scale   KL      BC nll  s")
    for _ in range(args.rounds):
        start = time.perf_counter()
        trainer.train_step()
        rollout = seen["rollout"]
        done, success = rollout["next", "done"].sum().item(), rollout["next", "terminated"].sum().item()
        d = score(trainer.losses.discriminator, trainer._sample(trainer.expert, 4096), trainer._sample(seen["policy_rows"], 4096))
        with torch.no_grad():
            new = ppo.actor_network.get_dist(rollout.select(*ppo.actor_network.in_keys)).log_prob(rollout["action"])
            kl = (rollout["action_log_prob"] - new).mean().item()
            scale = ppo.actor_network(rollout[:1].select(*ppo.actor_network.in_keys).clone())["scale"].mean().item()
        reward = rollout["next", "reward"]
        print(
            f"{trainer.progress:5d} {success:2d}/{done:<3d} {100 * d['accuracy']:5.1f}  {d['expert_logit']:+6.2f} {d['policy_logit']:+6.2f}"
            f"  {reward.mean().item():+6.2f} {reward.std().item():5.2f}  {seen['g_actor']:8.3f} {seen['g_critic']:8.2f}"
            f"  {scale:5.3f}  {kl:+.4f}  {bc_nll():6.2f}  {time.perf_counter() - start:4.0f}",
            flush=True,
        )
    trainer.close()
    scratch.cleanup()


if __name__ == "__main__":
    main()
