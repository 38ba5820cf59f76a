"""PPO for the walking skills: many batched simulations, on-policy, weights-only resume.

Issue 38's fallback for the humanoid's skill. SAC (:mod:`torchrl_causal.experts.locomotion`) is
bound by its updates on one CPU core (~75 env steps/s at 0.5 updates per step, 2 x 256), so its
3M-step budget is ~11 core-hours; PPO's cost is the simulation's (a 4096-step batch is ~1.5 s of
MuJoCo and ~0.1 s of updates at 2 x 256), tens of times more env steps per core-hour, which is
what a standing-start humanoid needs (OGBench's SAC skill used 40M). On-policy also makes the
resume across machines exact: the learner's weights, normaliser and optimiser are the whole state.

The policy is the skill's body (:func:`~torchrl_causal.experts.skills.make_skill_network`) on
running-normalised observations, a Gaussian around ``tanh`` of its first half of outputs with the
second half's softplus as the scale; the env clips the sampled action to ``[-1, 1]``. Its
deterministic action is therefore ``tanh`` of the body's first half, as the SAC skill's, and the
exported body has the normaliser folded into its first layer
(:func:`fold_observation_normalisation`): the shipped weights load into the same network as
SAC's, and :class:`~torchrl_causal.experts.HumanoidMazeExpert` uses them unchanged.

TorchRL parts: :class:`~torchrl.collectors.Collector` over the batched env (or, with
``collector_workers`` > 1, :class:`~torchrl.collectors.MultiSyncCollector` over that many
processes, each with its share of the simulations),
:class:`~torchrl.objectives.value.GAE`, :class:`~torchrl.objectives.ClipPPOLoss`. Rewards are
scaled by ``reward_scale`` for the critic (the stand reward is up to 2.5 per step). Every
``checkpoint_minutes`` and every evaluation ``<run_dir>/resume_state.pt`` is written (a few MB);
the same command resumes from it, on this machine or (``--resume-from``) another::

    python -m torchrl_causal.experts.locomotion_ppo --skill humanoid --run-dir runs/humanoid_ppo
    python -m torchrl_causal.experts.locomotion_ppo --skill humanoid --run-dir runs/humanoid_ppo --collector-workers 2
"""

from __future__ import annotations

import argparse
import copy
import functools
import json
import logging
import math
from dataclasses import asdict, dataclass, fields, replace
from pathlib import Path
from typing import Any

import torch
from tensordict import TensorDictBase
from tensordict.nn import NormalParamExtractor, TensorDictModule, TensorDictSequential
from torch import nn
from torchrl.collectors import BaseCollector
from torchrl.envs import EnvBase, TransformedEnv, UnaryTransform
from torchrl.modules import MLP, IndependentNormal, ProbabilisticActor, ValueOperator
from torchrl.objectives import ClipPPOLoss
from torchrl.objectives.value import GAE

from torchrl_causal.command_line import count, non_negative_number, positive_number
from torchrl_causal.envs.open_ground import DirectionalLocomotionEnv
from torchrl_causal.errors import InvalidTypeError, InvalidValueError
from torchrl_causal.experiment.interrupts import RunInterrupted, deferred_signals
from torchrl_causal.experiment.run_directory import atomic_save
from torchrl_causal.experts.locomotion import SKILLS, LocomotionSkill, evaluate_locomotion
from torchrl_causal.experts.skill_run import (
    SkillLoop,
    SkillRunDirectory,
    check_same_config,
    parallel_skill_collector,
    read_skill_state,
    require_positive,
    run_skill_command,
    skill_collector,
    skill_command,
    skill_parser,
    worker_seeds,
)

__all__ = [
    "ADAPTIVE_LR_BOUNDS",
    "PPOLocomotionConfig",
    "RunningNormalisation",
    "adapt_learning_rate",
    "export_learner",
    "fold_observation_normalisation",
    "gaussian_kl",
    "make_ppo_actor",
    "train_locomotion_ppo",
]

log = logging.getLogger(__name__)

_CONFIG = "ppo_config.json"


