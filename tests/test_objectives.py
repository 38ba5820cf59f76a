"""Loss modules against reference formulas computed independently on tiny batches."""

from __future__ import annotations

import math

import pytest
import torch
import torch.distributions.normal
from tensordict import TensorDict
from torchrl.data import Bounded
from torchrl.envs.utils import ExplorationType, set_exploration_type
from torchrl.objectives import GAILLoss, SoftUpdate, ValueEstimators

from torchrl_causal.modules import (
    make_deterministic_actor,
    make_gail_discriminator,
    make_gail_value_network,
    make_qvalue_network,
    make_tanh_gaussian_actor,
)
from torchrl_causal.objectives import (
    DiscriminatorReward,
    HuberBCLoss,
    IQLearnLoss,
    SQILLoss,
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


def make_loss(cls, *, alpha: float, **kwargs):
    torch.manual_seed(0)
    actor = make_tanh_gaussian_actor(OBS_DIM, SPEC, hidden=8, num_blocks=1, dropout=0.0, log_std_init=-0.7)
    qvalue = make_qvalue_network(OBS_DIM, SPEC, hidden=8, num_blocks=1)
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
    log_det = torch.log1p(-torch.tanh(pre) ** 2) + math.log(half_range)
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
    expected = sum(
        ((critic(loss, loss.qvalue_network_params, j, batch["observation"], batch["action"]) - y) ** 2).mean()
        for j in (0, 1)
    )
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
        torch.minimum(*(critic(loss, loss.target_qvalue_network_params, j, next_obs, actions[m]) for j in (0, 1)))
        - alpha * log_probs[m]
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


@pytest.mark.parametrize("cls", [SQILLoss, IQLearnLoss])
@pytest.mark.parametrize("term, actor_moves, critic_moves, alpha_moves", [
    ("loss_actor", True, False, False),
    ("loss_qvalue", False, True, False),
    ("loss_alpha", False, False, True),
])
def test_each_loss_term_reaches_only_its_own_parameters(cls, term, actor_moves, critic_moves, alpha_moves):
    loss, _ = make_loss(cls, alpha=0.05)
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


def _linear_discriminator(weight: torch.Tensor) -> torch.nn.Module:
    from tensordict.nn import TensorDictModule

    class Logistic(torch.nn.Module):
        def __init__(self):
            super().__init__()
            self.weight = torch.nn.Parameter(weight.clone())

        def forward(self, obs, act):
            return torch.sigmoid(torch.cat([obs, act], -1) @ self.weight)[..., None]

    return TensorDictModule(Logistic(), in_keys=["observation", "action"], out_keys=["d_logits"])


def test_gail_gradient_penalty_matches_formula_and_trains_the_discriminator():
    weight = torch.tensor([2.0, -1.0, 0.5, 3.0, -2.0])
    gp_lambda = 5.0
    transitions = TensorDict({"observation": torch.randn(8, OBS_DIM), "action": SPEC.rand((8,))}, [8])
    # Expert and policy rows coincide, so every interpolate is that same point.
    with_gp = GAILLoss(_linear_discriminator(weight), use_grad_penalty=True, gp_lambda=gp_lambda)
    without_gp = GAILLoss(_linear_discriminator(weight), use_grad_penalty=False)
    batch = gail_discriminator_batch(with_gp, transitions, transitions)
    out = with_gp(batch)

    x = torch.cat([transitions["observation"], transitions["action"]], -1)
    d = torch.sigmoid(x @ weight)
    grad_norm = d * (1 - d) * weight.norm()  # |dD/dx| of a logistic model
    expected_gp = gp_lambda * ((grad_norm - 1) ** 2).mean()
    assert out["gp_loss"] > 0
    torch.testing.assert_close(out["gp_loss"], expected_gp)
    torch.testing.assert_close(out["loss"] - without_gp(batch)["loss"], expected_gp)
    out["loss"].backward()
    without_gp(batch)["loss"].backward()
    grad_with = next(with_gp.parameters()).grad
    grad_without = next(without_gp.parameters()).grad
    assert not torch.allclose(grad_with, grad_without), "the penalty must reach the discriminator's weights"


def test_discriminator_reward_is_minus_log_one_minus_d_without_dropout():
    torch.manual_seed(0)
    discriminator = make_gail_discriminator(OBS_DIM, SPEC, hidden=16, dropout=0.2)
    reward = DiscriminatorReward(discriminator)
    rollout = TensorDict({"observation": torch.randn(5, OBS_DIM), "action": SPEC.rand((5,))}, [5])
    r1 = reward(rollout.clone())["next", "reward"]
    r2 = reward(rollout.clone())["next", "reward"]
    discriminator.eval()
    with torch.no_grad():
        d = discriminator(rollout.clone())["d_logits"]
    torch.testing.assert_close(r1, -torch.log(1 - d))
    torch.testing.assert_close(r1, r2)
    discriminator.train()
    reward(rollout.clone())
    assert discriminator.training, "the discriminator's mode must be restored"


def test_gail_wiring_uses_paper_settings_and_feeds_discriminator_reward_to_gae():
    torch.manual_seed(0)
    gail = make_gail_losses(
        make_tanh_gaussian_actor(OBS_DIM, SPEC, hidden=8, num_blocks=1),
        make_gail_value_network(OBS_DIM, hidden=8),
        make_gail_discriminator(OBS_DIM, SPEC, hidden=8),
    )
    assert gail.discriminator.use_grad_penalty and gail.discriminator.gp_lambda == 5.0
    ppo = gail.policy
    assert ppo.entropy_coeff.item() == pytest.approx(1e-2) and ppo.critic_coeff.item() == pytest.approx(0.5)
    assert ppo.clip_epsilon.item() == pytest.approx(0.2) and ppo.normalize_advantage
    assert ppo.value_estimator.gamma.item() == pytest.approx(0.99)
    assert ppo.value_estimator.lmbda.item() == pytest.approx(0.95)

    horizon = 6
    terminated = torch.zeros(1, horizon, 1, dtype=torch.bool)
    terminated[0, -1] = True
    rollout = TensorDict(
        {
            "observation": torch.randn(1, horizon, OBS_DIM),
            "next": {"observation": torch.randn(1, horizon, OBS_DIM), "done": terminated.clone(), "terminated": terminated},
        },
        [1, horizon],
    )
    with torch.no_grad(), set_exploration_type(ExplorationType.RANDOM):
        rollout = ppo.actor_network(rollout)
        rollout = ppo.value_estimator(gail.reward(rollout))
    # At the terminal step the GAE value target is the reward itself.
    torch.testing.assert_close(rollout["value_target"][0, -1], rollout["next", "reward"][0, -1])
    assert (rollout["next", "reward"] > 0).all()
    ppo_out = ppo(rollout.reshape(-1))
    assert {"loss_objective", "loss_critic", "loss_entropy"} <= set(ppo_out.keys())


def test_gail_pairing_rejects_unequal_batches():
    loss = GAILLoss(make_gail_discriminator(OBS_DIM, SPEC, hidden=8))
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
