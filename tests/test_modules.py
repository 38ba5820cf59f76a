"""Networks and TorchRL factories: structure from the paper's Appendix E, keys, bounds, invariants."""

from __future__ import annotations

import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st
from tensordict import TensorDict
from torch import nn
from torchrl.data import Bounded, Composite, Unbounded
from torchrl.envs.utils import ExplorationType, set_exploration_type

from torchrl_causal.modules import (
    ResidualBlock,
    ResidualMLP,
    SkipMLP,
    Standardize,
    bounded_action_spec,
    fit_standardizers,
    make_deterministic_actor,
    make_gail_discriminator,
    make_gail_value_network,
    make_qvalue_network,
    make_tanh_gaussian_actor,
)

SPEC = Bounded(torch.tensor([-0.4, -2.0]), torch.tensor([0.4, 1.0]), shape=(2,))
CENTER = (SPEC.space.high + SPEC.space.low) / 2
HALF_RANGE = (SPEC.space.high - SPEC.space.low) / 2


def obs_td(n: int = 5, dim: int = 3, seed: int = 0) -> TensorDict:
    return TensorDict({"observation": torch.randn(n, dim, generator=torch.Generator().manual_seed(seed))}, [n])


def test_residual_block_has_the_paper_layer_order():
    block = ResidualBlock(8, dropout=0.05)
    # The linear layers are AutocastLinear (an nn.Linear that may compute in bf16): the order is the point.
    kinds = [nn.Linear if isinstance(m, nn.Linear) else type(m) for m in block.body]
    assert kinds == [nn.LayerNorm, nn.SiLU, nn.Linear, nn.LayerNorm, nn.SiLU, nn.Dropout, nn.Linear]
    assert block.body[5].p == 0.05


def test_residual_block_is_identity_when_its_last_layer_is_zero():
    block = ResidualBlock(8)
    nn.init.zeros_(block.body[-1].weight)
    nn.init.zeros_(block.body[-1].bias)
    x = torch.randn(4, 8)
    torch.testing.assert_close(block(x), x)


def test_residual_mlp_is_projection_blocks_head_on_concatenated_inputs():
    net = ResidualMLP(5, 2, hidden=16, num_blocks=3, dropout=0.1)
    assert len(net.blocks) == 3 and all(b.body[5].p == 0.1 for b in net.blocks)
    assert net.projection.out_features == 16 and net.head.in_features == 16
    net.eval()
    obs, act = torch.randn(4, 3), torch.randn(4, 2)
    expected = net.head(net.blocks(net.projection(torch.cat([obs, act], -1))))
    torch.testing.assert_close(net(obs, act), expected)


@settings(max_examples=25, deadline=None)
@given(
    samples=st.integers(2, 5),
    batch=st.integers(1, 6),
    obs_dim=st.integers(1, 9),
    act_dim=st.integers(1, 3),
    expanded=st.sampled_from(["observation", "action", "both"]),
    seed=st.integers(0, 2**16),
)
def test_residual_mlp_on_an_expanded_input_equals_the_materialised_input(samples, batch, obs_dim, act_dim, expanded, seed):
    # IQ-Learn's K-sample pass expands each state beside K actions; the shared-input
    # projection must give the values and gradients of the plain concatenation. In float64
    # the two summation orders agree far inside the default tolerance for any weights; in
    # float32 the gradients of large-norm nets differ by rounding near that tolerance.
    generator = torch.Generator().manual_seed(seed)
    with torch.random.fork_rng():
        torch.manual_seed(seed)
        net = ResidualMLP(obs_dim + act_dim, 1, hidden=8, num_blocks=2).double()
    obs = torch.randn(batch, obs_dim, generator=generator, dtype=torch.float64)
    act = torch.randn(samples, batch, act_dim, generator=generator, dtype=torch.float64)
    obs = obs.expand(samples, batch, obs_dim)
    if expanded != "observation":
        act = act[:1].expand(samples, batch, act_dim)
    if expanded == "action":
        obs = obs.contiguous()
    expected_net = ResidualMLP(obs_dim + act_dim, 1, hidden=8, num_blocks=2).double()
    expected_net.load_state_dict(net.state_dict())
    out = net(obs, act)
    expected = expected_net.head(expected_net.blocks(expected_net.projection(torch.cat([obs, act], -1))))
    assert out.shape == (samples, batch, 1)
    torch.testing.assert_close(out, expected)
    out.square().sum().backward()
    expected.square().sum().backward()
    for (name, param), reference in zip(net.named_parameters(), expected_net.parameters()):
        torch.testing.assert_close(param.grad, reference.grad, msg=name)


def test_residual_mlp_names_a_wrong_input_size():
    with pytest.raises(ValueError, match="expects 5 input features, got 4"):
        ResidualMLP(5, 1, hidden=8)(torch.zeros(2, 4))
    with pytest.raises(ValueError, match="dropout"):
        ResidualMLP(5, 1, dropout=1.0)