@dataclass(frozen=True)
class PPOLocomotionConfig:
    """Budget and hyperparameters of a PPO skill run (MuJoCo-PPO defaults: clip 0.2, GAE 0.95).

    One iteration collects ``rollout_steps`` steps in each of ``num_envs`` simulations, then
    makes ``epochs`` passes over them in minibatches of ``minibatch_size``. ``init_scale`` is the
    exploration noise's standard deviation at initialisation (the scale is a biased softplus of
    the body's second half: 1.0 spans the whole ``[-1, 1]`` torque range, which topples a standing
    humanoid within ~1 s); ``anneal_lr`` decays the learning rate linearly to 0 over ``total_steps``;
    ``speed_weight`` (``None``: the env's default) weighs the speed term of the skill env's reward;
    ``command_spread`` (``None``: uniform commands) bounds the angle between a command and the heading.
    ``widen_gate`` (``None``: the spread stays put) makes one run its own curriculum: at each
    evaluation, on the current commands, whose :func:`~torchrl_causal.experts.locomotion.upright_speed`
    reaches the gate, the spread widens by ``widen_step`` for the rest of the run, up to pi (uniform,
    the skill's task). Each spread selects its own best body (a wider one is a harder task, so
    scores across spreads do not compare): the export is the best at the widest spread reached.
    ``command_frame`` (``None``: the world frame) makes the learner read observations turned so
    that the command points at that angle (the skill's
    :class:`~torchrl_causal.experts.skills.CommandFrame`, applied to the collector's env; the
    exported body starts with it, so it reads the env's own observations).
    ``direction_period`` (``None``: the env's, 100-200 steps) is the inclusive range of steps between
    the training env's command redraws; the evaluation keeps the skill's task, so a run that walks
    longer legs (as a maze's corridors ask) scores on the same commands as one that does not.
    ``collector_workers`` processes collect each batch (1: this process, the runs on record),
    each on ``num_envs / collector_workers`` simulations with seeds of its own
    (:func:`~torchrl_causal.experts.skill_run.worker_seeds`): the batch and the update are the
    same size and shape. A curriculum's widened commands reach them by a new set of workers.
    """

    total_steps: int = 30_000_000
    num_envs: int = 64
    rollout_steps: int = 64
    epochs: int = 4
    minibatch_size: int = 1024
    gamma: float = 0.99
    lmbda: float = 0.95
    clip_epsilon: float = 0.2
    entropy_coeff: float = 1e-3
    critic_coeff: float = 0.5
    lr: float = 3e-4
    max_grad_norm: float = 0.5
    reward_scale: float = 0.1
    hidden: int = 256
    init_scale: float = 1.0
    anneal_lr: bool = False
    desired_kl: float | None = None
    speed_weight: float | None = None
    command_spread: float | None = None
    widen_gate: float | None = None
    widen_step: float = math.pi / 4
    command_frame: float | None = None
    direction_period: tuple[int, int] | None = None
    eval_every: int = 500_000
    eval_envs: int = 8
    eval_steps: int = 400
    checkpoint_minutes: float = 10.0
    seed: int = 0
    collector_workers: int = 1

    def __post_init__(self) -> None:
        require_positive(self, ("total_steps", "num_envs", "rollout_steps", "epochs", "minibatch_size", "hidden", "collector_workers"))
        if self.num_envs % self.collector_workers:
            raise InvalidValueError(
                f"collector_workers ({self.collector_workers}) must divide num_envs ({self.num_envs}): each worker steps an equal share"
            )
        require_positive(self, ("eval_every", "eval_envs", "eval_steps"))
        if self.minibatch_size > self.frames_per_batch:
            raise InvalidValueError(
                f"minibatch_size ({self.minibatch_size}) exceeds a batch of num_envs x rollout_steps = {self.frames_per_batch}"
            )
        if not 0 < self.gamma < 1 or not 0 <= self.lmbda <= 1 or not 0 < self.clip_epsilon < 1:
            raise InvalidValueError(
                f"need 0 < gamma < 1, 0 <= lmbda <= 1, 0 < clip_epsilon < 1, got {self.gamma}, {self.lmbda}, {self.clip_epsilon}"
            )
        if not (self.lr > 0 and self.max_grad_norm > 0 and self.reward_scale > 0 and self.entropy_coeff >= 0 and self.critic_coeff > 0):
            raise InvalidValueError("lr, max_grad_norm, reward_scale and critic_coeff must be > 0 and entropy_coeff >= 0")
        if self.desired_kl is not None and (not self.desired_kl > 0 or self.anneal_lr):
            raise InvalidValueError(f"desired_kl must be > 0 and excludes anneal_lr (both set the learning rate), got {self.desired_kl}")
        if not self.init_scale > 0.01:  # the softplus's floor
            raise InvalidValueError(f"init_scale must be > 0.01, got {self.init_scale}")
        if self.speed_weight is not None and not self.speed_weight >= 0:
            raise InvalidValueError(f"speed_weight must be >= 0, got {self.speed_weight}")
        if self.command_frame is not None and not math.isfinite(self.command_frame):
            raise InvalidValueError(f"command_frame must be a finite angle (radians) or None, got {self.command_frame}")
        if self.direction_period is not None:
            period = tuple(self.direction_period)
            if len(period) != 2 or not all(isinstance(n, int) for n in period) or not 1 <= period[0] <= period[1]:
                raise InvalidValueError(f"direction_period must be two steps 1 <= low <= high, got {self.direction_period!r}")
        if self.command_spread is not None and not 0 <= self.command_spread <= math.pi:
            raise InvalidValueError(f"command_spread must lie in [0, pi], got {self.command_spread} (--command-spread pi: uniform)")
        if self.widen_gate is not None:
            if self.command_spread is None or self.command_spread >= math.pi:
                raise InvalidValueError(f"widen_gate needs a command_spread below pi to widen from, got {self.command_spread}")
            if not self.widen_gate > 0 or not 0 < self.widen_step <= math.pi:
                raise InvalidValueError(f"need widen_gate > 0 and 0 < widen_step <= pi, got {self.widen_gate}, {self.widen_step}")

    @property
    def env_options(self) -> dict[str, Any]:
        """The reward settings passed to the skill's env (those left at ``None`` keep the env's default)."""
        options = {"speed_weight": self.speed_weight, "command_spread": self.command_spread}
        return {name: value for name, value in options.items() if value is not None}

    @property
    def collector_options(self) -> dict[str, Any]:
        """The training env's settings on top of :attr:`env_options` (the evaluation keeps the skill's task)."""
        return {} if self.direction_period is None else {"direction_period": self.direction_period}

    @property
    def frames_per_batch(self) -> int:
        return self.num_envs * self.rollout_steps


