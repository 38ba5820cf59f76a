"""Confounded Route Choice: the paper's appendix table, exactly, and the env that realises it."""

from __future__ import annotations

import math
from fractions import Fraction
from itertools import product

import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st
from tensordict import TensorDict
from torchrl.envs import TransformedEnv
from torchrl.envs.utils import check_env_specs

from torchrl_causal.envs import RouteChoiceEnv, route_choice_value

TRAIN, DEPLOY = Fraction(1, 4), Fraction(3, 4)


def training_conditional(given_w: bool):
    """P_tr(X = 1 | z[, w]) under the expert X = Z xor O, by enumeration of the example's SCM
    (Z ~ Bern(1/2), O ~ Bern(2/3), U ~ Bern(1/4), W = O xor U), written from the paper's text."""
    joint: dict[tuple[int, int], list[Fraction]] = {}
    for z, o, u in product((0, 1), repeat=3):
        p = Fraction(1, 2) * (Fraction(2, 3) if o else Fraction(1, 3)) * (TRAIN if u else 1 - TRAIN)
        cell = joint.setdefault((z, o ^ u if given_w else 0), [Fraction(0), Fraction(0)])
        cell[z ^ o] += p
    return lambda z, o, w: joint[(z, w if given_w else 0)][1] / sum(joint[(z, w if given_w else 0)])


EXPERT = lambda z, o, w: float(z ^ o)  # noqa: E731
PI_C = training_conditional(given_w=False)
PI_C_HAT = lambda z, o, w: float(PI_C(z, o, w) > Fraction(1, 2))  # noqa: E731
PI_N = training_conditional(given_w=True)
PI_N_HAT = lambda z, o, w: float(z ^ w)  # noqa: E731

TABLE = [  # (policy, train value, deploy value): the paper's Table "orthogonality-values"
    ("expert", EXPERT, Fraction(3, 4), Fraction(7, 12)),
    ("pi_c", PI_C, Fraction(3, 4), Fraction(7, 12)),
    ("pi_c_hat", PI_C_HAT, Fraction(3, 4), Fraction(3, 4)),
    ("pi_n", PI_N, Fraction(101, 140), Fraction(31, 60)),
    ("pi_n_hat", PI_N_HAT, Fraction(11, 16), Fraction(19, 48)),
]


def test_training_conditionals_match_the_example():
    # P_tr(X = z | z, W = 0) = 3/5 and P_tr(X = 1 - z | z, W = 1) = 6/7, as derived in the paper
    for z in (0, 1):
        assert PI_N(z, None, 0) == (Fraction(3, 5) if z == 1 else Fraction(2, 5))
        assert PI_N(z, None, 1) == (Fraction(6, 7) if z == 0 else Fraction(1, 7))
        assert PI_C(z, None, None) == (Fraction(2, 3) if z == 0 else Fraction(1, 3))
    assert PI_N_HAT(0, None, 1) == float(PI_N(0, None, 1) > Fraction(1, 2))  # the compass-follower is the argmax


@pytest.mark.parametrize(("name", "policy", "train", "deploy"), TABLE, ids=[row[0] for row in TABLE])
def test_appendix_table_exact(name, policy, train, deploy):
    assert route_choice_value(policy, TRAIN) == train
    assert route_choice_value(policy, DEPLOY) == deploy


@settings(max_examples=30, deadline=None)
@given(numerator=st.integers(0, 97))
def test_closed_forms_in_the_wind_probability(numerator):
    s = Fraction(numerator, 97)
    assert route_choice_value(EXPERT, s) == Fraction(1, 2) + (1 - s) / 3
    assert route_choice_value(PI_C, s) == Fraction(1, 2) + (1 - s) / 3
    assert route_choice_value(PI_C_HAT, s) == Fraction(3, 4)
    assert route_choice_value(PI_N, s) == (1 - s) * Fraction(173, 210) + s * Fraction(87, 210)
    assert route_choice_value(PI_N_HAT, s) == (1 - s) * Fraction(5, 6) + s * Fraction(1, 4)


def test_value_rejects_bad_inputs():
    with pytest.raises(ValueError, match="wind_probability"):
        route_choice_value(EXPERT, 1.5)
    with pytest.raises(ValueError, match="policy"):
        route_choice_value(lambda z, o, w: 2.0, TRAIN)


@pytest.mark.parametrize("regime", ["train", "deploy"])
def test_specs_and_single_step_episodes(regime):
    env = RouteChoiceEnv(batch_size=(8,), regime=regime, seed=0)
    check_env_specs(env)
    rollout = env.rollout(3, break_when_any_done=False)
    assert rollout["next", "terminated"].all() and not rollout["next", "truncated"].any()
    assert torch.equal(rollout["W"], (rollout["latent", "O"] != rollout["scm", "U"]).float())
    with pytest.raises(ValueError, match="horizon"):
        RouteChoiceEnv(batch_size=(2,), horizon=2)