def test_dropout_is_active_in_train_mode_only():
    net = ResidualMLP(3, 4, hidden=32, num_blocks=2, dropout=0.5)
    x = torch.randn(6, 3)
    torch.manual_seed(0)
    assert not torch.allclose(net(x), net(x))
    net.eval()
    torch.testing.assert_close(net(x), net(x))


def test_skip_mlp_skips_around_the_middle_layer():
    net = SkipMLP(4, 1, hidden=8, dropout=0.2)
    assert sum(isinstance(m, nn.Linear) for m in net.modules()) == 3
    assert all(isinstance(m, nn.ReLU) for m in (net.input_layer[1], net.hidden_layer[1]))
    assert net.input_layer[2].p == net.hidden_layer[2].p == 0.2
    net.eval()
    nn.init.zeros_(net.hidden_layer[0].weight)
    nn.init.zeros_(net.hidden_layer[0].bias)
    x = torch.randn(3, 4)
    # With the middle layer silenced only the skip path is left.
    torch.testing.assert_close(net(x), net.head(net.input_layer(x)))


def test_tanh_gaussian_actor_scale_is_state_independent_and_learnable():
    actor = make_tanh_gaussian_actor(3, SPEC, hidden=16, num_blocks=2, log_std_init=-0.5)
    td = actor(obs_td())
    assert torch.allclose(td["scale"], td["scale"][:1].expand_as(td["scale"]))
    torch.testing.assert_close(td["scale"][0], torch.full((2,), -0.5).exp())
    log_std = [p for n, p in actor.named_parameters() if "state_independent_scale" in n]
    assert len(log_std) == 1 and log_std[0].shape == (2,)
    td["action_log_prob"].sum().backward()
    assert log_std[0].grad is not None and log_std[0].grad.abs().sum() > 0


def test_tanh_gaussian_actor_paper_defaults_and_keys():
    actor = make_tanh_gaussian_actor(3, SPEC)
    body = actor.module[0].module[0]
    assert body.projection.out_features == 256 and len(body.blocks) == 3
    assert body.blocks[0].body[5].p == 0.05
    td = actor(obs_td())
    assert {"loc", "scale", "action", "action_log_prob"} <= set(td.keys())


def test_tanh_gaussian_actor_squashes_to_non_unit_bounds():
    actor = make_tanh_gaussian_actor(3, SPEC, hidden=16, num_blocks=1, log_std_init=1.0)
    actions = actor(obs_td(n=2000))["action"]
    assert (actions >= SPEC.space.low).all() and (actions <= SPEC.space.high).all()
    # A wide Gaussian fills most of each (asymmetric) interval.
    assert (actions.max(0).values - actions.min(0).values > 1.6 * HALF_RANGE).all()
    with set_exploration_type(ExplorationType.DETERMINISTIC):
        td = actor(obs_td())
    torch.testing.assert_close(td["action"], CENTER + HALF_RANGE * torch.tanh(td["loc"]))


def test_deterministic_actor_is_tanh_of_the_network_scaled_to_bounds():
    actor = make_deterministic_actor(3, SPEC, hidden=16, num_blocks=2)
    body = actor[0].module
    assert len(body.blocks) == 2
    td = obs_td()
    with torch.no_grad():
        expected = CENTER + HALF_RANGE * torch.tanh(body(td["observation"]))
        torch.testing.assert_close(actor(td.clone())["action"], expected)
    assert len(make_deterministic_actor(3, SPEC)[0].module.blocks) == 4  # paper's BC depth


@settings(max_examples=25, deadline=None)
@given(rows=st.integers(2, 40), features=st.integers(2, 6), seed=st.integers(0, 2**31 - 1))
def test_standardize_gives_zero_mean_unit_deviation_on_its_fitting_data(rows, features, seed):
    generator = torch.Generator().manual_seed(seed)
    samples = torch.randn(rows, features, generator=generator, dtype=torch.float64) * 10.0 ** torch.arange(features) + 3
    samples[:, 0] = 7.0  # a constant feature is centred, not divided by ~0
    out = Standardize(features).double().fit(samples)(samples)
    torch.testing.assert_close(out.mean(0), torch.zeros(features, dtype=torch.float64), atol=1e-9, rtol=0)
    torch.testing.assert_close(out[:, 1:].std(0), torch.ones(features - 1, dtype=torch.float64))
    assert (out[:, 0] == 0).all()