#: The learning rates :func:`adapt_learning_rate` stays within (rsl_rl's).
ADAPTIVE_LR_BOUNDS = (1e-5, 1e-2)


def gaussian_kl(loc: torch.Tensor, scale: torch.Tensor, other_loc: torch.Tensor, other_scale: torch.Tensor) -> torch.Tensor:
    """``KL(N(loc, scale) || N(other_loc, other_scale))`` of diagonal Gaussians, summed over the last dim.

    Examples:
        >>> gaussian_kl(torch.zeros(1, 2), torch.ones(1, 2), torch.ones(1, 2), torch.ones(1, 2))
        tensor([1.])
    """
    ratio = scale / other_scale
    return (0.5 * (ratio.square() + ((loc - other_loc) / other_scale).square() - 1) - ratio.log()).sum(-1)


def adapt_learning_rate(lr: float, kl: float, desired_kl: float, factor: float = 1.5) -> float:
    """The next learning rate of a KL-adaptive PPO (rsl_rl's rule for legged locomotion).

    Divided by ``factor`` when the measured KL exceeds twice ``desired_kl``, multiplied by it
    when the KL is under half of it, unchanged between; kept within :data:`ADAPTIVE_LR_BOUNDS`.

    Examples:
        >>> adapt_learning_rate(3e-4, kl=0.05, desired_kl=0.01) == 3e-4 / 1.5
        True
        >>> adapt_learning_rate(3e-4, kl=0.001, desired_kl=0.01) == 3e-4 * 1.5
        True
        >>> adapt_learning_rate(3e-4, kl=0.01, desired_kl=0.01)
        0.0003
    """
    low, high = ADAPTIVE_LR_BOUNDS
    if kl > 2 * desired_kl:
        return max(low, lr / factor)
    if kl < desired_kl / 2:
        return min(high, lr * factor)
    return lr


class RunningNormalisation(nn.Module):
    """``(x - mean) / sqrt(var + eps)`` with the mean and variance of every observation seen.

    The statistics are buffers (saved with the module) updated by :meth:`update` with a batch
    (Chan et al.'s parallel merge), never by gradients.

    Examples:
        >>> norm = RunningNormalisation(2)
        >>> norm.update(torch.tensor([[0.0, 10.0], [2.0, 30.0]]))
        >>> norm(torch.tensor([[1.0, 20.0]]))
        tensor([[0., 0.]])
        >>> norm.mean.tolist(), norm.var.tolist()
        ([1.0, 20.0], [1.0, 100.0])
    """

    mean: torch.Tensor
    var: torch.Tensor
    count: torch.Tensor

    def __init__(self, dim: int, eps: float = 1e-8) -> None:
        super().__init__()
        self.eps = eps
        self.register_buffer("mean", torch.zeros(dim))
        self.register_buffer("var", torch.ones(dim))
        self.register_buffer("count", torch.zeros((), dtype=torch.float64))

    @torch.no_grad()
    def update(self, batch: torch.Tensor) -> None:
        batch = batch.reshape(-1, self.mean.shape[0]).double()
        n = batch.shape[0]
        mean, var = batch.mean(0), batch.var(0, unbiased=False)
        total = self.count + n
        delta = mean - self.mean.double()
        new_mean = self.mean.double() + delta * n / total
        merged = (self.var.double() * self.count + var * n + delta.square() * self.count * n / total) / total
        self.mean.copy_(new_mean.float())
        self.var.copy_(merged.float())
        self.count.copy_(total)

    def forward(self, observation: torch.Tensor) -> torch.Tensor:
        return (observation - self.mean) / torch.sqrt(self.var + self.eps)


