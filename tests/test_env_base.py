"""The SCM layer shared by every confounded env: validation, seeding, horizon, gusts, compass."""

from __future__ import annotations

import math

import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st
from torchrl.data import Bounded, Unbounded
from torchrl.envs.utils import check_env_specs

from torchrl_causal.envs import CompassSensor, GustConfoundedEnv, GustProcess, rotate


class DriftEnv(GustConfoundedEnv):
    """A minimal gust env: a point that drifts by the action, succeeds beyond radius 3."""

    slice_template = None  # the base never reads it

    def _make_variable_specs(self):
        batch = self.batch_size
        variables = {
            "P": Unbounded(shape=(*batch, 2)),
            "W": Unbounded(shape=(*batch, 2)),
            ("latent", "O"): Unbounded(shape=(*batch, 2)),
        }
        return Bounded(-1.0, 1.0, shape=(*batch, 2)), variables

    def _reset_state(self, mask):
        fresh = torch.zeros((*self.batch_size, 2))
        self.point = torch.where(mask, fresh, getattr(self, "point", fresh))

    def _transition(self, action):
        self.point = self.point + action
        distance = self.point.norm(dim=-1, keepdim=True)
        success = distance > 3.0
        return self.maze_reward(success, distance), success

    def _observation(self):
        east = torch.tensor([1.0, 0.0]).expand(*self.batch_size, 2)
        return {"P": self.point.clone(), "W": self.read_compass(east), "latent": {"O": east.clone()}, **self.scm_observation()}


@pytest.mark.parametrize("batch_size", [(), (3,), (2, 3)])
@pytest.mark.parametrize("regime", ["train", "deploy"])
def test_specs_hold_for_any_batch_shape(batch_size, regime):
    env = DriftEnv(batch_size=batch_size, regime=regime, horizon=5, seed=0)
    check_env_specs(env)
    rollout = env.rollout(12, break_when_any_done=False)
    assert rollout.shape == (*batch_size, 12)
    assert rollout["success"].dtype == torch.bool and rollout["success"].shape == (*batch_size, 12, 1)


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"regime": "test"}, "regime"),
        ({"confounding_strength": 1.5}, "confounding_strength"),
        ({"confounding_strength": -0.1}, "confounding_strength"),
        ({"horizon": 0}, "horizon"),
        ({"horizon": 2.5}, "horizon"),
    ],
)
def test_bad_arguments_are_named(kwargs, message):
    with pytest.raises(ValueError, match=message):
        DriftEnv(batch_size=(2,), **kwargs)


def test_truncation_at_horizon_and_termination_on_success():
    env = DriftEnv(batch_size=(2,), horizon=4, seed=0)
    td = env.reset()
    td["action"] = torch.tensor([[0.0, 0.0], [1.0, 0.0]])  # env 1 reaches radius 3 at step 4
    flags = []
    for _ in range(4):
        td = env.step(td)
        flags.append([td["next", key].squeeze(-1).tolist() for key in ("terminated", "truncated", "success")])
        td = td["next"].set("action", td["action"])
    assert flags[2] == [[False, False], [False, False], [False, False]]
    # step 4: env 0 runs out of time (truncated), env 1 arrives (terminated, not truncated)
    assert flags[3] == [[False, True], [True, False], [False, True]]


def test_partial_reset_only_touches_masked_envs():
    env = DriftEnv(batch_size=(3,), horizon=50, seed=0)
    td = env.reset()
    td["action"] = torch.ones(3, 2) * 0.5
    td = env.step(td)["next"]
    before = td["P"].clone()
    td["_reset"] = torch.tensor([[True], [False], [False]])
    after = env.reset(td)
    assert after["P"][0].abs().sum() == 0
    assert torch.equal(after["P"][1:], before[1:])


def _half_east(td):
    return td.set("action", torch.tensor([0.5, 0.0]).expand(*td.shape, 2).clone())


