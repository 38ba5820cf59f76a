"""The maze experts' walking skills: SAC in open ground, in the gusts, with TorchRL parts.

OGBench generated its maze datasets with goal-direction locomotion policies steered by a
planner; this trains such a policy (SAC, 2 x 256 MLPs, batch 256, gamma 0.99, tau 0.005,
uniformly random warm-up steps) on a :class:`~torchrl_causal.envs.open_ground.DirectionalLocomotionEnv`,
with TorchRL's :class:`~torchrl.objectives.SACLoss`, :class:`~torchrl.collectors.Collector` and
:class:`~torchrl.data.TensorDictReplayBuffer`. A :class:`LocomotionSkill` names what differs
between agents (env, network, default budget, where the weights ship): :data:`SKILLS` has the
ant's (:class:`~torchrl_causal.envs.ant.AntLocomotionEnv`, OGBench's budget: ~400k env steps at
one update per step) and the humanoid's (:class:`~torchrl_causal.envs.humanoid.HumanoidLocomotionEnv`,
issue 38: 3M env steps at 0.5 updates per step, ~7-10 CPU-hours).

Runs resume in two ways:

* on the same machine: every ``checkpoint_minutes`` the networks, optimisers, counters and RNG
  states go to ``<run_dir>/checkpoint.pt`` and the replay buffer to ``<run_dir>/buffer`` (both
  atomically); a restarted run continues from them (in-flight episodes restart);
* across machines: each checkpoint also writes ``<run_dir>/resume_state.pt``, the few MB a run
  needs without its buffer (actor, critics, target critics, alpha, optimiser states, counters,
  the best evaluated policy body).
  ``--resume-from FILE`` starts a fresh run directory from such a file; the buffer refills from
  the current policy (no random actions) before the updates go on.

The best evaluation's policy body is exported to ``--output`` (by default ``<run_dir>/export.pt``:
a run never overwrites the weights the package ships unless that path is named, as here, where
the ant's shipped weights are regenerated)::

    python -m torchrl_causal.experts.locomotion --skill ant --run-dir runs/ant_locomotion \
        --output torchrl_causal/envs/assets/ant_locomotion.pt
    python -m torchrl_causal.experts.locomotion --skill humanoid --run-dir runs/humanoid_locomotion
"""

from __future__ import annotations

import logging
import math
from collections.abc import Callable, Mapping
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Any, TypedDict, cast

import torch
from tensordict.nn import NormalParamExtractor, TensorDictModule
from torch import nn
from torchrl.data import LazyTensorStorage, TensorDictReplayBuffer
from torchrl.envs.utils import ExplorationType, set_exploration_type
from torchrl.modules import MLP, ProbabilisticActor, TanhNormal, ValueOperator
from torchrl.objectives import SACLoss, SoftUpdate

from torchrl_causal.command_line import non_negative, positive_number
from torchrl_causal.envs.ant import LOCOMOTION_OBSERVATION_DIM, AntLocomotionEnv
from torchrl_causal.envs.humanoid import HUMANOID_SKILL_OBSERVATION_DIM, HumanoidLocomotionEnv
from torchrl_causal.envs.open_ground import DirectionalLocomotionEnv
from torchrl_causal.errors import InvalidValueError
from torchrl_causal.experiment.run_directory import atomic_save, load_checkpoint
from torchrl_causal.experts.skill_run import (
    BEST_BODY,
    BOOKKEEPING,
    EXPORT,
    SkillLoop,
    SkillRunDirectory,
    add_output_argument,
    check_same_config,
    finish_skill_run,
    read_skill_state,
    require_positive,
    run_skill_command,
    skill_collector,
    skill_parser,
    upright_speed,
)
from torchrl_causal.experts.skills import HUMANOID_LOCOMOTION_WEIGHTS, LOCOMOTION_WEIGHTS, CommandFrame, make_skill_network