def fold_observation_normalisation(norm: RunningNormalisation, body: nn.Module) -> nn.Sequential:
    """A copy of ``body`` whose first :class:`~torch.nn.Linear` reads raw observations:
    ``folded(x) == body(norm(x))`` (``W' = W / s``, ``b' = b - W' mean``, ``s = sqrt(var + eps)``).

    Examples:
        >>> from torchrl_causal.experts.skills import make_skill_network
        >>> norm, body = RunningNormalisation(4), make_skill_network(4, 2, hidden=8)
        >>> norm.update(torch.randn(100, 4) * 3 + 1)
        >>> x = torch.randn(5, 4)
        >>> torch.allclose(fold_observation_normalisation(norm, body)(x), body(norm(x)), atol=1e-5)
        True
    """
    layers = [copy.deepcopy(layer) for layer in body.children()] if isinstance(body, nn.Sequential) else []
    first = layers[0] if layers else None
    if not isinstance(first, nn.Linear):
        raise InvalidTypeError(f"the body must be an nn.Sequential starting with nn.Linear, got {body}")
    scale = torch.sqrt(norm.var + norm.eps)
    linear = nn.Linear(first.in_features, first.out_features)
    with torch.no_grad():
        linear.weight.copy_(first.weight / scale)
        linear.bias.copy_(first.bias - linear.weight @ norm.mean)
    return nn.Sequential(linear, *layers[1:])  # the same layers, so the same state-dict keys


class _TanhMean(nn.Module):
    def forward(self, loc: torch.Tensor) -> torch.Tensor:
        return torch.tanh(loc)


def make_ppo_actor(body: nn.Module, norm: RunningNormalisation, init_scale: float = 1.0) -> ProbabilisticActor:
    """The PPO policy: ``Normal(tanh(loc), scale)`` with ``(loc, scale)`` from ``body(norm(obs))``.

    Its deterministic action is ``tanh(loc)``; sampled actions are not clipped here (the env
    clips), so their log-probability is the Gaussian's, as PPO's ratio needs. ``scale`` is a
    softplus biased so that a zero output gives ``init_scale``.

    Examples:
        >>> from tensordict import TensorDict
        >>> from torchrl_causal.experts.skills import make_skill_network
        >>> actor = make_ppo_actor(make_skill_network(6, 3, hidden=8), RunningNormalisation(6))
        >>> out = actor(TensorDict(observation=torch.zeros(2, 6), batch_size=[2]))
        >>> out["action"].shape, out["action_log_prob"].shape
        (torch.Size([2, 3]), torch.Size([2]))
    """
    extractor = NormalParamExtractor(scale_mapping=f"biased_softplus_{float(init_scale)}")
    params = TensorDictModule(nn.Sequential(norm, body, extractor), in_keys=["observation"], out_keys=["loc", "scale"])
    mean = TensorDictModule(_TanhMean(), in_keys=["loc"], out_keys=["loc"])
    return ProbabilisticActor(
        TensorDictSequential(params, mean),
        in_keys=["loc", "scale"],
        out_keys=["action"],
        distribution_class=IndependentNormal,
        return_log_prob=True,
        log_prob_key="action_log_prob",
    )


def _make_value(skill: LocomotionSkill, norm: RunningNormalisation, hidden: int) -> ValueOperator:
    network = MLP(in_features=skill.observation_dim, out_features=1, num_cells=[hidden, hidden], activation_class=nn.Tanh)
    return ValueOperator(nn.Sequential(norm, network), in_keys=["observation"])