def test_seed_reproduces_rollouts():
    rollouts = []
    for _ in range(2):
        env = DriftEnv(batch_size=(4,), regime="deploy", horizon=7, seed=123)
        rollouts.append(env.rollout(30, _half_east, break_when_any_done=False))
    assert torch.equal(rollouts[0]["W"], rollouts[1]["W"])
    assert torch.equal(rollouts[0]["scm", "U"], rollouts[1]["scm", "U"])


def test_gust_process_statistics():
    process = GustProcess()
    g = torch.Generator().manual_seed(0)
    n_envs, steps = 4000, 40
    gust = process.draw((n_envs,), generator=g)
    history = [gust]
    for step in range(1, steps):
        gust = process.advance(gust, torch.full((n_envs, 1), step), generator=g)
        history.append(gust)
    gusts = torch.stack(history, dim=1)  # [n_envs, steps, 2]
    blocks = gusts.reshape(n_envs, steps // process.period, process.period, 2)
    # piecewise constant: every block of 5 steps starting at a multiple of 5 holds one value
    assert torch.equal(blocks, blocks[:, :, :1].expand_as(blocks))
    first = blocks[:, :, 0].reshape(-1, 2)
    magnitude = first.norm(dim=-1)
    active = magnitude > 0
    n = active.numel()
    assert abs(active.float().mean().item() - 0.05) < 3 * math.sqrt(0.05 * 0.95 / n)
    assert ((magnitude[active] >= 2.0) & (magnitude[active] <= 5.0)).all()
    # magnitude ~ U[2, 5]: mean 3.5, sd sqrt(0.75); direction uniform: mean unit vector ~ 0
    k = int(active.sum())
    assert abs(magnitude[active].mean().item() - 3.5) < 4 * math.sqrt(0.75 / k)
    assert GustProcess.direction(first[active]).mean(0).norm().item() < 4 / math.sqrt(k)


def test_gust_process_rejects_bad_parameters():
    with pytest.raises(ValueError, match="probability"):
        GustProcess(probability=1.5)
    with pytest.raises(ValueError, match="period"):
        GustProcess(period=0)


def test_compass_mixes_signal_gust_and_noise():
    sensor = CompassSensor()
    g = torch.Generator().manual_seed(0)
    n = 20000
    angle = torch.rand(n, 1, generator=g) * 2 * math.pi
    signal = torch.cat((angle.cos(), angle.sin()), -1)
    gust = torch.tensor([[0.0, 3.0]]).expand(n, 2)  # a northward gust of magnitude 3
    reading = sensor.read(signal, gust, rotation=0.0, generator=g)
    raw = torch.atanh(reading.clamp(-0.999999, 0.999999))
    residual = raw - 0.9 * signal - 0.1 * torch.tensor([0.0, 1.0])
    assert residual.mean(0).abs().max() < 4 * 0.05 / math.sqrt(n)
    assert abs(residual.std().item() - 0.05) < 0.002


@settings(max_examples=25, deadline=None)
@given(strength=st.floats(0.0, 1.0), seed=st.integers(0, 2**31))
def test_deploy_rotates_the_compass_by_strength_pi(strength, seed):
    readings = {}
    for regime in ("train", "deploy"):
        env = DriftEnv(batch_size=(6,), regime=regime, confounding_strength=strength, horizon=10, seed=seed)
        readings[regime] = env.rollout(10, _half_east, break_when_any_done=False)["W"]
    expected = rotate(readings["train"], strength * math.pi)
    torch.testing.assert_close(readings["deploy"], expected, atol=1e-6, rtol=0)
    if strength == 0.0:
        assert torch.equal(readings["deploy"], readings["train"])


@settings(max_examples=50, deadline=None)
@given(angle=st.floats(-10, 10), other=st.floats(-10, 10))
def test_rotate_preserves_norm_and_composes(angle, other):
    vectors = torch.tensor([[1.0, 0.0], [0.3, -0.7], [2.0, 5.0]], dtype=torch.float64)
    rotated = rotate(vectors, angle)
    torch.testing.assert_close(rotated.norm(dim=-1), vectors.norm(dim=-1))
    torch.testing.assert_close(rotate(rotated, other), rotate(vectors, angle + other))
