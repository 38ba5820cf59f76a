"""The soft-Q fixes of ``+recipe=goal_valued_bc_anchored`` against closed forms and independent formulas.

The chain MDP: expert states 0..3 walk right, state 3 enters the goal (terminated); state 4
is a policy state that loops on itself; state 5 is a policy state that enters the goal.
With a tabular critic that ignores the action and an entropy coefficient of ~0, SQIL's
fixed point is the discounted sum of its labels, in closed form:

* goal worth zero (the paper): ``V_i = r_E (1 - gamma^(4 - i)) / (1 - gamma)``: the value
  falls as the expert nears the goal, so stopping one step short beats entering it;
* ``goal_value="expert"``: ``V_i = r_E / (1 - gamma)`` for every expert state, and a
  policy transition into the goal is worth ``gamma r_E / (1 - gamma)``;

and the paper's IQ-Learn critic is the same with ``r_E = 1/p`` (``p`` the batch's expert
fraction, here 4/6).
"""

from __future__ import annotations

import math

import pytest
import torch
from tensordict import TensorDict
from tensordict.nn import TensorDictModule
from tiny_runs import tiny
from torch import nn
from torchrl.data import Bounded
from torchrl.objectives import SoftUpdate

from torchrl_causal.modules import make_qvalue_network, make_tanh_gaussian_actor
from torchrl_causal.objectives import IQLearnLoss, SQILLoss, add_absorbing_transitions, eval_mode
from torchrl_causal.trainers.update import ActorCriticUpdate

pytestmark = pytest.mark.filterwarnings("ignore::UserWarning")

GAMMA, CHAIN, STATES = 0.8, 4, 7  # states 0..3 expert, 4 and 5 policy, 6 the goal
SPEC = Bounded(-1.0, 1.0, shape=(1,))
TINY_ALPHA = dict(alpha_init=1e-8, min_alpha=1e-8, max_alpha=1e-8)


class TabularCritic(nn.Module):
    """Q(s, a) = table[s] for one-hot (optionally flag-extended) states: the action is ignored,
    so the soft value of a state is its table entry (up to the ~0 entropy term)."""

    def __init__(self, features: int) -> None:
        super().__init__()
        self.table = nn.Linear(features, 1, bias=False)
        nn.init.zeros_(self.table.weight)

    def forward(self, observation: torch.Tensor, action: torch.Tensor) -> torch.Tensor:
        return self.table(observation)


def chain_batch() -> TensorDict:
    one_hot = torch.eye(STATES)
    rows = [(0, 1, True, False), (1, 2, True, False), (2, 3, True, False), (3, 6, True, True), (4, 4, False, False), (5, 6, False, True)]
    state, nxt, expert, terminated = (torch.tensor(column) for column in zip(*rows))
    return TensorDict(
        {
            "observation": one_hot[state],
            "action": torch.zeros(len(rows), 1),
            "expert": expert.unsqueeze(-1),
            "next": {"observation": one_hot[nxt], "terminated": terminated.unsqueeze(-1), "done": terminated.unsqueeze(-1).clone()},
        },
        [len(rows)],
    )


def fit_chain(cls, steps: int = 60, absorbing: bool = False, **kwargs) -> torch.Tensor:
    """Trains the tabular critics on the whole chain batch each step; returns critic 0's table.

    The step size makes each SGD step set every table entry to its target (fitted
    Q-iteration): SQIL's loss is ``mean((Q - y)^2)`` per critic, gradient ``2 (Q - y) / N``;
    the paper's IQ-Learn's is ``(r_hat - e/p) / N``; the two absorbing loops share one
    entry, which halves the step that is exact for it."""
    torch.manual_seed(0)
    actor = make_tanh_gaussian_actor(STATES, SPEC, hidden=4, num_blocks=1)
    critic = TensorDictModule(TabularCritic(STATES + absorbing), in_keys=["observation", "action"], out_keys=["state_action_value"])
    loss = cls(actor, critic, absorbing=absorbing, **TINY_ALPHA, **kwargs)
    loss.make_value_estimator(gamma=GAMMA)
    batch = chain_batch()
    if absorbing:
        batch = add_absorbing_transitions(batch)
    critic_params = list(loss.qvalue_network_params.flatten_keys().values())
    rows = batch.shape[0] / (2 if absorbing else 1)
    optimizer = torch.optim.SGD(critic_params, lr=rows / 2 if cls is SQILLoss else rows)
    target = SoftUpdate(loss, tau=1.0)  # the target critics follow at once: tabular fitted Q-iteration
    for _ in range(steps):
        optimizer.zero_grad()
        loss(batch.clone())["loss_qvalue"].backward()
        optimizer.step()
        target.step()
    return critic_params[0].detach().reshape(-1)