def train_locomotion_ppo(
    run_dir: str | Path,
    config: PPOLocomotionConfig = PPOLocomotionConfig(),
    *,
    skill: str | LocomotionSkill = "humanoid",
    output: str | Path | None = None,
    resume_from: str | Path | None = None,
    init_from: str | Path | None = None,
    progress_bar: bool = True,
) -> dict[str, Any]:
    """Trains (or resumes) a skill with PPO in ``run_dir``; exports the best folded body to ``output``.

    A ``run_dir`` holding a ``resume_state.pt`` continues from it; otherwise ``resume_from`` (a
    ``resume_state.pt`` from another machine) starts it. A run made with another config is
    refused (the changed fields are named). ``init_from`` instead starts a new run, under this
    config, from another PPO run's learner (weights, normaliser, Adam and its env-step count): a
    curriculum stage, e.g. a standing policy fine-tuned on a reward that pays walking more. The
    best evaluation (:func:`~torchrl_causal.experts.locomotion.upright_speed`) keeps its folded body in ``<run_dir>/best_body.pt``
    (a run started ``init_from`` selects among its own evaluations). Returns the final record.
    """
    if resume_from is not None and init_from is not None:
        raise InvalidValueError("give resume_from (continue a run) or init_from (start a new run from its learner), not both")
    skill = SKILLS[skill] if isinstance(skill, str) else skill
    unknown = sorted((set(config.env_options) | set(config.collector_options)) - set(skill.env_options))
    if unknown:
        raise InvalidValueError(f"the {skill.name} skill's env takes no {unknown} (it takes {list(skill.env_options) or 'none'})")
    # Applied to the collector's env, so the learner (and its normaliser) only ever see the turned observations.
    frame = _command_frame(skill, config)
    run = SkillRunDirectory(run_dir, _CONFIG)
    run.open(config)
    torch.manual_seed(config.seed)

    norm, body, actor, value, loss = _make_learner(skill, config)
    advantage = GAE(gamma=config.gamma, lmbda=config.lmbda, value_network=value, average_gae=False)
    optimizer = torch.optim.Adam(loss.parameters(), lr=config.lr)
    # command_spread is the curriculum's current spread (``widen_gate``); a new stage starts at its own.
    counters: dict[str, Any] = {
        "steps": 0,
        "iterations": 0,
        "best_score": -math.inf,
        "collect_seed": config.seed,
        "command_spread": config.command_spread,
    }

    source = run.resume_state if run.resume_state.exists() else (Path(resume_from) if resume_from is not None else None)
    if source is not None:
        state = read_skill_state(source, skill.name, "ppo")
        check_same_config(state["config"], config, source)
        loss.load_state_dict(state["loss"])
        optimizer.load_state_dict(state["optimizer"])
        counters.update(state["counters"])
        if source != run.resume_state:
            run.adopt_best(state)
        log.info("[%s ppo] resumed at %d env steps from %s", skill.name, counters["steps"], source)
    elif init_from is not None:
        parent = read_skill_state(init_from, skill.name, "ppo")
        parent_scale = parent["config"].get("init_scale", PPOLocomotionConfig.init_scale)
        if parent_scale != config.init_scale:
            # The scale's softplus bias is set by init_scale: another value changes the parent's policy.
            raise InvalidValueError(
                f"{init_from} was trained with init_scale={parent_scale}, which sets the policy's noise mapping: "
                f"pass the same (--init-scale {parent_scale}), got {config.init_scale}"
            )
        try:
            loss.load_state_dict(parent["loss"])
            optimizer.load_state_dict(parent["optimizer"])
        except (RuntimeError, ValueError) as error:
            raise InvalidValueError(f"{init_from}'s learner does not fit this config (hidden={config.hidden}?): {error}") from error
        for group in optimizer.param_groups:
            group["lr"] = config.lr  # this run's learning rate, not the parent's last one
        inherited = parent["counters"]
        counters.update(
            steps=inherited["steps"],
            iterations=inherited["iterations"],
            collect_seed=inherited["collect_seed"],
            init_from=str(init_from),
            init_steps=inherited["steps"],
        )
        log.info("[%s ppo] new run from %s's learner at %d env steps", skill.name, init_from, counters["steps"])
    run.write_config(config)

    def save() -> None:
        run.save_resume_state(
            {
                "progress": counters["steps"],
                "algorithm": "ppo",
                "skill": skill.name,
                "config": asdict(config),
                "loss": loss.state_dict(),
                "optimizer": optimizer.state_dict(),
                "counters": dict(counters),
            }
        )

    def env_options() -> dict[str, Any]:
        spread = counters["command_spread"]
        return {**config.env_options, **({} if spread is None else {"command_spread": spread})}

    def evaluate() -> dict[str, float]:
        folded = _skill_body(norm, body, frame)
        # On the run's own task (a curriculum stage's commands); the final stage's is the skill's.
        result = evaluate_locomotion(folded, skill=skill, envs=config.eval_envs, steps=config.eval_steps, env_options=env_options())
        score = run.keep_if_best(counters, folded, result)
        spread = counters["command_spread"]
        if config.widen_gate is not None and spread is not None and spread < math.pi and score >= config.widen_gate:
            counters["command_spread"] = min(math.pi, spread + config.widen_step)
            counters["best_score"] = -math.inf  # the wider spread selects its own best
            if env is not None:  # a widened curriculum, from the next batch on (workers: from the next workers on)
                env.command_spread = counters["command_spread"]
            log.info(
                "[%s ppo] upright speed %.3f >= %.3f: commands widen to %.4f rad",
                skill.name,
                score,
                config.widen_gate,
                counters["command_spread"],
            )
        return {**result, **({} if spread is None else {"command_spread": spread})}

    env: DirectionalLocomotionEnv | None = None  # the in-process collector's, where the curriculum widens in place
    if counters["steps"] < config.total_steps:
        loop = SkillLoop(
            run, f"{skill.name} ppo", "ppo", config, config.frames_per_batch, counters["steps"], save, progress_bar=progress_bar
        )
        # A signal lets the batch in flight finish; the run then saves and stops (a second one stops it at once).
        with deferred_signals() as signals:
            while counters["steps"] < config.total_steps and signals.received is None:
                # A resumed run draws fresh episodes from a new seed (the simulations are not saved),
                # as do the new workers of a widened curriculum.
                counters["collect_seed"] += 1
                collector, env = _collector(skill, config, counters, actor, frame, {**env_options(), **config.collector_options})
                spread = counters["command_spread"]
                try:
                    for batch in collector:
                        metrics = _learn(batch, loss, advantage, optimizer, norm, config, counters)
                        collector.update_policy_weights_()  # the workers' copy (in process: the same module)
                        if loop.after_batch(counters["steps"], batch.numel(), metrics, evaluate):
                            break
                        if signals.received is not None or (env is None and counters["command_spread"] != spread):
                            break
                finally:
                    collector.shutdown()  # the workers too, whatever stopped the loop
        loop.close()
        if signals.received is not None and counters["steps"] < config.total_steps:
            raise RunInterrupted(signals.received)
    record = {"skill": skill.name, "algorithm": "ppo", "steps": counters["steps"], "best_eval_score": counters["best_score"]}
    if "init_from" in counters:
        record.update(init_from=counters["init_from"], init_steps=counters["init_steps"])
    return run.finish(output, record)