__all__ = [
    "BEST_BODY",
    "BOOKKEEPING",
    "SKILLS",
    "EXPORT",
    "LocomotionConfig",
    "LocomotionSkill",
    "evaluate_locomotion",
    "make_locomotion_actor",
    "check_same_config",
    "add_output_argument",
    "finish_skill_run",
    "require_positive",
    "train_locomotion",
    "upright_speed",
]

log = logging.getLogger(__name__)

_CHECKPOINT = "checkpoint.pt"
_BUFFER = "buffer"
_CONFIG = "locomotion_config.json"
#: what SACLoss reads; the collector's other entries (loc, scale, xy...) stay out of the buffer.
_TRANSITION_KEYS = ("observation", "action", ("next", "observation"), ("next", "reward"), ("next", "done"), ("next", "terminated"))


@dataclass(frozen=True)
class LocomotionConfig:
    """Budget and hyperparameters of a locomotion SAC run (OGBench's ant run by default).

    ``random_steps`` uniformly random steps open a fresh run, and updates start once the buffer
    holds more than ``random_steps`` transitions: a run resumed without its buffer refills it
    from the current policy first.
    """

    total_steps: int = 400_000
    buffer_size: int = 400_000
    random_steps: int = 10_000
    num_envs: int = 4
    frames_per_batch: int = 200
    updates_per_step: float = 1.0
    batch_size: int = 256
    gamma: float = 0.99
    tau: float = 0.005
    lr: float = 3e-4
    hidden: int = 256
    eval_every: int = 20_000
    eval_envs: int = 8
    eval_steps: int = 300
    checkpoint_minutes: float = 5.0
    seed: int = 0

    def __post_init__(self) -> None:
        require_positive(self, ("total_steps", "buffer_size", "num_envs", "frames_per_batch", "batch_size", "hidden"))
        require_positive(self, ("eval_every", "eval_envs", "eval_steps"))
        if self.frames_per_batch % self.num_envs:
            raise InvalidValueError(f"frames_per_batch ({self.frames_per_batch}) must be a multiple of num_envs ({self.num_envs})")
        if not 0 < self.tau <= 1 or not 0 < self.gamma < 1:
            raise InvalidValueError(f"need 0 < tau <= 1 and 0 < gamma < 1, got tau={self.tau}, gamma={self.gamma}")


@dataclass(frozen=True)
class LocomotionSkill:
    """What a walking skill's SAC run needs to know about its agent.

    Args:
        name: the CLI's ``--skill`` name.
        make_env: ``(batch_size, seed, **options) -> env`` on open ground; ``options`` are the
            env's reward settings a trainer's config may change (the humanoid's ``speed_weight``).
        observation_dim, action_dim: the policy's input and output widths.
        weights: where the package ships the skill's policy body (the default export).
        defaults: the :class:`LocomotionConfig` fields this skill changes.
        env_options: the names ``make_env`` accepts as ``options``.
        command_frame: ``angle -> module`` turning this skill's observations so the command points
            at ``angle`` (:class:`~torchrl_causal.experts.skills.CommandFrame`), or ``None`` where
            the skill has none (the PPO trainer's ``command_frame`` option).
    """

    name: str
    make_env: Callable[..., DirectionalLocomotionEnv]
    observation_dim: int
    action_dim: int
    weights: Path
    defaults: dict[str, Any] = field(default_factory=dict)
    env_options: tuple[str, ...] = ()
    command_frame: Callable[[float], nn.Module] | None = None

    def config(self, **overrides: Any) -> LocomotionConfig:
        """The skill's default :class:`LocomotionConfig` with ``overrides`` (``None`` values ignored)."""
        return replace(LocomotionConfig(), **{**self.defaults, **{k: v for k, v in overrides.items() if v is not None}})

    def network(self, hidden: int = 256) -> nn.Module:
        """A fresh policy body (:func:`~torchrl_causal.experts.skills.make_skill_network`)."""
        return make_skill_network(self.observation_dim, self.action_dim, hidden)


