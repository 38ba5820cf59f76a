"""The P(U)-shift deployment of the gust-confounded mazes (``shift="prior"``) beside the
default compass rotation: the default path is the rotation SCM as it was, only P(U) moves
under the prior shift, W leans on the wind in training, strength 0 makes W a faithful heading,
the diagram is the same, and the config selects it (or refuses a bad value in one line)."""

from __future__ import annotations

import math
from dataclasses import dataclass

import pytest
import torch

from torchrl_causal.envs import AntMazeEnv, HumanoidMazeEnv, RoverMazeEnv
from torchrl_causal.envs.base import (
    CompassSensor,
    DivertedCompass,
    GustConfoundedEnv,
    GustProcess,
    PrevailingGustProcess,
    PriorShift,
    rotate,
)
from torchrl_causal.errors import InvalidValueError
from torchrl_causal.experiment import compose_config
from torchrl_causal.experiment.builders import make_env
from torchrl_causal.experiment.schema import ConfigValueError, validate_config
from torchrl_causal.transforms import imitator_window

BATCH, STEPS = 64, 60


def _constant_policy(batch: int):
    action = torch.linspace(-0.6, 0.8, 2 * batch).reshape(batch, 2)
    return lambda td: td.set("action", action)


def _rover_rollout(env: RoverMazeEnv):
    return env.rollout(STEPS, _constant_policy(env.batch_size[0]), break_when_any_done=False)


# ---------------------------------------------------------------- the default is the rotation, as it was


@dataclass(frozen=True)
class LegacyGusts:
    """The rotation regime's gust process written out as it was before the shift option."""

    period: int = 5
    probability: float = 0.05
    low: float = 2.0
    high: float = 5.0

    def draw(self, shape, *, generator=None, device=None, dtype=torch.float32):
        active, magnitude, angle = torch.rand((*shape, 3), generator=generator, device=device, dtype=dtype).unbind(-1)
        magnitude = torch.where(active < self.probability, self.low + (self.high - self.low) * magnitude, torch.zeros_like(magnitude))
        angle = 2 * math.pi * angle
        return torch.stack((magnitude * torch.cos(angle), magnitude * torch.sin(angle)), dim=-1)

    def advance(self, gust, step_count, *, generator=None):
        fresh = self.draw(gust.shape[:-1], generator=generator, device=gust.device, dtype=gust.dtype)
        return torch.where(step_count % self.period == 0, fresh, gust)


@dataclass(frozen=True)
class LegacyCompass:
    """The rotation regime's compass written out as it was: 0.9 signal + 0.1 gust direction."""

    def read(self, signal, gust, *, rotation, generator=None):
        noise = torch.randn(signal.shape, generator=generator, device=signal.device, dtype=signal.dtype)
        norm = gust.norm(dim=-1, keepdim=True)
        direction = torch.where(norm > 0, gust / norm.clamp_min(1e-12), torch.zeros_like(gust))
        return rotate(torch.tanh(0.9 * signal + 0.1 * direction + 0.05 * noise), rotation)


@pytest.mark.parametrize("regime", ["train", "deploy"])
def test_the_default_shift_is_the_rotation_scm_bit_for_bit(regime: str) -> None:
    default = RoverMazeEnv("medium", batch_size=BATCH, regime=regime, confounding_strength=0.5, seed=11)
    legacy = RoverMazeEnv("medium", batch_size=BATCH, regime=regime, confounding_strength=0.5, seed=11)
    legacy.gust_process, legacy.compass = LegacyGusts(), LegacyCompass()  # type: ignore[misc]
    assert default.shift == "rotation" and "shift" not in default.config()  # records read as before the option
    assert default.compass_rotation == (0.5 * math.pi if regime == "deploy" else 0.0)
    ours, theirs = _rover_rollout(default), _rover_rollout(legacy)
    for key in (("next", "P"), ("next", "W"), ("next", "scm", "U"), ("next", "reward"), ("next", "latent", "O")):
        assert torch.equal(ours[key], theirs[key]), key


# ---------------------------------------------------------------- P(U) moves, nothing else


def _gust_statistics(process: GustProcess, windows: int, seed: int) -> tuple[float, torch.Tensor, int]:
    gusts = process.draw((windows,), generator=torch.Generator().manual_seed(seed))
    blowing = gusts.norm(dim=-1) > 0
    return float(blowing.float().mean()), GustProcess.direction(gusts[blowing]).mean(0), int(blowing.sum())


