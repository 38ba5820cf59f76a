"""GAIL's behaviour-cloned start (``+recipe=gail_bc_start``) against closed forms and the trainer's promises.

* Maximum-likelihood cloning of a tanh-Gaussian actor on observation-independent actions
  reaches the closed-form solution: pre-tanh mean and standard deviation of ``atanh(a)``.
* The trainer clones before its first rollout, holds the actor (only the critic and the
  discriminator learn) for ``critic_rounds`` rounds, then lets PPO move it, and never
  clones again once progress is made (a resumed run).
* The recipe composes beside the paper-faithful config, which keeps the random start.
"""

from __future__ import annotations

from pathlib import Path

import pytest
import torch
from tensordict import TensorDict
from test_trainers import build_trainer, tiny_config
from torchrl.data import Bounded

from torchrl_causal.experiment import compose_config, validate_config
from torchrl_causal.modules import make_tanh_gaussian_actor
from torchrl_causal.objectives.utils import gaussian_nll, interior_actions
from torchrl_causal.trainers.warm_start import behaviour_clone

pytestmark = pytest.mark.filterwarnings("ignore::UserWarning")


def test_cloning_reaches_the_closed_form_maximum_likelihood_tanh_gaussian() -> None:
    # Actions a = tanh(u), u ~ N(mu, sigma) per dimension, whatever the observation: the
    # maximum-likelihood tanh-Gaussian has pre-tanh mean and (population) standard
    # deviation those of atanh(a), because tanh's Jacobian does not depend on them.
    torch.manual_seed(0)
    spec = Bounded(-1.0, 1.0, shape=(2,))
    mu, sigma, n = torch.tensor([0.4, -0.8]), torch.tensor([0.3, 0.6]), 512
    actions = torch.tanh(mu + sigma * torch.randn(n, 2))
    pre_tanh = torch.atanh(actions)
    mu_hat, sigma_hat = pre_tanh.mean(0), pre_tanh.std(0, unbiased=False)
    # Its NLL in closed form: Gaussian NLL of atanh(a) plus log|d tanh / du| = log(1 - a^2).
    gaussian = torch.distributions.Normal(mu_hat, sigma_hat).log_prob(pre_tanh)
    best_nll = -(gaussian - torch.log1p(-actions.pow(2))).sum(-1).mean()

    actor = make_tanh_gaussian_actor(3, spec, hidden=8, num_blocks=1, dropout=0.0)
    rows = TensorDict({"observation": torch.zeros(n, 3)}, [n])  # one state: the ML solution is exact
    weights = torch.full((n, 1), 1.0 / n)
    behaviour_clone(
        lambda: gaussian_nll(actor, rows, interior_actions(spec, actions), weights),
        torch.optim.Adam(actor.parameters(), lr=2e-2),
        updates=600,
        max_grad_norm=10.0,
    )
    with torch.no_grad():
        out = actor(rows[:1].clone())
        nll = gaussian_nll(actor, rows, actions, weights)
    torch.testing.assert_close(out["scale"][0], sigma_hat, atol=0.01, rtol=0.02)
    # At the optimum: no tanh-Gaussian explains the actions better (the mean is fitted too).
    assert best_nll.item() - 1e-3 <= nll.item() <= best_nll.item() + 5e-3


def _expert_nll(trainer) -> float:
    with torch.no_grad():
        return trainer.expert_nll(trainer.expert).item()


def _flat(params) -> list[torch.Tensor]:
    return [p.detach().clone() for p in params.flatten_keys().values()]


def test_the_warm_start_clones_then_holds_the_actor_for_its_critic_rounds(tmp_path: Path, caplog) -> None:
    cfg = tiny_config(
        tmp_path,
        "rovermaze_u",
        "gail",
        True,
        "+recipe=gail_bc_start",
        "algo.warm_start.bc_updates=40",
        "algo.warm_start.critic_rounds=1",
        "algo.rounds=3",
        "demos.successful_only=false",  # the tiny horizon's demonstrations never reach the goal
    )
    trainer = build_trainer(cfg)
    trainer.setup()
    ppo = trainer.losses.policy
    try:
        before = _expert_nll(trainer)
        cloned: dict[str, list[torch.Tensor]] = {}
        clone = trainer.clone_expert_actions

        def spy() -> None:
            clone()
            cloned["actor"] = _flat(ppo.actor_network_params)
            cloned["critic"] = _flat(ppo.critic_network_params)

        trainer.clone_expert_actions = spy
        with caplog.at_level("INFO"):
            trainer.train_step()  # clone, then a critic round: the actor stays as cloned
        assert "behaviour cloning 40/40" in caplog.text
        assert _expert_nll(trainer) < before - 0.1  # the cloned actor explains the expert's actions better
        assert all(torch.equal(a, b) for a, b in zip(cloned["actor"], _flat(ppo.actor_network_params)))
        assert not all(torch.equal(a, b) for a, b in zip(cloned["critic"], _flat(ppo.critic_network_params)))
        held = _flat(ppo.actor_network_params)
        trainer.train_step()  # round 2: PPO moves the actor; no second cloning
        assert caplog.text.count("behaviour cloning 40/40") == 1
        assert not all(torch.equal(a, b) for a, b in zip(held, _flat(ppo.actor_network_params)))
    finally:
        trainer.close()


def test_the_paper_faithful_config_keeps_its_random_start_and_the_recipe_ablates_line_by_line() -> None:
    paper = compose_config(["env=antmaze_medium", "+row=c_gail", "scale=cpu_ant"])
    recipe = compose_config(["env=antmaze_medium", "+row=c_gail", "scale=cpu_ant", "+recipe=gail_bc_start"])
    validate_config(recipe)
    assert paper.algo.get("warm_start") is None and not paper.demos.successful_only
    assert recipe.algo.warm_start.bc_updates > 0 and recipe.algo.warm_start.critic_rounds > 0 and recipe.demos.successful_only
    # Everything else is the paper-faithful config's.
    for key in ("loss", "actor", "discriminator", "rounds", "episodes_per_round", "discriminator_epochs"):
        assert recipe.algo[key] == paper.algo[key], key
    ablated = compose_config(["env=antmaze_medium", "+row=c_gail", "scale=cpu_ant", "+recipe=gail_bc_start", "algo.warm_start=null"])
    assert ablated.algo.warm_start is None and ablated.demos.successful_only


def test_a_warm_start_refuses_negative_counts() -> None:
    from torchrl_causal.experiment import ConfigValueError

    with pytest.raises(ConfigValueError, match="bc_updates"):
        validate_config(compose_config(["algo=gail", "+recipe=gail_bc_start", "algo.warm_start.bc_updates=-1"]))