#: The skills — OGBench's ant (its SAC budget) and OGBench's humanoid (issue 38's budget).
SKILLS: dict[str, LocomotionSkill] = {
    "ant": LocomotionSkill(
        "ant", lambda n, seed: AntLocomotionEnv(batch_size=n, seed=seed), LOCOMOTION_OBSERVATION_DIM, 8, LOCOMOTION_WEIGHTS
    ),
    "humanoid": LocomotionSkill(
        "humanoid",
        lambda n, seed, **options: HumanoidLocomotionEnv(batch_size=n, seed=seed, **options),
        HUMANOID_SKILL_OBSERVATION_DIM,
        21,
        HUMANOID_LOCOMOTION_WEIGHTS,
        defaults={
            "total_steps": 3_000_000,
            "buffer_size": 1_000_000,
            "updates_per_step": 0.5,
            "num_envs": 8,
            "eval_every": 50_000,
            "eval_steps": 400,
        },
        env_options=("speed_weight", "command_spread", "direction_period"),
        command_frame=CommandFrame,
    ),
}


def make_locomotion_actor(body: nn.Module | None = None) -> ProbabilisticActor:
    """The tanh-Gaussian SAC actor around a skill's policy body (the ant's by default).

    Its deterministic action is ``tanh`` of the body's first half of outputs, which is what
    :class:`~torchrl_causal.experts.AntMazeExpert` computes from the exported body.

    Examples:
        >>> from tensordict import TensorDict
        >>> actor = make_locomotion_actor()
        >>> actor(TensorDict(observation=torch.zeros(2, 29), batch_size=[2]))["action"].shape
        torch.Size([2, 8])
    """
    body = SKILLS["ant"].network() if body is None else body
    module = TensorDictModule(nn.Sequential(body, NormalParamExtractor()), in_keys=["observation"], out_keys=["loc", "scale"])
    return ProbabilisticActor(
        module,
        in_keys=["loc", "scale"],
        out_keys=["action"],
        distribution_class=TanhNormal,
        distribution_kwargs={"low": -1.0, "high": 1.0},
        return_log_prob=False,
    )


def _make_critic(skill: LocomotionSkill, hidden: int) -> ValueOperator:
    # TorchRL's MLP concatenates its (observation, action) inputs.
    network = MLP(
        in_features=skill.observation_dim + skill.action_dim, out_features=1, num_cells=[hidden, hidden], activation_class=nn.ReLU
    )
    return ValueOperator(network, in_keys=["observation", "action"])


@torch.no_grad()
def evaluate_locomotion(
    body: nn.Module,
    *,
    skill: str | LocomotionSkill = "ant",
    envs: int = 8,
    steps: int = 300,
    seed: int = 12345,
    env_options: Mapping[str, Any] | None = None,
) -> dict[str, float]:
    """Deterministic rollouts of ``body`` on open ground, in the gusts (the skill env's
    ``env_options``, e.g. a curriculum stage's ``command_spread``; its defaults otherwise).

    Returns ``speed``, the mean ground-plane speed (m/s) along the command over every step;
    ``fall_rate``, the fraction of envs that fell at least once (a fallen env restarts);
    ``steps_to_fall``, the mean step of each env's first fall (``steps`` when none fell). The
    ant's command changes every 100 steps, the humanoid's every 100-200.
    """
    skill = SKILLS[skill] if isinstance(skill, str) else skill
    env = skill.make_env(envs, seed, **(env_options or {}))
    env.horizon = steps
    actor = make_locomotion_actor(body)
    with set_exploration_type(ExplorationType.DETERMINISTIC):
        rollout = env.rollout(steps, actor, break_when_any_done=False)
    fell = rollout["next", "terminated"][..., 0]
    first_fall = torch.where(fell.any(-1), fell.float().argmax(-1) + 1, torch.full_like(fell[:, 0], steps, dtype=torch.long))
    return {
        "speed": rollout["next", "speed"].mean().item(),
        "fall_rate": fell.any(-1).float().mean().item(),
        "steps_to_fall": first_fall.float().mean().item(),
    }