def test_the_gust_marginal_differs_between_the_regimes_as_specified() -> None:
    shift, windows = PriorShift(), 40_000
    means = {}
    for regime, seed in (("train", 1), ("deploy", 2)):
        process = shift.process(regime)
        assert isinstance(process, PrevailingGustProcess)
        frequency, mean, count = _gust_statistics(process, windows, seed)
        # binomial frequency within 4 standard errors of p
        assert abs(frequency - process.probability) <= 4 * math.sqrt(process.probability * (1 - process.probability) / windows)
        # mean unit direction within 4 standard errors (a unit vector's component has variance <= 1) of the closed form
        expected = torch.tensor(process.mean_direction())
        assert (mean - expected).abs().max() <= 4 / math.sqrt(count)
        means[regime] = mean
    # the prevailing directions are opposite: the means lie 2 * sinc(1/4) = 1.80 apart, against a few hundredths of noise
    spread = PriorShift().train.spread
    assert (means["train"] - means["deploy"]).norm() >= 2 * math.sin(math.pi * spread) / (math.pi * spread) - 8 / math.sqrt(windows * 0.25)
    assert float(means["train"] @ means["deploy"]) < 0


def test_the_rotation_keeps_p_u_and_the_prior_shift_moves_it_in_the_env() -> None:
    for shift, moves in (("rotation", False), ("prior", True)):
        gusts = {}
        for regime in ("train", "deploy"):
            env = RoverMazeEnv("medium", batch_size=BATCH, regime=regime, seed=5, shift=shift)
            assert env.gusts is (env.prior_shift.process(regime) if moves else GustConfoundedEnv.gust_process)
            u = _rover_rollout(env)["next", "scm", "U"].reshape(-1, 2)
            gusts[regime] = GustProcess.direction(u[u.norm(dim=-1) > 0]).mean(0)
        if moves:  # blowing towards +x+y in training, -x-y when deployed
            assert (gusts["train"] > 0.3).all() and (gusts["deploy"] < -0.3).all()
        else:
            assert torch.equal(gusts["train"], gusts["deploy"])  # the same draws in both regimes


def test_only_p_u_differs_between_the_regimes_of_the_prior_shift() -> None:
    train = RoverMazeEnv("medium", batch_size=BATCH, regime="train", confounding_strength=0.7, seed=3, shift="prior")
    deploy = RoverMazeEnv("medium", batch_size=BATCH, regime="deploy", confounding_strength=0.7, seed=3, shift="prior")
    assert deploy.compass_rotation == train.compass_rotation == 0.0 and deploy.sensor == train.sensor
    # Give the deployed env the training wind: W, dynamics and reward are then the same functions of U.
    deploy.prior_shift = PriorShift(train=train.prior_shift.train, deploy=train.prior_shift.train)  # type: ignore[misc]
    a, b = _rover_rollout(train), _rover_rollout(deploy)
    for key in (("next", "P"), ("next", "W"), ("next", "scm", "U"), ("next", "reward")):
        assert torch.equal(a[key], b[key]), key


# ---------------------------------------------------------------- W and U


def _tanh_direction_error(weight: float) -> float:
    """Largest angle (radians) between a unit vector and tanh(weight * it), on a dense grid."""
    angles = torch.linspace(-math.pi, math.pi, 100_001, dtype=torch.float64)
    squashed = torch.tanh(weight * torch.stack((angles.cos(), angles.sin()), -1))
    return float((torch.atan2(squashed[:, 1], squashed[:, 0]) - angles).remainder(2 * math.pi).sub(math.pi).abs().sub(math.pi).abs().max())


def _cosines_with_the_gust(td) -> torch.Tensor:
    w, u = td["next", "W"].reshape(-1, 2), td["next", "scm", "U"].reshape(-1, 2)
    blowing = u.norm(dim=-1) > 0
    return torch.nn.functional.cosine_similarity(w[blowing], u[blowing], dim=-1)


def test_w_follows_the_wind_in_training_at_full_strength() -> None:
    env = RoverMazeEnv("medium", batch_size=BATCH, regime="train", confounding_strength=1.0, seed=7, shift="prior")
    td = _rover_rollout(env)
    cosines = _cosines_with_the_gust(td)
    # At diversion 1 the needle is the gust's direction; tanh turns it by at most `error`, the
    # noise (sd 0.05 on a reading at least tanh(0.9 / sqrt 2) * sqrt 2 long) by 4 sd at most.
    sensor = DivertedCompass()
    shortest = math.tanh(sensor.signal_weight / math.sqrt(2)) * math.sqrt(2)
    bound = math.cos(_tanh_direction_error(sensor.signal_weight) + 4 * sensor.noise_std / shortest)
    assert float(cosines.mean()) >= bound > 0.9
    # the gust diverts W in about p = 25% of the training steps (the rotation regime: 5%)
    share = float((td["next", "scm", "U"].norm(dim=-1) > 0).float().mean())
    assert abs(share - env.gusts.probability) < 0.05
    # the rotation regime's W barely points along the gust (its gust weight is 0.1)
    rotation = RoverMazeEnv("medium", batch_size=BATCH, regime="train", seed=7)
    assert float(_cosines_with_the_gust(_rover_rollout(rotation)).mean()) < bound - 0.5