def closed_form(expert_reward: float, goal_valued: bool) -> torch.Tensor:
    forever = expert_reward / (1 - GAMMA)
    chain = [forever if goal_valued else expert_reward * (1 - GAMMA ** (CHAIN - i)) / (1 - GAMMA) for i in range(CHAIN)]
    return torch.tensor([*chain, 0.0, GAMMA * forever if goal_valued else 0.0])


@pytest.mark.parametrize("goal_value", [None, "expert"])
@pytest.mark.parametrize("cls", [SQILLoss, IQLearnLoss])
def test_chain_fixed_point_is_the_closed_form(cls, goal_value) -> None:
    kwargs = {"num_value_samples": 1} if cls is IQLearnLoss else {}
    table = fit_chain(cls, goal_value=goal_value, **kwargs)
    expert_reward = 1.0 if cls is SQILLoss else 6 / 4  # the paper's IQ-Learn: SQIL with r_E = 1/p
    torch.testing.assert_close(table[:6], closed_form(expert_reward, goal_value == "expert"), atol=2e-3, rtol=1e-3)


def test_with_the_goal_worth_zero_stopping_short_pays_and_with_its_value_it_does_not() -> None:
    paper = fit_chain(SQILLoss)
    assert paper[CHAIN - 1] < paper[CHAIN - 2] < paper[0]  # nearer the goal is worth less
    fixed = fit_chain(SQILLoss, goal_value="expert")
    assert torch.allclose(fixed[:CHAIN], fixed[0].expand(CHAIN), atol=2e-3)


def test_absorbing_states_value_the_goal_by_the_batch_mix_not_by_the_expert() -> None:
    # Kostrikov et al.'s absorbing state, as add_absorbing_transitions builds it, copies each
    # episode's label into its absorbing loop; expert and policy loops share one input (zero
    # observation, flag 1), so the critic learns their average label: here one expert and
    # one policy goal entry per batch, V_abs = (1/2) r_E / (1 - gamma), half an expert state's
    # value. The goal's worth then falls as the policy reaches it more often: the reason the
    # recipe uses goal_value="expert" instead.
    table = fit_chain(SQILLoss, absorbing=True)
    absorbing_value = table[STATES]  # the flag's weight: the zero observation's only feature
    torch.testing.assert_close(absorbing_value, torch.tensor(0.5 / (1 - GAMMA)), atol=5e-3, rtol=1e-3)
    torch.testing.assert_close(table[CHAIN - 1], 1 + GAMMA * absorbing_value, atol=5e-3, rtol=1e-3)


def test_goal_value_is_checked() -> None:
    actor = make_tanh_gaussian_actor(3, SPEC, hidden=4, num_blocks=1)
    critic = make_qvalue_network(3, SPEC, hidden=4, num_blocks=1)
    with pytest.raises(ValueError, match="goal_value must be one of"):
        SQILLoss(actor, critic, goal_value="goal")
    with pytest.raises(ValueError, match="choose one"):
        SQILLoss(actor, make_qvalue_network(4, SPEC, hidden=4, num_blocks=1), goal_value="expert", absorbing=True)
    with pytest.raises(ValueError, match="variant='iq_learn'"):
        IQLearnLoss(actor, critic, variant="iq_learn", goal_value="expert")
    with pytest.raises(ValueError, match="bc_weight"):
        SQILLoss(actor, critic, bc_weight=0.0)


def _batch(n: int = 6, seed: int = 0) -> TensorDict:
    g = torch.Generator().manual_seed(seed)
    expert = torch.tensor([[True], [False], [True], [True], [False], [False]])[:n]
    return TensorDict(
        {
            "observation": torch.randn(n, 3, generator=g),
            "action": torch.rand(n, 2, generator=g) * 2 - 1,
            "expert": expert,
            "next": {
                "observation": torch.randn(n, 3, generator=g),
                "terminated": torch.zeros(n, 1, dtype=torch.bool),
                "done": torch.zeros(n, 1, dtype=torch.bool),
            },
        },
        [n],
    )


