"""Loss modules against reference formulas computed independently on tiny batches."""

from __future__ import annotations

import math

import pytest
import torch
import torch.distributions.normal
from tensordict import TensorDict
from tensordict.nn import TensorDictModule
from torchrl.data import Bounded
from torchrl.envs.utils import ExplorationType, set_exploration_type
from torchrl.objectives import SoftUpdate, ValueEstimators

from torchrl_causal.modules import (
    make_deterministic_actor,
    make_gail_discriminator,
    make_gail_value_network,
    make_qvalue_network,
    make_tanh_gaussian_actor,
)
from torchrl_causal.objectives import (
    AbsorbingIndicator,
    DiscriminatorReward,
    GAILDiscriminatorLoss,
    HuberBCLoss,
    IQLearnLoss,
    SQILLoss,
    add_absorbing_transitions,
    eval_mode,
    gail_discriminator_batch,
    make_gail_losses,
)

pytestmark = pytest.mark.filterwarnings("ignore::UserWarning")

OBS_DIM, ACT_DIM, LOW, HIGH, GAMMA = 3, 2, -0.5, 0.5, 0.9
SPEC = Bounded(LOW, HIGH, shape=(ACT_DIM,))
# Row 0: expert; row 1: policy; row 2: expert, terminated; row 3: policy, truncated (done but not terminated).
EXPERT = torch.tensor([[True], [False], [True], [False]])
TERMINATED = torch.tensor([[False], [False], [True], [False]])
DONE = torch.tensor([[False], [False], [True], [True]])