class _Counters(TypedDict):
    """Where training stands, checkpointed with the learner."""

    steps: int
    updates: int
    update_debt: float  # updates owed, fractional while updates_per_step is not an integer
    best_score: float  # the best evaluation's upright_speed
    collect_seed: int


def train_locomotion(
    run_dir: str | Path,
    config: LocomotionConfig = LocomotionConfig(),
    *,
    skill: str | LocomotionSkill = "ant",
    output: str | Path | None = None,
    resume_from: str | Path | None = None,
    progress_bar: bool = True,
) -> dict[str, Any]:
    """Trains (or resumes) a skill's policy in ``run_dir``; exports the best body to ``output``.

    ``output=None`` (the default) exports nothing beyond the run directory's best body;
    ``skill.weights`` replaces the weights the package ships for the skill. ``resume_from``
    (a ``resume_state.pt``) starts an empty ``run_dir`` from another machine's run: its
    networks, optimisers and counters, the buffer refilled by the current policy; a
    ``run_dir`` that has its own checkpoint ignores it. Returns the final record: steps,
    updates, best evaluation and the export path. A run directory made with another config
    is refused (the changed fields are named), and so is a folder holding anything the run
    did not write (:class:`~torchrl_causal.experts.skill_run.SkillRunDirectory`).
    """
    skill = SKILLS[skill] if isinstance(skill, str) else skill
    run = SkillRunDirectory(run_dir, _CONFIG, (_CHECKPOINT, _BUFFER, f"{_BUFFER}.tmp", f"{_BUFFER}.old"))
    run.open(config)
    torch.manual_seed(config.seed)

    actor = make_locomotion_actor(skill.network(config.hidden))
    loss = SACLoss(
        actor, _make_critic(skill, config.hidden), num_qvalue_nets=2, loss_function="l2", action_spec=skill.make_env(1, 0).action_spec[0]
    )
    loss.make_value_estimator(gamma=config.gamma)
    target_updater = SoftUpdate(loss, tau=config.tau)
    optimizers = {
        "actor": torch.optim.Adam(loss.actor_network_params.flatten_keys().values(), lr=config.lr),
        "critic": torch.optim.Adam(loss.qvalue_network_params.flatten_keys().values(), lr=config.lr),
        "alpha": torch.optim.Adam([loss.log_alpha], lr=config.lr),
    }
    buffer = TensorDictReplayBuffer(storage=LazyTensorStorage(config.buffer_size), batch_size=config.batch_size)
    counters: _Counters = {"steps": 0, "updates": 0, "update_debt": 0.0, "best_score": -math.inf, "collect_seed": config.seed}

    def load_learner(state: dict[str, Any]) -> None:
        loss.load_state_dict(state["loss"])
        for name, optimizer in optimizers.items():
            optimizer.load_state_dict(state["optimizers"][name])
        counters.update(state["counters"])

    checkpoint = run.path / _CHECKPOINT
    if checkpoint.exists():
        state = load_checkpoint(checkpoint)
        load_learner(state)
        torch.set_rng_state(state["torch_rng"])
        buffer.loads(run.path / _BUFFER)
        log.info("[%s] resumed at %d steps from %s", skill.name, counters["steps"], checkpoint)
    elif resume_from is not None:
        state = read_skill_state(resume_from, skill.name, "sac")
        check_same_config(state["config"], config, resume_from)
        load_learner(state)
        run.adopt_best(state)
        log.info(
            "[%s] resumed at %d steps from %s; the buffer refills from the current policy (%d steps)",
            skill.name,
            counters["steps"],
            resume_from,
            config.random_steps,
        )
    run.write_config(config)

    def save() -> None:
        run.replace_folder(_BUFFER, buffer.dumps)
        learner = {
            "progress": counters["steps"],
            "algorithm": "sac",
            "skill": skill.name,
            "config": asdict(config),
            "loss": loss.state_dict(),
            "optimizers": {k: o.state_dict() for k, o in optimizers.items()},
            "counters": dict(counters),
        }
        atomic_save({**learner, "torch_rng": torch.get_rng_state()}, checkpoint)
        run.save_resume_state(learner)

    def evaluate() -> dict[str, float]:
        body = actor.module[0].module[0]
        result = evaluate_locomotion(body, skill=skill, envs=config.eval_envs, steps=config.eval_steps)
        run.keep_if_best(cast("dict[str, Any]", counters), body, result)  # a TypedDict is not a MutableMapping to mypy
        return result

    remaining = config.total_steps - counters["steps"]
    if remaining > 0:
        # A resumed run draws fresh episodes from a new seed (env state is not checkpointed).
        counters["collect_seed"] += 1
        env = skill.make_env(config.num_envs, counters["collect_seed"])
        random_left = max(0, config.random_steps - counters["steps"])
        collector = skill_collector(env, actor, config.frames_per_batch, remaining, random_left)
        shown = ("train_reward", "eval_speed", "eval_fall_rate", "alpha")
        loop = SkillLoop(
            run, f"{skill.name} locomotion", "locomotion", config, config.frames_per_batch, counters["steps"], save, shown, progress_bar
        )
        for batch in collector:
            buffer.extend(batch.reshape(-1).select(*_TRANSITION_KEYS))
            counters["steps"] += batch.numel()
            metrics: dict[str, float] = {"train_reward": batch["next", "reward"].mean().item()}
            if len(buffer) > config.random_steps:
                counters["update_debt"] += config.updates_per_step * batch.numel()
                losses = None
                while counters["update_debt"] >= 1:
                    losses = loss(buffer.sample())
                    total = losses["loss_actor"] + losses["loss_qvalue"] + losses["loss_alpha"]
                    for optimizer in optimizers.values():
                        optimizer.zero_grad(set_to_none=True)
                    total.backward()
                    for optimizer in optimizers.values():
                        optimizer.step()
                    target_updater.step()
                    counters["updates"] += 1
                    counters["update_debt"] -= 1
                if losses is not None:
                    metrics.update(loss_qvalue=losses["loss_qvalue"].item(), alpha=losses["alpha"].item(), entropy=losses["entropy"].item())
            collector.update_policy_weights_()
            if loop.after_batch(counters["steps"], batch.numel(), metrics, evaluate):
                break
        collector.shutdown()
        loop.close()
    record = {"skill": skill.name, "steps": counters["steps"], "updates": counters["updates"], "best_eval_score": counters["best_score"]}
    return run.finish(output, record)