def _actor_and_loss(**kwargs):
    torch.manual_seed(0)
    spec = Bounded(-1.0, 1.0, shape=(2,))
    actor = make_tanh_gaussian_actor(3, spec, hidden=8, num_blocks=1, dropout=0.0, log_std_init=-0.5)
    # alpha_init inside the clamp: reading alpha clamps log_alpha in place otherwise.
    loss = SQILLoss(actor, make_qvalue_network(3, spec, hidden=8, num_blocks=1), alpha_init=0.05, **kwargs)
    loss.make_value_estimator(gamma=0.99)
    return actor, loss


@pytest.mark.parametrize("bc_scale", ["expert_value", "actor_loss"])
def test_behaviour_cloning_anchor_is_td3_bc_on_the_expert_rows(bc_scale: str) -> None:
    actor, loss = _actor_and_loss(bc_weight=0.4, bc_scale=bc_scale)
    batch = _batch()
    out = loss(batch.clone())
    with torch.no_grad():
        loc = actor.module[0](batch.select("observation").clone())["loc"]
    mode = torch.tanh(loc)  # the deterministic action of a tanh-Gaussian on [-1, 1]
    expert = batch["expert"].squeeze(-1)
    mse = (mode[expert] - batch["action"][expert].clamp(-1 + 2e-3, 1 - 2e-3)).pow(2).mean()
    # expert_value: SQIL's r_E / (1 - gamma) = 1 / 0.01, whatever the critics say
    scale = 100.0 if bc_scale == "expert_value" else out["loss_actor"].detach().abs()
    torch.testing.assert_close(out["loss_bc"], 0.4 * scale * mse, rtol=1e-5, atol=1e-6)
    out["loss_bc"].backward()
    assert loss.log_alpha.grad is None
    assert all(p.grad is None for p in loss.qvalue_network_params.values(True, True))
    assert any(p.grad is not None and p.grad.abs().sum() > 0 for p in loss.actor_network_params.values(True, True))
    assert "loss_bc" not in _actor_and_loss()[1](batch.clone()).keys()


@pytest.mark.parametrize("cls", [SQILLoss, IQLearnLoss])
def test_the_one_pass_anchor_is_the_separate_pass_anchor_up_to_the_dropout_mask(cls) -> None:
    """The anchor read off the actor loss's own pass against today's second actor pass
    (``bc_separate_pass=True``, SAC's actor loss and :meth:`behaviour_cloning_anchor`): the
    same value and actor gradient without dropout (eval mode), and with dropout the same
    actor loss from the same random state (the one pass draws SAC's mask and noise, in order)."""
    torch.manual_seed(0)
    spec = Bounded(-1.0, 1.0, shape=(2,))
    actor = make_tanh_gaussian_actor(3, spec, hidden=8, num_blocks=1, dropout=0.2, log_std_init=-0.5)
    loss = cls(actor, make_qvalue_network(3, spec, hidden=8, num_blocks=1), alpha_init=0.05, bc_weight=0.4, goal_value="expert")
    loss.make_value_estimator(gamma=0.99)
    batch = _batch()
    params = list(loss.actor_network_params.values(True, True))

    def run(separate: bool) -> tuple[dict[str, torch.Tensor], list[torch.Tensor]]:
        loss.bc_separate_pass = separate
        torch.manual_seed(3)
        data = batch.clone()
        out = loss(data)
        # SAC's priority and actor outputs aside, nothing is left in the batch (the pass's action is taken back)
        assert set(data.keys(True, True)) - set(batch.keys(True, True)) <= {"td_error", "loc", "scale"}
        grads = torch.autograd.grad(out["loss_actor"] + out["loss_bc"], params, allow_unused=True)
        return {key: value.detach() for key, value in out.items()}, [torch.zeros_like(p) if g is None else g for g, p in zip(grads, params)]

    with eval_mode(actor):
        (one, one_grads), (two, two_grads) = run(False), run(True)
    assert one["loss_bc"] > 0
    torch.testing.assert_close(one, two, rtol=1e-6, atol=0)
    for a, b in zip(one_grads, two_grads):
        torch.testing.assert_close(a, b, rtol=1e-5, atol=1e-7)
    assert sum(g.abs().sum() for g in one_grads) > 0
    (one, _), (two, _) = run(False), run(True)  # train mode: dropout 0.2
    assert torch.equal(one["loss_actor"], two["loss_actor"]) and torch.equal(one["loss_qvalue"], two["loss_qvalue"])
    assert not torch.equal(one["loss_bc"], two["loss_bc"])  # another mask for the separate pass