def fixed_noise(shape, dtype, device):
    """Deterministic stand-in for the standard-normal draws of ``Normal.rsample``."""
    n = math.prod(shape)
    return torch.linspace(-1.3, 1.7, n, dtype=dtype, device=device).roll(n // 3).reshape(shape)


@pytest.fixture
def frozen_noise(monkeypatch):
    monkeypatch.setattr(torch.distributions.normal, "_standard_normal", fixed_noise)


def make_batch(seed: int = 0, n: int = 4) -> TensorDict:
    g = torch.Generator().manual_seed(seed)
    return TensorDict(
        {
            "observation": torch.randn(n, OBS_DIM, generator=g),
            "action": (torch.rand(n, ACT_DIM, generator=g) - 0.5) * (HIGH - LOW),
            "expert": EXPERT[:n].clone(),
            "next": {
                "observation": torch.randn(n, OBS_DIM, generator=g),
                "done": DONE[:n].clone(),
                "terminated": TERMINATED[:n].clone(),
            },
        },
        [n],
    )


def make_loss(cls, *, alpha: float, actor_dropout: float = 0.0, **kwargs):
    torch.manual_seed(0)
    actor = make_tanh_gaussian_actor(OBS_DIM, SPEC, hidden=8, num_blocks=1, dropout=actor_dropout, log_std_init=-0.7)
    qvalue = make_qvalue_network(OBS_DIM + kwargs.get("absorbing", False), SPEC, hidden=8, num_blocks=1)
    loss = cls(actor, qvalue, **kwargs)
    loss.make_value_estimator(gamma=GAMMA)
    with torch.no_grad():
        loss.log_alpha.fill_(math.log(alpha))
        # Targets that differ from the online critics, so the test sees which ones are used.
        for p in loss.target_qvalue_network_params.values(True, True):
            p.add_(0.3 * torch.randn_like(p))
    return loss, actor


def critic(loss, params, j: int, obs: torch.Tensor, act: torch.Tensor) -> torch.Tensor:
    """Q_j(obs, act) with the j-th slice of the loss's stacked critic parameters, shape [..., 1]."""
    with params[j].to_module(loss.qvalue_network):
        td = TensorDict({"observation": obs, "action": act}, obs.shape[:-1])
        return loss.qvalue_network(td)["state_action_value"]


def squashed_sample(actor, obs: torch.Tensor, sample_shape: tuple = ()) -> tuple[torch.Tensor, torch.Tensor]:
    """Reference tanh-Gaussian draw with ``fixed_noise`` and its log-density, by the change-of-variables formula."""
    with torch.no_grad():
        td = actor.module[0](TensorDict({"observation": obs}, obs.shape[:-1]))
    loc, scale = td["loc"], td["scale"]
    pre = loc + scale * fixed_noise((*sample_shape, *loc.shape), loc.dtype, loc.device)
    half_range = (HIGH - LOW) / 2
    action = (HIGH + LOW) / 2 + half_range * torch.tanh(pre)
    gaussian = -((pre - loc) ** 2) / (2 * scale**2) - scale.log() - 0.5 * math.log(2 * math.pi)
    log_det = torch.log1p(-(torch.tanh(pre) ** 2)) + math.log(half_range)
    return action, (gaussian - log_det).sum(-1, keepdim=True)


@pytest.mark.parametrize("raw_alpha, alpha", [(0.05, 0.05), (10.0, 0.1), (1e-6, 1e-3)])
def test_sqil_critic_regresses_on_relabelled_soft_bellman_target(frozen_noise, raw_alpha, alpha):
    loss, actor = make_loss(SQILLoss, alpha=raw_alpha)
    batch = make_batch()
    batch["next", "reward"] = torch.full((4, 1), 100.0)  # an env reward that SQIL must ignore
    out = loss(batch)

    next_action, next_log_prob = squashed_sample(actor, batch["next", "observation"])
    min_target_q = torch.minimum(
        *(critic(loss, loss.target_qvalue_network_params, j, batch["next", "observation"], next_action) for j in (0, 1))
    )
    reward = EXPERT.float()
    y = reward + GAMMA * (~TERMINATED).float() * (min_target_q - alpha * next_log_prob)
    expected = sum(((critic(loss, loss.qvalue_network_params, j, batch["observation"], batch["action"]) - y) ** 2).mean() for j in (0, 1))
    torch.testing.assert_close(out["loss_qvalue"], expected, rtol=1e-5, atol=1e-6)
    assert out["alpha"].item() == pytest.approx(alpha, rel=1e-5)
    assert torch.equal(batch["next", "reward"], torch.full((4, 1), 100.0)), "the caller's batch was modified"
    assert "td_error" in batch.keys(), "SAC's priority must reach the caller's batch"


@pytest.mark.parametrize("num_value_samples", [1, 3])
def test_iq_learn_critic_loss_matches_chi_squared_objective(frozen_noise, num_value_samples):
    alpha = 0.05
    loss, actor = make_loss(IQLearnLoss, alpha=alpha, num_value_samples=num_value_samples)
    batch = make_batch()
    out = loss(batch)

    next_obs = batch["next", "observation"]
    actions, log_probs = squashed_sample(actor, next_obs, (num_value_samples,))
    soft_values = [
        torch.minimum(*(critic(loss, loss.target_qvalue_network_params, j, next_obs, actions[m]) for j in (0, 1))) - alpha * log_probs[m]
        for m in range(num_value_samples)
    ]
    v_next = torch.stack(soft_values).mean(0)
    expected = 0.0
    for j in (0, 1):
        r_hat = critic(loss, loss.qvalue_network_params, j, batch["observation"], batch["action"])
        r_hat = r_hat - GAMMA * (~TERMINATED).float() * v_next
        expected = expected - r_hat[EXPERT].mean() + 0.5 * (r_hat**2).mean()
    torch.testing.assert_close(out["loss_qvalue"], expected, rtol=1e-5, atol=1e-6)


def test_iq_learn_unreduced_loss_averages_to_the_objective(frozen_noise):
    mean_loss, _ = make_loss(IQLearnLoss, alpha=0.05, num_value_samples=2)
    none_loss, _ = make_loss(IQLearnLoss, alpha=0.05, num_value_samples=2, reduction="none", scalar_output_mode="exclude")
    batch = make_batch()
    per_sample = none_loss(batch.clone())["loss_qvalue"]
    assert per_sample.shape == (4,)
    torch.testing.assert_close(per_sample.mean(), mean_loss(batch.clone())["loss_qvalue"])


def _critic_grads(loss) -> torch.Tensor:
    return torch.cat([p.grad.flatten() for p in loss.qvalue_network_params.values(True, True)])


@pytest.mark.parametrize("expert_rows", [[0, 2], [3]])  # expert fraction p = 1/2, 1/4
def test_paper_iq_learn_critic_gradient_is_half_sqil_with_expert_reward_one_over_p(frozen_noise, expert_rows):
    batch = make_batch()
    batch["expert"] = torch.zeros(4, 1, dtype=torch.bool)
    batch["expert"][expert_rows] = True
    p = len(expert_rows) / 4
    iq, _ = make_loss(IQLearnLoss, alpha=0.05, num_value_samples=1)
    sqil, _ = make_loss(SQILLoss, alpha=0.05, expert_reward=1 / p)
    for a, b in zip(iq.parameters(), sqil.parameters()):
        assert torch.equal(a, b), "both losses must start from the same weights"
    iq(batch.clone())["loss_qvalue"].backward()
    sqil(batch.clone())["loss_qvalue"].backward()
    torch.testing.assert_close(_critic_grads(iq), 0.5 * _critic_grads(sqil), rtol=1e-5, atol=1e-7)


@pytest.mark.parametrize("num_value_samples", [1, 3])
def test_online_iq_learn_adds_the_value_term_on_the_online_critic(frozen_noise, num_value_samples):
    alpha, n = 0.05, 4
    loss, actor = make_loss(IQLearnLoss, alpha=alpha, variant="iq_learn", num_value_samples=num_value_samples)
    batch = make_batch()
    out = loss(batch)

    obs, next_obs = batch["observation"], batch["next", "observation"]
    states = torch.cat([obs, next_obs])  # V(z) and V(z') are sampled in one pass
    actions, log_probs = squashed_sample(actor, states, (num_value_samples,))
    params = loss.qvalue_network_params
    discount = GAMMA * (~TERMINATED).float()
    expected = 0.0
    for j in (0, 1):
        soft = torch.stack([critic(loss, params, j, states, actions[m]) - alpha * log_probs[m] for m in range(num_value_samples)]).mean(0)
        value, next_value = soft[:n], soft[n:]
        r_hat = critic(loss, params, j, obs, batch["action"]) - discount * next_value
        expected = expected - r_hat[EXPERT].mean() + (value - discount * next_value).mean() + 0.5 * (r_hat**2).mean()
    torch.testing.assert_close(out["loss_qvalue"], expected, rtol=1e-5, atol=1e-6)


def test_iq_learn_variant_is_checked_and_paper_is_the_default():
    loss, _ = make_loss(IQLearnLoss, alpha=0.05)
    assert loss.variant == "paper"
    with pytest.raises(ValueError, match="variant must be one of"):
        make_loss(IQLearnLoss, alpha=0.05, variant="garg")


@pytest.mark.parametrize("cls", [SQILLoss, IQLearnLoss])
def test_targets_sample_the_actor_without_dropout(frozen_noise, cls):
    loss, actor = make_loss(cls, alpha=0.05, actor_dropout=0.5)
    reference, _ = make_loss(cls, alpha=0.05)  # same weights, no dropout at all
    batch = make_batch()
    assert actor.training
    torch.testing.assert_close(loss(batch.clone())["loss_qvalue"], reference(batch.clone())["loss_qvalue"])
    assert actor.training, "the actor's mode must be restored"
    # The actor loss still sees dropout (a regulariser), so it differs from the dropout-free one.
    assert not torch.allclose(loss(batch.clone())["loss_actor"], reference(batch.clone())["loss_actor"])


def _absorbing_critic(loss, params, j: int, obs: torch.Tensor, flag: torch.Tensor, act: torch.Tensor) -> torch.Tensor:
    """Q_j on the observation with the absorbing flag appended, through the wrapped network itself."""
    with params[j].to_module(loss.qvalue_network):
        td = TensorDict({"observation": torch.cat([obs, flag.float()], -1), "action": act}, obs.shape[:-1])
        return loss.qvalue_network.network(td)["state_action_value"]


@pytest.mark.parametrize("cls", [SQILLoss, IQLearnLoss])
def test_the_goal_transition_bootstraps_through_the_absorbing_state(frozen_noise, cls):
    alpha = 0.05
    loss, actor = make_loss(cls, alpha=alpha, absorbing=True, **({"num_value_samples": 1} if cls is IQLearnLoss else {}))
    batch = add_absorbing_transitions(make_batch())  # row 2 reaches the goal; row 4 is its absorbing state
    assert batch.shape == (5,) and not batch["next", "terminated"].any()
    out = loss(batch)

    next_obs, next_flag = batch["next", "observation"], batch["next", "absorbing"]
    next_action, next_log_prob = squashed_sample(actor, next_obs, () if cls is SQILLoss else (1,))
    next_action, next_log_prob = next_action.reshape(5, ACT_DIM), next_log_prob.reshape(5, 1)
    target = loss.target_qvalue_network_params
    next_value = (
        torch.minimum(*(_absorbing_critic(loss, target, j, next_obs, next_flag, next_action) for j in (0, 1))) - alpha * next_log_prob
    )
    expert = batch["expert"]
    q = [_absorbing_critic(loss, loss.qvalue_network_params, j, batch["observation"], batch["absorbing"], batch["action"]) for j in (0, 1)]
    # No row is terminal any more: the goal transition and the absorbing loop bootstrap with gamma.
    if cls is SQILLoss:
        y = expert.float() + GAMMA * next_value
        expected = sum(((q_j - y) ** 2).mean() for q_j in q)
    else:
        r_hat = [q_j - GAMMA * next_value for q_j in q]
        expected = sum(-r[expert].mean() + 0.5 * (r**2).mean() for r in r_hat)
    torch.testing.assert_close(out["loss_qvalue"], expected, rtol=1e-5, atol=1e-6)
    assert ("next", "absorbing") in loss.in_keys and "absorbing" in loss.in_keys


def test_absorbing_transitions_follow_every_terminal_one():
    g = torch.Generator().manual_seed(0)
    n = 9
    terminated = torch.rand(n, 1, generator=g) < 0.4
    truncated = ~terminated & (torch.rand(n, 1, generator=g) < 0.5)
    batch = TensorDict(
        {
            "observation": torch.randn(n, OBS_DIM, generator=g),
            "action": torch.rand(n, ACT_DIM, generator=g),
            "expert": torch.rand(n, 1, generator=g) < 0.5,
            "next": {"observation": torch.randn(n, OBS_DIM, generator=g), "terminated": terminated, "done": terminated | truncated},
        },
        [n],
    )
    original = batch.clone()
    out = add_absorbing_transitions(batch)
    assert (batch == original).all(), "the input must not change"
    term = terminated.squeeze(-1)
    assert out.shape == (n + int(term.sum()),)
    head, tail = out[:n], out[n:]
    kept = head[~term]
    assert (kept.exclude("absorbing", ("next", "absorbing")) == batch[~term]).all()
    assert not kept["absorbing"].any() and not kept["next", "absorbing"].any()
    assert torch.equal(kept["next", "done"], truncated[~term])  # truncation still ends the episode
    goal = head[term]
    assert goal["next", "absorbing"].all() and not goal["next", "terminated"].any() and not goal["next", "done"].any()
    assert not goal["absorbing"].any() and (goal["next", "observation"] == 0).all()
    assert torch.equal(goal["observation"], batch["observation"][term])
    assert tail["absorbing"].all() and tail["next", "absorbing"].all()
    assert not tail["next", "terminated"].any() and not tail["next", "done"].any()
    for key in ("observation", "action", ("next", "observation")):
        assert (tail[key] == 0).all()
    assert torch.equal(tail["expert"], batch["expert"][term])  # absorbing rows keep their episode's label
    with pytest.raises(ValueError, match="flat batch"):
        add_absorbing_transitions(batch.reshape(3, 3))
    with pytest.raises(KeyError, match="terminated"):
        add_absorbing_transitions(batch.exclude(("next", "terminated")))


@pytest.mark.parametrize("cls", [SQILLoss, IQLearnLoss])
def test_alpha_is_clamped_at_both_ends_even_after_optimizer_steps(cls):
    loss, _ = make_loss(cls, alpha=1.0)
    batch = make_batch()
    assert loss(batch)["alpha"].item() == pytest.approx(0.1, rel=1e-5)  # paper's log-alpha = 0 start
    optimizer = torch.optim.SGD([loss.log_alpha], lr=1e3)
    for sign, bound in ((-1.0, 1e-3), (1.0, 0.1)):
        for _ in range(3):
            optimizer.zero_grad()
            (sign * -loss.log_alpha).backward()  # push log-alpha far past the bound
            optimizer.step()
            assert loss(batch)["alpha"].item() == pytest.approx(bound, rel=1e-5)
            assert loss.log_alpha.item() == pytest.approx(math.log(bound), rel=1e-5)


def _grads(params) -> list[torch.Tensor | None]:
    return [p.grad for p in params]


def _moved(grads) -> bool:
    return any(g is not None and g.abs().sum() > 0 for g in grads)


@pytest.mark.parametrize("cls, kwargs", [(SQILLoss, {}), (IQLearnLoss, {}), (IQLearnLoss, {"variant": "iq_learn"})])
@pytest.mark.parametrize(
    "term, actor_moves, critic_moves, alpha_moves",
    [
        ("loss_actor", True, False, False),
        ("loss_qvalue", False, True, False),
        ("loss_alpha", False, False, True),
    ],
)
def test_each_loss_term_reaches_only_its_own_parameters(cls, kwargs, term, actor_moves, critic_moves, alpha_moves):
    loss, _ = make_loss(cls, alpha=0.05, **kwargs)
    loss.zero_grad(set_to_none=True)
    loss(make_batch())[term].backward()
    assert _moved(_grads(loss.actor_network_params.values(True, True))) == actor_moves
    assert _moved(_grads(loss.qvalue_network_params.values(True, True))) == critic_moves
    assert _moved([loss.log_alpha.grad]) == alpha_moves
    assert not _moved(_grads(loss.target_qvalue_network_params.values(True, True)))


@pytest.mark.parametrize("cls", [SQILLoss, IQLearnLoss])
def test_missing_or_malformed_expert_flag_is_named(cls):
    loss, _ = make_loss(cls, alpha=0.05)
    batch = make_batch()
    with pytest.raises(KeyError, match="'expert'"):
        loss(batch.exclude("expert"))
    batch["expert"] = batch["expert"].float()
    with pytest.raises(ValueError, match="'expert'.*bool"):
        loss(batch)


def test_iq_learn_rejects_a_batch_without_expert_rows():
    loss, _ = make_loss(IQLearnLoss, alpha=0.05)
    batch = make_batch()
    batch["expert"] = torch.zeros_like(batch["expert"])
    with pytest.raises(ValueError, match="at least one expert transition"):
        loss(batch)


@pytest.mark.parametrize("cls", [SQILLoss, IQLearnLoss])
def test_expert_key_is_configurable_and_no_reward_is_read(cls):
    loss, _ = make_loss(cls, alpha=0.05)
    assert "expert" in loss.in_keys and ("next", "reward") not in loss.in_keys
    loss.set_keys(expert="is_demo")
    assert "is_demo" in loss.in_keys and "expert" not in loss.in_keys
    batch = make_batch()
    batch.rename_key_("expert", "is_demo")
    assert torch.isfinite(loss(batch)["loss_qvalue"])


def test_iq_learn_accepts_only_one_step_value_estimation():
    loss, _ = make_loss(IQLearnLoss, alpha=0.05)
    with pytest.raises(NotImplementedError):
        loss.make_value_estimator(ValueEstimators.TD1)
    with pytest.raises(ValueError, match="num_value_samples"):
        make_loss(IQLearnLoss, alpha=0.05, num_value_samples=0)


def test_huber_bc_loss_matches_piecewise_formula():
    torch.manual_seed(0)
    actor = make_deterministic_actor(OBS_DIM, SPEC, hidden=8, num_blocks=1)
    delta = 0.2
    loss = HuberBCLoss(actor, delta=delta)
    batch = TensorDict({"observation": torch.randn(6, OBS_DIM), "action": SPEC.rand((6,))}, [6])
    with torch.no_grad():
        prediction = actor(batch.exclude("action"))["action"]
    error = (prediction - batch["action"]).abs()
    assert (error > delta).any() and (error <= delta).any(), "batch must exercise both Huber regimes"
    expected = torch.where(error <= delta, 0.5 * error**2, delta * (error - 0.5 * delta)).mean()
    torch.testing.assert_close(loss(batch)["loss_bc"], expected)


class _Logit(torch.nn.Module):
    """A discriminator body with a hand-written logit of the concatenated inputs."""

    def __init__(self, logit, weight: torch.Tensor):
        super().__init__()
        self.logit = logit
        self.weight = torch.nn.Parameter(weight.clone())

    def forward(self, *inputs):
        return self.logit(torch.cat(inputs, -1), self.weight)[..., None]


def _discriminator(logit, weight: torch.Tensor) -> TensorDictModule:
    return TensorDictModule(_Logit(logit, weight), in_keys=["observation", "action"], out_keys=["d_logits"])


def _linear(u, w):
    return u @ w


def _quadratic(u, w):
    return 0.5 * (u**2).sum(-1) * w.sum()  # w = [1.0]: gradient u


def _pairs(n: int, seed: int = 0) -> tuple[TensorDict, TensorDict]:
    g = torch.Generator().manual_seed(seed)

    def make() -> TensorDict:
        return TensorDict(
            {
                "observation": torch.randn(n, OBS_DIM, generator=g),
                "action": torch.rand(n, ACT_DIM, generator=g) - 0.5,
            },
            [n],
        )

    return make(), make()


def test_gail_penalty_acts_on_the_logit_and_trains_the_discriminator():
    weight = torch.tensor([2.0, -1.0, 0.5, 3.0, -2.0])
    gp_lambda = 5.0
    expert, policy = _pairs(8)
    with_gp = GAILDiscriminatorLoss(_discriminator(_linear, weight), gp_lambda=gp_lambda)
    without_gp = GAILDiscriminatorLoss(_discriminator(_linear, weight), use_grad_penalty=False)
    batch = gail_discriminator_batch(with_gp, expert, policy)
    out = with_gp(batch)

    u_expert = torch.cat([expert["observation"], expert["action"]], -1)
    u_policy = torch.cat([policy["observation"], policy["action"]], -1)
    # BCE with logits: -log sigmoid(l) = softplus(-l), -log(1 - sigmoid(l)) = softplus(l).
    bce = (torch.nn.functional.softplus(-(u_expert @ weight)) + torch.nn.functional.softplus(u_policy @ weight)).mean()
    # The logit of a linear model has gradient w at every interpolate: a unit-norm target
    # it can meet, unlike the sigmoid's D(1 - D) w.
    expected_gp = gp_lambda * (weight.norm() - 1) ** 2
    torch.testing.assert_close(out["gp_loss"], expected_gp)
    torch.testing.assert_close(out["loss"], bce + expected_gp)
    torch.testing.assert_close(without_gp(batch)["loss"], bce)
    out["loss"].backward()
    without_gp(batch)["loss"].backward()
    grad_with = next(with_gp.parameters()).grad
    grad_without = next(without_gp.parameters()).grad
    assert not torch.allclose(grad_with, grad_without), "the penalty must reach the discriminator's weights"


@pytest.mark.parametrize("absorbing", [False, True])
def test_gail_penalty_draws_one_interpolation_weight_per_sample(absorbing):
    gp_lambda, n = 5.0, 6
    expert, policy = _pairs(n, seed=1)
    discriminator = _discriminator(_quadratic, torch.ones(1))
    if absorbing:
        discriminator = AbsorbingIndicator(discriminator)
        expert["absorbing"] = torch.tensor([[False], [True], [False], [False], [False], [False]])
        policy["absorbing"] = torch.tensor([[False], [False], [False], [True], [False], [False]])
    loss = GAILDiscriminatorLoss(discriminator, gp_lambda=gp_lambda)
    torch.manual_seed(3)
    gp = loss(gail_discriminator_batch(loss, expert, policy))["gp_loss"]

    torch.manual_seed(3)
    eps = torch.rand(n, 1)  # one weight per pair, shared by every coordinate
    u_expert = torch.cat([expert["observation"], expert["action"]], -1)
    u_policy = torch.cat([policy["observation"], policy["action"]], -1)
    interpolates = eps * u_policy + (1 - eps) * u_expert  # the gradient of 0.5 |u|^2 is u
    penalty = (interpolates.norm(dim=-1) - 1) ** 2
    if absorbing:
        penalty = penalty[[0, 2, 4, 5]]  # pairs with an absorbing end are left out
    torch.testing.assert_close(gp, gp_lambda * penalty.mean())


def test_discriminator_reward_is_the_logit_or_softplus_without_dropout():
    torch.manual_seed(0)
    discriminator = make_gail_discriminator(OBS_DIM, SPEC, hidden=16, dropout=0.2)
    rollout = TensorDict({"observation": torch.randn(5, OBS_DIM), "action": SPEC.rand((5,))}, [5])
    logit_reward = DiscriminatorReward(discriminator)
    r1 = logit_reward(rollout.clone())["next", "reward"]
    r2 = logit_reward(rollout.clone())["next", "reward"]
    discriminator.eval()
    with torch.no_grad():
        logits = discriminator(rollout.clone())["d_logits"]
    discriminator.train()
    torch.testing.assert_close(r1, logits)
    torch.testing.assert_close(r1, r2)  # no dropout mask
    positive = DiscriminatorReward(discriminator, reward="positive")(rollout.clone())["next", "reward"]
    torch.testing.assert_close(positive, -torch.log(1 - torch.sigmoid(logits)))
    assert discriminator.training, "the discriminator's mode must be restored"
    with pytest.raises(ValueError, match="reward must be one of"):
        DiscriminatorReward(discriminator, reward="negative")


def _terminal_rollout(horizon: int) -> TensorDict:
    terminated = torch.zeros(1, horizon, 1, dtype=torch.bool)
    terminated[0, -1] = True
    return TensorDict(
        {
            "observation": torch.randn(1, horizon, OBS_DIM),
            "next": {"observation": torch.randn(1, horizon, OBS_DIM), "done": terminated.clone(), "terminated": terminated},
        },
        [1, horizon],
    )


def _zero_output(module: torch.nn.Module) -> None:
    last = [m for m in module.modules() if isinstance(m, torch.nn.Linear)][-1]
    with torch.no_grad():
        last.weight.zero_()
        last.bias.zero_()


@pytest.mark.parametrize("reward", ["logit", "positive"])
def test_only_the_positive_reward_pays_for_staying_out_of_a_terminal_goal(reward):
    torch.manual_seed(0)
    discriminator = make_gail_discriminator(OBS_DIM, SPEC, hidden=8)
    value = make_gail_value_network(OBS_DIM, hidden=8)
    _zero_output(discriminator)  # D = 1/2 everywhere: the discriminator cannot tell
    _zero_output(value)
    gail = make_gail_losses(
        make_tanh_gaussian_actor(OBS_DIM, SPEC, hidden=8, num_blocks=1, dropout=0.0), value, discriminator, reward=reward
    )
    horizon, gamma, lmbda = 6, 0.99, 0.95
    with torch.no_grad(), set_exploration_type(ExplorationType.RANDOM):
        rollout = gail.policy.actor_network(_terminal_rollout(horizon))
        rollout = gail.policy.value_estimator(gail.reward(rollout))
    targets = rollout["value_target"][0, :, 0]
    if reward == "logit":
        # Zero reward at chance: ending the episode and going on are worth the same.
        torch.testing.assert_close(targets, torch.zeros(horizon))
    else:
        # log 2 per step: with V = 0 the GAE target of step t sums (gamma lambda)^k log 2 up
        # to the terminal step, so the further from the goal, the more it is worth.
        steps_left = torch.arange(horizon, 0, -1, dtype=torch.float32)
        expected = math.log(2) * (1 - (gamma * lmbda) ** steps_left) / (1 - gamma * lmbda)
        torch.testing.assert_close(targets, expected)


def test_absorbing_discriminator_adds_the_absorbing_return_at_termination():
    torch.manual_seed(0)
    gamma = 0.9
    discriminator = make_gail_discriminator(OBS_DIM + 1, SPEC, hidden=8)
    gail = make_gail_losses(
        make_tanh_gaussian_actor(OBS_DIM, SPEC, hidden=8, num_blocks=1, dropout=0.0),
        make_gail_value_network(OBS_DIM, hidden=8),
        discriminator,
        gamma=gamma,
        absorbing=True,
    )
    horizon = 4
    with torch.no_grad(), set_exploration_type(ExplorationType.RANDOM):
        rollout = gail.reward(gail.policy.actor_network(_terminal_rollout(horizon)))
    discriminator.eval()
    with torch.no_grad():
        flat = rollout.reshape(-1)
        inputs = torch.cat([flat["observation"], torch.zeros(horizon, 1)], -1)
        logits = discriminator.module(inputs, flat["action"])
        absorbing_logit = discriminator.module(torch.cat([torch.zeros(1, OBS_DIM), torch.ones(1, 1)], -1), torch.zeros(1, ACT_DIM))
    expected = logits.clone()
    expected[-1] += gamma / (1 - gamma) * absorbing_logit[0]
    torch.testing.assert_close(rollout["next", "reward"][0], expected)
    with pytest.raises(ValueError, match="gamma"):
        DiscriminatorReward(gail.reward.discriminator, gamma=None)


def test_ppo_ratio_is_one_before_any_update_when_rollout_and_loss_share_the_policy():
    torch.manual_seed(0)
    actor = make_tanh_gaussian_actor(OBS_DIM, SPEC, hidden=32, num_blocks=2, dropout=0.05, log_std_init=-1.5)
    gail = make_gail_losses(actor, make_gail_value_network(OBS_DIM, hidden=8), make_gail_discriminator(OBS_DIM, SPEC, hidden=8))
    rollout = TensorDict(
        {
            "observation": torch.randn(4, 50, OBS_DIM),
            "next": {
                "observation": torch.randn(4, 50, OBS_DIM),
                "done": torch.zeros(4, 50, 1, dtype=torch.bool),
                "terminated": torch.zeros(4, 50, 1, dtype=torch.bool),
            },
        },
        [4, 50],
    )
    with torch.no_grad(), set_exploration_type(ExplorationType.RANDOM), eval_mode(actor):
        rollout = actor(rollout)
    with torch.no_grad():
        rollout = gail.policy.value_estimator(gail.reward(rollout))
    flat = rollout.reshape(-1)
    with eval_mode(actor):
        out = gail.policy(flat)
    assert out["clip_fraction"].item() == 0.0
    assert abs(out["max_ratio"].item() - 1) < 1e-5 and abs(out["mean_ratio"].item() - 1) < 1e-5
    # The bug this guards against: a fresh dropout mask in the loss moves the ratio off 1.
    assert actor.training
    assert gail.policy(flat)["clip_fraction"].item() > 0.05


def test_gail_wiring_uses_paper_settings():
    torch.manual_seed(0)
    gail = make_gail_losses(
        make_tanh_gaussian_actor(OBS_DIM, SPEC, hidden=8, num_blocks=1),
        make_gail_value_network(OBS_DIM, hidden=8),
        make_gail_discriminator(OBS_DIM, SPEC, hidden=8),
    )
    assert isinstance(gail.discriminator, GAILDiscriminatorLoss)
    assert gail.discriminator.use_grad_penalty and gail.discriminator.gp_lambda == 5.0
    assert gail.reward.reward == "logit" and not gail.reward.absorbing
    ppo = gail.policy
    assert ppo.entropy_coeff.item() == pytest.approx(1e-2) and ppo.critic_coeff.item() == pytest.approx(0.5)
    assert ppo.clip_epsilon.item() == pytest.approx(0.2) and ppo.normalize_advantage
    assert ppo.value_estimator.gamma.item() == pytest.approx(0.99)
    assert ppo.value_estimator.lmbda.item() == pytest.approx(0.95)
    horizon = 6
    with torch.no_grad(), set_exploration_type(ExplorationType.RANDOM):
        rollout = ppo.actor_network(_terminal_rollout(horizon))
        rollout = ppo.value_estimator(gail.reward(rollout))
    # At the terminal step the GAE value target is the reward itself.
    torch.testing.assert_close(rollout["value_target"][0, -1], rollout["next", "reward"][0, -1])
    ppo_out = ppo(rollout.reshape(-1))
    assert {"loss_objective", "loss_critic", "loss_entropy"} <= set(ppo_out.keys())


def test_gail_pairing_rejects_unequal_batches():
    loss = GAILDiscriminatorLoss(make_gail_discriminator(OBS_DIM, SPEC, hidden=8))
    expert = TensorDict({"observation": torch.randn(4, OBS_DIM), "action": SPEC.rand((4,))}, [4])
    with pytest.raises(ValueError, match="as many expert as policy"):
        gail_discriminator_batch(loss, expert, expert[:3])


def _bandit_batch(actor, n: int, expert_mean: float, g: torch.Generator) -> TensorDict:
    """Half expert actions near ``expert_mean``, half fresh policy samples; every step terminal."""
    obs = torch.zeros(n, 1)
    with torch.no_grad(), set_exploration_type(ExplorationType.RANDOM):
        policy_actions = actor(TensorDict({"observation": obs[: n // 2]}, [n // 2]))["action"]
    expert_actions = (expert_mean + 0.05 * torch.randn(n // 2, 1, generator=g)).clamp(-0.99, 0.99)
    ones = torch.ones(n, 1, dtype=torch.bool)
    return TensorDict(
        {
            "observation": obs,
            "action": torch.cat([expert_actions, policy_actions]),
            "expert": torch.cat([ones[: n // 2], ~ones[n // 2 :]]),
            "next": {"observation": obs.clone(), "done": ones, "terminated": ones.clone()},
        },
        [n],
    )


@pytest.mark.parametrize("cls", [SQILLoss, IQLearnLoss])
def test_policy_mean_moves_toward_expert_action_on_a_continuous_bandit(cls):
    torch.manual_seed(0)
    g = torch.Generator().manual_seed(1)
    spec = Bounded(-1.0, 1.0, shape=(1,))
    actor = make_tanh_gaussian_actor(1, spec, hidden=16, num_blocks=1, dropout=0.0, log_std_init=-1.0)
    loss = cls(actor, make_qvalue_network(1, spec, hidden=16, num_blocks=1))
    optimizer = torch.optim.Adam(loss.parameters(), lr=3e-3)
    updater = SoftUpdate(loss, tau=0.05)

    def policy_mean() -> float:
        with torch.no_grad(), set_exploration_type(ExplorationType.DETERMINISTIC):
            return actor(TensorDict({"observation": torch.zeros(1, 1)}, [1]))["action"].item()

    start = policy_mean()
    for _ in range(150):
        out = loss(_bandit_batch(actor, 32, 0.5, g))
        optimizer.zero_grad()
        (out["loss_actor"] + out["loss_qvalue"] + out["loss_alpha"]).backward()
        optimizer.step()
        updater.step()
    end = policy_mean()
    assert abs(end - 0.5) < 0.15 and abs(end - 0.5) < abs(start - 0.5) - 0.2, (start, end)