def test_the_needle_turns_by_strength_times_the_angle_to_the_wind() -> None:
    generator = torch.Generator().manual_seed(0)
    heading = torch.rand(4096, generator=generator) * 2 * math.pi - math.pi
    wind = torch.rand(4096, generator=generator) * 2 * math.pi - math.pi
    signal = torch.stack((heading.cos(), heading.sin()), -1)
    gust = 3.0 * torch.stack((wind.cos(), wind.sin()), -1)
    delta = (wind - heading + math.pi).remainder(2 * math.pi) - math.pi
    for strength in (0.0, 0.15, 0.5, 0.85, 1.0):
        needle = DivertedCompass(diversion=strength).needle(signal, gust)
        turned = torch.atan2(needle[:, 1], needle[:, 0])
        error = (turned - (heading + strength * delta) + math.pi).remainder(2 * math.pi) - math.pi
        assert error.abs().max() < 1e-4, strength
        # calm: the needle is the signal, whichever way it points (signed zeros included)
        assert torch.equal(DivertedCompass(diversion=strength).needle(signal, torch.zeros_like(gust)), signal), strength


def test_strength_zero_reads_the_heading_whatever_the_wind() -> None:
    generator = torch.Generator().manual_seed(1)
    signal = torch.nn.functional.normalize(torch.randn(1024, 2, generator=generator), dim=-1)
    calm, gusts = torch.zeros(1024, 2), PriorShift().train.draw((1024,), generator=generator)
    other = PriorShift().deploy.draw((1024,), generator=generator)
    sensor = DivertedCompass(diversion=0.0)
    readings = [sensor.read(signal, u, rotation=0.0, generator=torch.Generator().manual_seed(9)) for u in (calm, gusts, other)]
    assert torch.equal(readings[0], readings[1]) and torch.equal(readings[0], readings[2])  # W independent of U given the heading
    # and in the env, in both regimes: W is the noisy heading, the residual uncorrelated with the gust
    for regime in ("train", "deploy"):
        env = RoverMazeEnv("medium", batch_size=BATCH, regime=regime, confounding_strength=0.0, seed=4, shift="prior")
        td = _rover_rollout(env)
        residual = torch.atanh(td["next", "W"].clamp(-0.999, 0.999)) - 0.9 * td["next", "latent", "O"]
        assert residual.std() < 0.06  # the N(0, 0.05^2) noise alone
        u = td["next", "scm", "U"]
        blowing = u.norm(dim=-1) > 0
        correlation = (residual[blowing] * GustProcess.direction(u[blowing])).sum(-1)
        assert abs(float(correlation.mean())) <= 4 * 0.05 * math.sqrt(2) / math.sqrt(int(blowing.sum()))


def test_a_compass_diversion_outside_the_unit_interval_is_refused() -> None:
    with pytest.raises(InvalidValueError, match="diversion"):
        DivertedCompass(diversion=1.5)
    with pytest.raises(InvalidValueError, match="spread"):
        PrevailingGustProcess(spread=-0.1)


# ---------------------------------------------------------------- the diagram


@pytest.mark.parametrize("env_class", [RoverMazeEnv, AntMazeEnv, HumanoidMazeEnv])
def test_the_diagram_and_window_are_the_same_under_either_shift(env_class: type[GustConfoundedEnv]) -> None:
    shift = env_class.prior_shift
    # the period sets the bidirected edges; the prior shift keeps it
    assert shift.train.period == shift.deploy.period == env_class.gust_process.period
    template = env_class.slice_template()  # a class-level fact: no constructor argument enters it
    assert "W" in template.observed and not any(src == "W" for src, _, _ in template.directed)  # W a collider
    window = imitator_window(template, 2, causal=True, mode="relaxed", window_matched=False)
    assert "W" not in window.lags


# ---------------------------------------------------------------- constructors and the config


@pytest.mark.parametrize("env_class", [AntMazeEnv, HumanoidMazeEnv, RoverMazeEnv])
def test_a_bad_shift_is_refused_before_anything_is_built(env_class: type, monkeypatch) -> None:
    from torchrl_causal.envs import mujoco_maze

    def no_simulator(*args, **kwargs):
        raise AssertionError("built a simulator")

    monkeypatch.setattr(mujoco_maze, "MazeSimulator", no_simulator)
    with pytest.raises(InvalidValueError, match="shift must be one of .* got 'wind'"):
        env_class(shift="wind")


def test_the_ant_maze_takes_the_prior_shift() -> None:
    env = AntMazeEnv("medium", batch_size=2, regime="deploy", seed=0, shift="prior")
    td = env.rollout(3)
    assert env.config()["shift"] == "prior" and env.gusts is env.prior_shift.deploy
    assert td["next", "W"].shape == (2, 3, 2)
    rebuilt = AntMazeEnv.from_config(env.config(), batch_size=(1,))
    assert rebuilt.shift == "prior"