def test_deploy_wind_interpolates_with_strength():
    assert RouteChoiceEnv(batch_size=(1,), regime="train").wind_probability == TRAIN
    assert RouteChoiceEnv(batch_size=(1,), regime="deploy").wind_probability == DEPLOY
    assert RouteChoiceEnv(batch_size=(1,), regime="deploy", confounding_strength=0.0).wind_probability == TRAIN
    assert RouteChoiceEnv(batch_size=(1,), regime="deploy", confounding_strength=0.5).wind_probability == Fraction(1, 2)


def _sampling_policy(probability, generator):
    """A TensorDict policy drawing X ~ Bern(probability(z, o, w)) from the env's keys."""
    table = torch.tensor([[[float(probability(z, o, w)) for w in (0, 1)] for o in (0, 1)] for z in (0, 1)], dtype=torch.float32)

    def act(td):
        z, o, w = (td.get(key).long() for key in ("Z", ("latent", "O"), "W"))
        p_one = table[z, o, w]
        return td.set("action", (torch.rand(p_one.shape, generator=generator) < p_one).float())

    return act


@pytest.mark.parametrize(("name", "policy", "train", "deploy"), TABLE, ids=[row[0] for row in TABLE])
def test_monte_carlo_rollouts_agree_with_the_exact_values(name, policy, train, deploy):
    n = 20_000
    for regime, exact in (("train", train), ("deploy", deploy)):
        env = RouteChoiceEnv(batch_size=(n,), regime=regime, seed=1)
        rollout = env.rollout(1, _sampling_policy(policy, torch.Generator().manual_seed(2)))
        mean = rollout["next", "reward"].mean().item()
        standard_error = math.sqrt(float(exact * (1 - exact)) / n)
        assert abs(mean - float(exact)) < 3 * standard_error, (name, regime, mean, float(exact))


def _fit_classifier(features: torch.Tensor, targets: torch.Tensor, steps: int = 300) -> torch.nn.Module:
    torch.manual_seed(0)
    model = torch.nn.Sequential(torch.nn.Linear(features.shape[-1], 16), torch.nn.Tanh(), torch.nn.Linear(16, 1))
    optimiser = torch.optim.Adam(model.parameters(), lr=0.05)
    for _ in range(steps):
        optimiser.zero_grad()
        torch.nn.functional.binary_cross_entropy_with_logits(model(features), targets).backward()
        optimiser.step()
    return model


@pytest.mark.parametrize(("causal", "deploy_value"), [(False, Fraction(19, 48)), (True, Fraction(3, 4))])
def test_behaviour_cloning_through_the_causal_window(causal, deploy_value):
    """BC on expert demonstrations, encoded by CausalWindowTransform: the non-causal encoding
    (Z, W) learns to follow the compass (19/48 at deployment), the causal one (Z) the sheltered
    route (3/4), exactly as the paper's example predicts."""
    from torchrl_causal.transforms import CausalWindowTransform

    n = 4000
    train_env = RouteChoiceEnv(batch_size=(n,), regime="train", seed=3)
    demonstrations = train_env.rollout(1, _sampling_policy(EXPERT, torch.Generator().manual_seed(4))).reshape(-1)
    demonstrations.set("is_init", torch.ones(n, 1, dtype=torch.bool))
    transform = CausalWindowTransform.from_env(train_env, k=0, causal=causal)
    assert ("W" in transform.window.lags) is not causal
    encoded = transform.encode_trajectories(demonstrations)
    model = _fit_classifier(encoded["observation"], demonstrations["action"])

    # The learned deterministic policy, read back as a function of (z, w), has the exact value.
    def learned(z, o, w):
        state = {"Z": torch.tensor([[float(z)]]), "W": torch.tensor([[float(w)]])}
        probe = TensorDict({**state, "next": state, "action": torch.zeros(1, 1), "is_init": torch.ones(1, 1, dtype=torch.bool)}, [1])
        return float(model(transform.encode_trajectories(probe)["observation"]).item() > 0)

    assert route_choice_value(learned, DEPLOY) == deploy_value

    # And it earns that value when rolled out in the deployment env through the transform.
    deploy_env = TransformedEnv(
        RouteChoiceEnv(batch_size=(n,), regime="deploy", seed=5), CausalWindowTransform.from_env(train_env, k=0, causal=causal)
    )
    with torch.no_grad():
        rollout = deploy_env.rollout(1, lambda td: td.set("action", (model(td["observation"]) > 0).float()))
    exact = float(deploy_value)
    assert abs(rollout["next", "reward"].mean().item() - exact) < 3 * math.sqrt(exact * (1 - exact) / n)