def _turned(env: EnvBase, frame: nn.Module | None) -> EnvBase:
    """``env`` with its observations turned by the run's command frame (itself without one)."""
    return env if frame is None else TransformedEnv(env, UnaryTransform(["observation"], ["observation"], fn=frame))


def _training_env(make_env: Any, count: int, options: dict[str, Any], frame: nn.Module | None, seed: int) -> EnvBase:
    """One collector worker's env: ``count`` simulations seeded ``seed``, behind the command frame."""
    return _turned(make_env(count, seed, **options), frame)


def _collector(
    skill: LocomotionSkill,
    config: PPOLocomotionConfig,
    counters: dict[str, Any],
    actor: nn.Module,
    frame: nn.Module | None,
    options: dict[str, Any],
) -> tuple[BaseCollector, DirectionalLocomotionEnv | None]:
    """The collector of the rest of the run under ``counters["collect_seed"]``, and its env where it is
    in this process (``collector_workers`` 1: one env of every simulation, seeded ``collect_seed``,
    the runs on record); with more workers, each builds its share (seeds :func:`worker_seeds`)."""
    remaining = config.total_steps - counters["steps"]
    if config.collector_workers == 1:
        env = skill.make_env(config.num_envs, counters["collect_seed"], **options)
        return skill_collector(_turned(env, frame), actor, config.frames_per_batch, remaining), env
    seeds = worker_seeds(config.seed, counters["collect_seed"], config.collector_workers)
    log.info("[%s ppo] collecting in %d processes, seeds %s", skill.name, len(seeds), [pair.env for pair in seeds])
    make_env = functools.partial(_training_env, skill.make_env, config.num_envs // len(seeds), options, frame)
    return parallel_skill_collector(make_env, seeds, actor, config.frames_per_batch, remaining), None


def _learn(
    batch: TensorDictBase,
    loss: ClipPPOLoss,
    advantage: GAE,
    optimizer: torch.optim.Optimizer,
    norm: RunningNormalisation,
    config: PPOLocomotionConfig,
    counters: dict[str, Any],
) -> dict[str, float]:
    """One iteration's learning from its collected ``batch``: the PPO update, then the normaliser
    and the counters; returns the batch's metrics."""
    metrics = {
        "train_reward": batch["next", "reward"].mean().item(),
        "fall_rate_per_step": batch["next", "terminated"].float().mean().item(),
        "policy_scale": batch["scale"].mean().item(),  # exploration noise (actions span [-1, 1])
    }
    if config.anneal_lr:
        for group in optimizer.param_groups:
            group["lr"] = config.lr * max(0.0, 1.0 - counters["steps"] / config.total_steps)
    metrics.update(_update(batch, loss, advantage, optimizer, config))
    # The statistics move after the update, so each batch is collected and learned with the same ones.
    norm.update(batch["observation"])
    counters["steps"] += batch.numel()
    counters["iterations"] += 1
    return metrics


def _make_learner(
    skill: LocomotionSkill, config: PPOLocomotionConfig
) -> tuple[RunningNormalisation, nn.Module, ProbabilisticActor, ValueOperator, ClipPPOLoss]:
    """The normaliser, the policy body, the actor and critic that read them, and their PPO loss."""
    norm = RunningNormalisation(skill.observation_dim)
    body = skill.network(config.hidden)
    actor, value = make_ppo_actor(body, norm, config.init_scale), _make_value(skill, norm, config.hidden)
    loss = ClipPPOLoss(
        actor,
        value,
        clip_epsilon=config.clip_epsilon,
        entropy_bonus=config.entropy_coeff > 0,
        entropy_coeff=config.entropy_coeff,
        critic_coeff=config.critic_coeff,
        loss_critic_type="l2",
        normalize_advantage=True,
    )
    loss.set_keys(sample_log_prob="action_log_prob")
    return norm, body, actor, value, loss


def _command_frame(skill: LocomotionSkill, config: PPOLocomotionConfig) -> nn.Module | None:
    """The config's command frame for this skill (``None`` without one); a skill that has none refuses."""
    if config.command_frame is None:
        return None
    if skill.command_frame is None:
        raise InvalidValueError(f"the {skill.name} skill has no command frame (command_frame is for the humanoid)")
    return skill.command_frame(config.command_frame)


def _skill_body(norm: RunningNormalisation, body: nn.Module, frame: nn.Module | None) -> nn.Sequential:
    """The exported body: the normaliser folded in, behind the command frame where the run has one
    (so it reads the env's own observations, as the maze expert gives them)."""
    folded = fold_observation_normalisation(norm, body)
    return folded if frame is None else nn.Sequential(frame, *folded)


def export_learner(state_path: str | Path, output: str | Path, *, skill: str | LocomotionSkill = "humanoid") -> int:
    """Writes the skill body of a PPO resume state's *current* learner to ``output``; returns its env steps.

    A run's ``best_body.pt`` is its best on the open-ground evaluation; the learner at a given
    state may be the better maze walker (the evaluation's short legs and uniform commands are not
    the maze's), so this exports the one a state holds, the same way a run exports its best: the
    normaliser folded in, behind the run's command frame.
    """
    skill = SKILLS[skill] if isinstance(skill, str) else skill
    state = read_skill_state(state_path, skill.name, "ppo")
    names = {field.name for field in fields(PPOLocomotionConfig)}
    config = PPOLocomotionConfig(**{k: v for k, v in state["config"].items() if k in names})
    norm, body, _, _, loss = _make_learner(skill, config)
    loss.load_state_dict(state["loss"])
    frame = _command_frame(skill, config)
    output = Path(output)
    output.parent.mkdir(parents=True, exist_ok=True)
    atomic_save(_skill_body(norm, body, frame).state_dict(), output)
    return int(state["progress"])


def _update(
    batch: TensorDictBase, loss: ClipPPOLoss, advantage: GAE, optimizer: torch.optim.Optimizer, config: PPOLocomotionConfig
) -> dict[str, float]:
    """``epochs`` passes of clipped-PPO minibatch updates over one collected batch."""
    # The raw rewards are read into the metrics before this: scale them in place, no copy.
    batch.set(("next", "reward"), batch.get(("next", "reward")) * config.reward_scale)
    with torch.no_grad():
        advantage(batch)  # over [num_envs, rollout_steps]: the time axis is the last one
    flat = batch.reshape(-1)
    totals: dict[str, float] = {}
    count = 0
    for _ in range(config.epochs):
        for indices in torch.randperm(flat.shape[0]).split(config.minibatch_size):
            losses = loss(flat[indices])
            total = losses["loss_objective"] + losses["loss_critic"] + losses.get("loss_entropy", torch.zeros(()))
            optimizer.zero_grad(set_to_none=True)
            total.backward()
            nn.utils.clip_grad_norm_(loss.parameters(), config.max_grad_norm)
            optimizer.step()
            for key in ("loss_objective", "loss_critic", "clip_fraction", "kl_approx"):
                if key in losses.keys():
                    totals[key] = totals.get(key, 0.0) + losses[key].detach().mean().item()
            count += 1
    metrics = {key: value / count for key, value in totals.items()}
    # How far this batch's whole update moved the policy, exactly (the Gaussians' KL, not the
    # sampled log-ratio, which is noisy and often negative): it sets the next batch's rate.
    with torch.no_grad():
        moved = loss.actor_network.get_dist_params(flat.select("observation").clone())
    metrics["kl_update"] = gaussian_kl(flat["loc"], flat["scale"], moved["loc"], moved["scale"]).mean().item()
    if config.desired_kl is not None:
        for group in optimizer.param_groups:
            group["lr"] = adapt_learning_rate(group["lr"], metrics["kl_update"], config.desired_kl)
    return {**metrics, "lr": optimizer.param_groups[0]["lr"]}


def _angle(text: str) -> float:
    """An angle in radians from the command line; ``pi`` spells the uniform spread exactly (3.1416 exceeds it)."""
    if text.strip().lower() == "pi":
        return math.pi
    try:
        angle = float(text)
    except ValueError:
        angle = math.nan
    if not math.isfinite(angle):
        raise argparse.ArgumentTypeError(f"{text} must be a finite angle in radians, or pi")
    return angle


def main(argv: list[str] | None = None) -> None:
    parser = skill_parser(
        __doc__,
        SKILLS,
        "humanoid",
        run_dir="resume state and logs (resumed); default runs/<skill>_ppo",
        resume_from="a resume_state.pt to start an empty --run-dir from",
        steps="total env steps (default 30M)",
    )
    parser.add_argument("--num-envs", type=count, default=None)
    parser.add_argument("--rollout-steps", type=count, default=None, help="steps per env per iteration (default 64)")
    parser.add_argument("--epochs", type=count, default=None, help="passes over each batch (default 4)")
    parser.add_argument("--minibatch-size", type=count, default=None, help="default 1024")
    parser.add_argument("--gamma", type=positive_number, default=None, help="discount (default 0.99; higher makes a fall cost more)")
    parser.add_argument("--entropy-coeff", type=non_negative_number, default=None, help="PPO's entropy bonus (default 1e-3)")
    parser.add_argument("--init-scale", type=positive_number, default=None, help="exploration noise at initialisation (default 1.0)")
    parser.add_argument("--anneal-lr", action="store_true", help="decay the learning rate linearly to 0 over --steps")
    parser.add_argument(
        "--desired-kl", type=positive_number, default=None, help="adapt the learning rate to keep PPO's KL near this (e.g. 0.01)"
    )
    parser.add_argument(
        "--speed-weight", type=non_negative_number, default=None, help="the reward's speed weight (humanoid; default: the env's, 1.0)"
    )
    parser.add_argument(
        "--command-spread",
        type=_angle,
        default=None,
        help="max angle (rad, or 'pi' for uniform commands) between a command and the heading (humanoid; default pi)",
    )
    parser.add_argument(
        "--widen-gate",
        type=positive_number,
        default=None,
        help="upright speed (m/s) at an evaluation that widens the commands (a curriculum)",
    )
    parser.add_argument("--widen-step", type=positive_number, default=None, help="radians the commands widen by at the gate (default pi/4)")
    parser.add_argument("--eval-envs", type=count, default=None, help="simulations per evaluation (default 8)")
    parser.add_argument(
        "--command-frame",
        type=_angle,
        default=None,
        help="learn on observations turned so the command points at this angle (rad, or 'pi'; humanoid)",
    )
    parser.add_argument(
        "--direction-period",
        type=count,
        nargs=2,
        metavar=("LOW", "HIGH"),
        default=None,
        help="steps between the training commands' redraws, drawn in [LOW, HIGH] (humanoid; default 100 200)",
    )
    parser.add_argument(
        "--collector-workers",
        type=count,
        default=None,
        help="processes that collect each batch, each on an equal share of --num-envs (default 1: this one)",
    )
    parser.add_argument("--init-from", default=None, help="a PPO resume_state.pt whose learner starts this new run (a curriculum stage)")
    parser.add_argument(
        "--export-from",
        default=None,
        metavar="STATE",
        help="train nothing: write the skill body of this resume_state.pt's current learner to --output (required)",
    )
    args = parser.parse_args(argv)
    skill = SKILLS[args.skill]
    if args.export_from is not None:
        if args.output is None:
            parser.error("--export-from needs --output (where the body goes)")
        with skill_command(args.threads):
            steps = export_learner(args.export_from, args.output, skill=skill)
        print(json.dumps({"exported": str(args.output), "steps": steps, "from": args.export_from}))
        return
    overrides = {
        "total_steps": args.steps,
        "num_envs": args.num_envs,
        "rollout_steps": args.rollout_steps,
        "epochs": args.epochs,
        "minibatch_size": args.minibatch_size,
        "eval_every": args.eval_every,
        "seed": args.seed,
        "gamma": args.gamma,
        "entropy_coeff": args.entropy_coeff,
        "init_scale": args.init_scale,
        "anneal_lr": True if args.anneal_lr else None,
        "desired_kl": args.desired_kl,
        "speed_weight": args.speed_weight,
        "command_spread": args.command_spread,
        "widen_gate": args.widen_gate,
        "widen_step": args.widen_step,
        "eval_envs": args.eval_envs,
        "command_frame": args.command_frame,
        "direction_period": None if args.direction_period is None else tuple(args.direction_period),
        "collector_workers": args.collector_workers,
    }
    run_skill_command(
        args.threads,
        Path(args.run_dir or f"runs/{skill.name}_ppo"),
        args.output,
        lambda run_dir, output: train_locomotion_ppo(
            run_dir,
            replace(PPOLocomotionConfig(), **{k: v for k, v in overrides.items() if v is not None}),
            skill=skill,
            output=output,
            resume_from=args.resume_from,
            init_from=args.init_from,
        ),
    )


if __name__ == "__main__":
    main()