def test_the_config_selects_the_shift_and_keeps_its_runs_apart() -> None:
    default = compose_config(["env=rovermaze_medium"])
    prior = compose_config(["env=rovermaze_medium", "env.shift=prior"])
    for cfg in (default, prior):
        validate_config(cfg)
    assert default.env.shift is None and make_env(default, "deploy", 2, 0).shift == "rotation"
    env = make_env(prior, "deploy", 2, 0)
    assert env.shift == "prior" and env.gusts is env.prior_shift.deploy
    assert "-prior" not in default.run_name and "-prior" not in default.demos.path
    assert prior.run_name == default.run_name.replace("-cs1.0-", "-cs1.0-prior-")
    assert prior.demos.path == default.demos.path.replace("-cs1.0-", "-cs1.0-prior-")


@pytest.mark.parametrize(
    ("overrides", "named"),
    [
        (["env=rovermaze_medium", "env.shift=wind"], "env.shift='wind' is not a shift"),
        (["env=route_choice", "env.shift=prior"], "env.shift='prior' is for the gust-confounded mazes"),
    ],
)
def test_a_bad_shift_in_the_config_is_refused_in_one_line(overrides: list[str], named: str, tmp_path) -> None:
    from torchrl_causal.cli.train import main

    cfg = compose_config([f"run_root={tmp_path / 'runs'}", *overrides])
    with pytest.raises(ConfigValueError, match=named):
        validate_config(cfg)
    with pytest.raises(SystemExit) as stop:
        main.__wrapped__(cfg)
    message = str(stop.value.code)
    assert message.startswith("error: config value env.shift=") and "\n" not in message
    assert not (tmp_path / "runs").exists()


def test_the_sensors_share_one_reading_protocol() -> None:
    # The env reads W through either sensor with the same arguments and the same noise draw.
    signal, gust = torch.tensor([[1.0, 0.0]]), torch.zeros(1, 2)
    for sensor in (CompassSensor(gust_weight=0.0), DivertedCompass()):
        w = sensor.read(signal, gust, rotation=0.0, generator=torch.Generator().manual_seed(2))
        expected = torch.tanh(0.9 * signal + 0.05 * torch.randn((1, 2), generator=torch.Generator().manual_seed(2)))
        assert torch.allclose(w, expected, atol=1e-6)


@pytest.mark.parametrize(
    ("experiment", "job", "shift"),
    [
        ("antmaze_shift", ["row=c_sqil", "+recipe=goal_valued_bc_anchored"], "prior"),
        ("antmaze_strength", ["env=antmaze_large", "env.confounding_strength=0.15", "row=bc"], "prior"),
        ("antmaze_horizon", ["env=antmaze_large", "env.horizon=1500", "row=c_iq_learn", "+recipe=goal_valued_bc_anchored"], None),
    ],
)
def test_the_ablation_configs_train_at_the_2_core_budget_under_their_shift(experiment: str, job: list[str], shift: str | None) -> None:
    cfg = compose_config([f"experiment={experiment}", *job])
    validate_config(cfg)
    budget = compose_config(["env=antmaze_medium", "scale=cpu_ant"])
    assert cfg.env.shift == shift and cfg.eval.final_episodes == budget.eval.final_episodes
    # demonstrations at the run's own horizon, strength and shift
    assert f"-h{cfg.env.horizon}-cs{cfg.env.confounding_strength}{'-prior' if shift else ''}-n" in cfg.demos.path


@pytest.mark.parametrize("sensor", [CompassSensor(), DivertedCompass(diversion=0.4)], ids=["compass", "diverted"])
def test_each_sensor_reads_its_closed_form_to_the_bit(sensor) -> None:
    # W = rotate(tanh(weighted signal [+ gust] + noise_std * noise), rotation), the noise drawn
    # first from the generator: written out here per sensor, independently of GustSensor.read.
    generator = torch.Generator().manual_seed(3)
    signal = torch.nn.functional.normalize(torch.randn(64, 2, generator=generator), dim=-1)
    gust = PriorShift().train.draw((64,), generator=generator)
    noise = torch.randn(signal.shape, generator=torch.Generator().manual_seed(5))
    if isinstance(sensor, DivertedCompass):
        raw = sensor.signal_weight * sensor.needle(signal, gust) + sensor.noise_std * noise
    else:
        raw = sensor.signal_weight * signal + sensor.gust_weight * GustProcess.direction(gust) + sensor.noise_std * noise
    expected = rotate(torch.tanh(raw), 0.7)
    assert torch.equal(sensor.read(signal, gust, rotation=0.7, generator=torch.Generator().manual_seed(5)), expected)