def main(argv: list[str] | None = None) -> None:
    parser = skill_parser(
        __doc__,
        SKILLS,
        "ant",
        run_dir="checkpoints, buffer and logs (resumed); default runs/<skill>_locomotion",
        resume_from="a resume_state.pt to start an empty --run-dir from (the buffer refills from the policy)",
        steps="total env steps (skill default: ant 400k, humanoid 3M)",
    )
    parser.add_argument("--utd", type=positive_number, default=None, help="gradient steps per env step (ant 1, humanoid 0.5)")
    parser.add_argument(
        "--random-steps",
        type=non_negative,
        default=None,
        help="uniformly random steps of a fresh run; the buffer size at which updates start",
    )
    args = parser.parse_args(argv)
    skill = SKILLS[args.skill]
    run_skill_command(
        args.threads,
        Path(args.run_dir or f"runs/{skill.name}_locomotion"),
        args.output,
        lambda run_dir, output: train_locomotion(
            run_dir,
            skill.config(
                total_steps=args.steps,
                updates_per_step=args.utd,
                random_steps=args.random_steps,
                eval_every=args.eval_every,
                seed=args.seed,
            ),
            skill=skill,
            output=output,
            resume_from=args.resume_from,
        ),
    )


if __name__ == "__main__":
    main()