def test_standardized_deterministic_actor_carries_its_statistics_in_its_state_dict():
    plain = make_deterministic_actor(3, SPEC, hidden=16, num_blocks=1)
    standardized = make_deterministic_actor(3, SPEC, hidden=16, num_blocks=1, standardize_observation=True)
    assert not any(isinstance(m, Standardize) for m in plain.modules())
    samples = torch.tensor([[0.0, 10.0, -1.0], [2.0, 30.0, -1.0], [4.0, 20.0, -1.0]])
    assert fit_standardizers(standardized, samples) == 1 and fit_standardizers(plain, samples) == 0
    standardize, network = standardized[0].module
    torch.testing.assert_close(standardize.loc, torch.tensor([2.0, 20.0, -1.0]))
    torch.testing.assert_close(standardize.scale, torch.tensor([2.0, 10.0, 1.0]))
    restored = make_deterministic_actor(3, SPEC, hidden=16, num_blocks=1, standardize_observation=True)
    restored.load_state_dict(standardized.state_dict())
    td = TensorDict({"observation": samples}, [3])
    with torch.no_grad():
        torch.testing.assert_close(restored(td.clone())["action"], standardized(td.clone())["action"])
        expected = CENTER + HALF_RANGE * torch.tanh(network((samples - standardize.loc) / standardize.scale))
        torch.testing.assert_close(standardized(td.clone())["action"], expected)
    with pytest.raises(ValueError, match=r"needs \(n >= 2, 3\) samples"):
        standardize.fit(samples[:1])


def test_qvalue_network_reads_observation_then_action():
    q = make_qvalue_network(3, SPEC, hidden=16, num_blocks=1)
    td = obs_td()
    td["action"] = SPEC.rand((5,))
    out = q(td.clone())["state_action_value"]
    assert out.shape == (5, 1)
    torch.testing.assert_close(out, q.module(torch.cat([td["observation"], td["action"]], -1)))
    td2 = td.clone()
    td2["action"] = -td["action"]
    assert not torch.allclose(q(td2)["state_action_value"], out)


def test_gail_value_network_is_a_three_layer_relu_mlp():
    v = make_gail_value_network(3, hidden=16)
    linears = [m for m in v.module.modules() if isinstance(m, nn.Linear)]
    assert [(m.in_features, m.out_features) for m in linears] == [(3, 16), (16, 16), (16, 1)]
    assert sum(isinstance(m, nn.ReLU) for m in v.module.modules()) == 2
    assert v(obs_td())["state_value"].shape == (5, 1)


def test_gail_discriminator_outputs_an_unbounded_logit_under_gail_loss_key():
    d = make_gail_discriminator(3, SPEC, hidden=16)
    assert d.module.input_layer[2].p == 0.2
    assert isinstance(d.module.output_activation, nn.Identity)  # logits: no sigmoid
    td = obs_td()
    td["action"] = SPEC.rand((5,))
    with torch.no_grad():
        d.module.head.bias.fill_(-3.0)  # a logit a sigmoid output could never produce
    logits = d(td)["d_logits"]
    assert logits.shape == (5, 1) and (logits < 0).any()


def test_action_spec_errors_name_the_problem():
    assert bounded_action_spec(Composite(action=SPEC)) is SPEC
    with pytest.raises(KeyError, match="'act'"):
        bounded_action_spec(Composite(action=SPEC), "act")
    with pytest.raises(TypeError, match="continuous Bounded"):
        make_tanh_gaussian_actor(3, Unbounded(shape=(2,)))
    with pytest.raises(ValueError, match="finite bounds"):
        bounded_action_spec(Bounded(-float("inf"), 1.0, shape=(2,)))


def test_batched_env_action_spec_gives_per_step_bounds():
    batched = Bounded(SPEC.space.low.expand(4, 2), SPEC.space.high.expand(4, 2), shape=(4, 2))
    per_step = bounded_action_spec(batched)
    assert per_step.shape == (2,) and torch.equal(per_step.space.low, SPEC.space.low)
    actor = make_tanh_gaussian_actor(3, batched, hidden=8, num_blocks=1)
    assert actor(obs_td(n=7))["action"].shape == (7, 2)
    low = torch.tensor([[-1.0, -1.0], [-2.0, -1.0]])
    with pytest.raises(ValueError, match="different bounds across its batch"):
        bounded_action_spec(Bounded(low, torch.ones(2, 2), shape=(2, 2)))


@settings(max_examples=15, deadline=None)
@given(
    obs_dim=st.integers(1, 6),
    act_dim=st.integers(1, 4),
    num_blocks=st.integers(0, 3),
    half_range=st.floats(0.1, 5.0),
    batch=st.integers(1, 5),
)
def test_actor_actions_stay_in_bounds_for_any_shape(obs_dim, act_dim, num_blocks, half_range, batch):
    spec = Bounded(-half_range, half_range, shape=(act_dim,))
    actor = make_tanh_gaussian_actor(obs_dim, spec, hidden=8, num_blocks=num_blocks, log_std_init=2.0)
    td = actor(TensorDict({"observation": 10 * torch.randn(batch, obs_dim)}, [batch]))
    assert td["action"].shape == (batch, act_dim)
    assert (td["action"].abs() <= half_range).all() and torch.isfinite(td["action_log_prob"]).all()