def test_the_expert_value_scale_keeps_the_anchor_when_the_critics_value_is_near_zero() -> None:
    # The failure of the |loss_actor| scale: with critics whose values at the actor's actions
    # cancel its entropy term, the actor loss is ~0 and that anchor vanishes; this one does not.
    actor, loss = _actor_and_loss(bc_weight=0.4)
    _, constant = _actor_and_loss(bc_weight=0.4, bc_scale="expert_value")
    batch = _batch()
    for module in (loss, constant):
        for param in module.qvalue_network_params.values(True, True):
            param.data.zero_()  # Q = 0 everywhere ...
        module.log_alpha.data.fill_(-20.0)  # ... and alpha ~ 0 (clamped to 1e-3): loss_actor ~ 0
    assert abs(loss(batch.clone())["loss_actor"].item()) < 0.05
    anchor = constant.behaviour_cloning_anchor(batch).item()
    assert loss(batch.clone())["loss_bc"].item() < 0.05 * 0.4 * anchor
    torch.testing.assert_close(constant(batch.clone())["loss_bc"].item(), 0.4 * 100.0 * anchor, rtol=1e-5, atol=0)


def test_an_unknown_bc_scale_is_refused() -> None:
    spec = Bounded(-1.0, 1.0, shape=(2,))
    with pytest.raises(ValueError, match="bc_scale must be one of"):
        SQILLoss(
            make_tanh_gaussian_actor(3, spec, hidden=8, num_blocks=1),
            make_qvalue_network(3, spec, hidden=8, num_blocks=1),
            bc_weight=0.4,
            bc_scale="mean_q",
        )


def test_behaviour_cloning_nll_is_the_tanh_gaussian_density_of_the_expert_actions() -> None:
    actor, loss = _actor_and_loss()
    batch = _batch()
    with torch.no_grad():
        params = actor.module[0](batch.select("observation").clone())
        loc, scale = params["loc"], params["scale"]
        expert = batch["expert"].squeeze(-1)
        action = batch["action"][expert].clamp(-1 + 2e-3, 1 - 2e-3)
        pre = torch.atanh(action)
        normal = torch.distributions.Normal(loc[expert], scale[expert])
        log_density = (normal.log_prob(pre) - torch.log1p(-action.pow(2))).sum(-1)
        torch.testing.assert_close(loss.behaviour_cloning_nll(batch), -log_density.mean(), rtol=1e-4, atol=1e-4)


def test_behaviour_cloning_lowers_the_nll_toward_the_expert() -> None:
    actor, loss = _actor_and_loss()
    batch = _batch()
    params = list(loss.actor_network_params.flatten_keys().values())
    optimizer = torch.optim.Adam(params, lr=1e-2)
    before = loss.behaviour_cloning_nll(batch).item()
    for _ in range(200):
        optimizer.zero_grad()
        loss.behaviour_cloning_nll(batch).backward()
        optimizer.step()
    assert loss.behaviour_cloning_nll(batch).item() < before - 1.0


def _adam_update(loss):
    """Adam (lr 1e-2) on every part of ``loss``, a fast target update and clipped gradients."""
    from functools import partial

    adam = partial(torch.optim.Adam, lr=1e-2)
    return ActorCriticUpdate(
        loss,
        actor_optimizer=adam,
        critic_optimizer=adam,
        alpha_optimizer=adam,
        target_update=partial(SoftUpdate, tau=0.5),
        max_grad_norm=1.0,
    )


def test_a_critic_step_moves_only_the_critics_and_the_targets() -> None:
    _, loss = _actor_and_loss()
    update = _adam_update(loss)
    snapshot = {name: p.detach().clone() for name, p in loss.named_parameters()}
    targets = [t.clone() for t in loss.target_qvalue_network_params.values(True, True)]
    update.critic_step(_batch())
    moved = {name for name, p in loss.named_parameters() if not torch.equal(p.detach(), snapshot[name])}
    assert moved and all(name.startswith("qvalue_network_params") for name in moved), moved
    assert update.updates == 0
    assert not all(torch.equal(a, b) for a, b in zip(targets, loss.target_qvalue_network_params.values(True, True)))


def test_the_update_sums_every_loss_term() -> None:
    _, loss = _actor_and_loss(bc_weight=0.4)
    update = _adam_update(loss)
    torch.manual_seed(1)  # the same action samples in both forwards
    total, _ = update.losses(_batch())
    torch.manual_seed(1)
    out = loss(_batch())
    expected = out["loss_qvalue"] + out["loss_actor"] + out["loss_alpha"] + out["loss_bc"]
    torch.testing.assert_close(total, expected)
    assert math.isfinite(total.item())


RECIPE_TINY = tiny(
    "sqil",
    "env.horizon=220",
    "causal=true",
    "+recipe=goal_valued_bc_anchored",
    "eval.trajectories=2",
    "algo.warm_start.bc_updates=60",
    "algo.warm_start.critic_updates=20",
)


def test_the_recipe_warm_starts_a_run_and_fixes_its_schedule_span(tmp_path, caplog) -> None:
    from hydra.utils import get_class

    from torchrl_causal.evaluation.evaluator import Evaluator
    from torchrl_causal.experiment import RunDirectory, compose_config
    from torchrl_causal.experiment.builders import make_window
    from torchrl_causal.lifecycle import run

    cfg = compose_config([*RECIPE_TINY, f"run_root={tmp_path}"])
    assert cfg.demos.successful_only and cfg.algo.loss.goal_value == "expert" and cfg.algo.loss.bc_weight == 0.4
    window = make_window(cfg)
    trainer = get_class(cfg.algo.trainer)(cfg, RunDirectory(cfg.run_dir), window, Evaluator(cfg, window).periodic)
    trainer.setup()
    try:
        # The schedule spans the config's 500k updates, not the run's 40; the budget can grow.
        assert trainer.update.cosine_updates == 500_000 and trainer.extendable_budget(cfg)
        # The warm-started actor collects the warm-up steps: no random frames.
        assert not trainer.collector.init_random_frames
        expert = trainer.expert_buffer.sample()
        nll_before = trainer.loss.behaviour_cloning_nll(expert).item()
        actor_before = [p.detach().clone() for p in trainer.loss.actor_network_params.values(True, True)]
        with caplog.at_level("INFO"):
            trainer.train_step()  # warm start, then the first 40 env steps (updates start after 80)
            assert trainer.update.updates == 0 and "behaviour cloning 60/60" in caplog.text
            assert trainer.loss.behaviour_cloning_nll(expert).item() < nll_before
            assert not all(torch.equal(a, b) for a, b in zip(actor_before, trainer.loss.actor_network_params.values(True, True)))
            trainer.train_step()  # 80 env steps: no update owed yet, so no critic fit either
            assert "critic fit" not in caplog.text
            trainer.train_step()  # 120: the critics are fitted once, then the 10 owed joint updates run
            trainer.train_step()
        assert caplog.text.count("critic fit 20/20") == 1 and trainer.update.updates == 20
    finally:
        trainer.close()
    # And the whole run completes, evaluating in both regimes (in a folder of its own: the one
    # above holds the bare trainer's replay/ without a run's config, which a run refuses to take).
    results = run(compose_config([*RECIPE_TINY, f"run_root={tmp_path / 'whole'}"]))
    assert set(results) >= {"train", "deploy"}


def test_a_shipped_policy_directory_evaluates_as_its_run(tmp_path) -> None:
    import torch as _torch

    from torchrl_causal.evaluation.runs import archive_runs
    from torchrl_causal.experiment import CheckpointError, RunDirectory, compose_config
    from torchrl_causal.lifecycle import evaluate_run, run

    cfg = compose_config(tiny("bc", f"run_root={tmp_path / 'runs'}", "eval.trajectories=0", "algo.epochs=2", "algo.eval_every=1"))
    run(cfg)
    (shipped,) = archive_runs(tmp_path / "runs", tmp_path / "policies", policies=True)
    files = sorted(str(p.relative_to(shipped)) for p in shipped.rglob("*") if p.is_file())
    assert "checkpoints/best.pt" in files and "checkpoints/last.pt" not in files and "config.yaml" in files
    assert shipped.joinpath("checkpoints/best.pt").stat().st_size < 600_000
    original, copy = (evaluate_run(path, "deploy", episodes=6, num_envs=3, seed=7, save=False) for path in (cfg.run_dir, shipped))
    assert copy.returns == original.returns and copy.successes == original.successes
    # A checkpoint that carries more than the policy is not shipped.
    best = RunDirectory(cfg.run_dir).best_checkpoint
    _torch.save({**_torch.load(best, weights_only=True), "critic": {}}, best)
    with pytest.raises(CheckpointError, match="not the selected policy alone"):
        archive_runs(tmp_path / "runs", tmp_path / "again", policies=True)
