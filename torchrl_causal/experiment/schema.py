"""Typed schemas of the Hydra config tree (structured configs in Hydra's ConfigStore).

Every group of ``conf/`` is merged onto one of these dataclasses at composition, so
a value of the wrong type (``seed=abc``, ``causal=maybe``, ``window.mode=fuzzy``) or an
unknown key fails before anything runs, with the offending key named. Ranges (counts
>= 1, strengths in [0, 1]...) are field metadata that :func:`validate_config` checks on
the composed, resolved config: also before a run directory exists.

Objects built from the config are nodes with a ``_target_`` (the class or factory) and
its keyword arguments under their own names; the trainer supplies the runtime
arguments (observation size, action spec, parameters) through ``_partial_``.

The schemas carry types and ranges, never values (every field is ``MISSING``): the YAML
files hold the values, so a schema merged after them (``algo/iq_learn.yaml`` refines
SQIL's schema) changes nothing.

Examples:
    >>> from omegaconf import OmegaConf
    >>> node = OmegaConf.structured(WindowConfig(k=2, mode=WindowMode.relaxed, window_matched=False))
    >>> node.mode = "fuzzy"  # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    omegaconf.errors.ValidationError: Invalid value 'fuzzy', expected one of [exact, relaxed]
    ...
"""

from __future__ import annotations

import dataclasses
import difflib
import enum
import math
import os
import typing
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any, Optional

from hydra.core.config_store import ConfigStore
from omegaconf import MISSING, DictConfig, OmegaConf

from torchrl_causal.algorithms import ROWS, algorithm
from torchrl_causal.compat import config_child, config_holds_value
from torchrl_causal.errors import TorchRLCausalError
from torchrl_causal.experiment.device import bf16_unavailable, compile_unavailable, resolve_device

__all__ = [
    "ALGO_SCHEMAS",
    "AlgoConfig",
    "BCConfig",
    "Config",
    "ConfigValueError",
    "DemosConfig",
    "EnvConfig",
    "EVAL_VIDEO_SIZE",
    "EvalConfig",
    "VideoFormat",
    "GAILConfig",
    "GAILReward",
    "IQLearnConfig",
    "IQLearnVariant",
    "LoggerConfig",
    "WandbLoggerConfig",
    "LOGGER_SCHEMAS",
    "LOGGER_MODULES",
    "OffPolicyConfig",
    "WindowConfig",
    "WindowMode",
    "algo_schema_of",
    "register_configs",
    "validate_config",
    "wandb_login_found",
]


class ConfigValueError(TorchRLCausalError, ValueError):
    """A config value of the right type that is not allowed (out of range, or an env
    without the expert every algorithm needs)."""


def _ranged(
    *, ge: float | None = None, gt: float | None = None, le: float | None = None, lt: float | None = None, default: Any = MISSING
) -> Any:
    bounds = {name: value for name, value in (("ge", ge), ("gt", gt), ("le", le), ("lt", lt)) if value is not None}
    return field(default=default, metadata=bounds)


def at_least(minimum: int = 1, default: Any = MISSING) -> Any:
    """An int field that must be ``>= minimum``."""
    return _ranged(ge=minimum, default=default)


def positive(default: Any = MISSING) -> Any:
    """A float field that must be ``> 0``."""
    return _ranged(gt=0.0, default=default)


def unit_interval(*, open_low: bool = False, open_high: bool = False, default: Any = MISSING) -> Any:
    """A float field in ``[0, 1]`` (either end optionally open)."""
    return _ranged(**({"gt": 0.0} if open_low else {"ge": 0.0}), **({"lt": 1.0} if open_high else {"le": 1.0}), default=default)


_BOUND_TEXT = {"ge": ">=", "gt": ">", "le": "<=", "lt": "<"}
_BOUND_TEST = {"ge": float.__ge__, "gt": float.__gt__, "le": float.__le__, "lt": float.__lt__}


# ---------------------------------------------------------------------- objects built from the config


@dataclass
class Target:
    """A node Hydra instantiates: ``_target_`` plus its keyword arguments."""

    _target_: str = MISSING
    _partial_: bool = True


@dataclass
class ResidualMLPConfig(Target):
    """A residual-MLP network factory (``make_tanh_gaussian_actor``, ``make_qvalue_network``...)."""

    hidden: int = at_least()
    num_blocks: int = at_least()
    dropout: float = unit_interval(open_high=True)


@dataclass
class BCActorConfig(ResidualMLPConfig):
    """BC's deterministic actor (``make_deterministic_actor``), optionally standardising its input."""

    standardize_observation: bool = False


@dataclass
class MLPConfig(Target):
    """A plain MLP factory (GAIL's value network)."""

    hidden: int = at_least()


@dataclass
class DiscriminatorConfig(MLPConfig):
    dropout: float = unit_interval(open_high=True)


@dataclass
class OptimizerConfig(Target):
    """A ``torch.optim`` optimiser; the trainer passes the parameters."""

    lr: float = positive()


@dataclass
class CosineScheduleConfig(Target):
    """``CosineAnnealingLR``; the trainer passes the optimiser and ``T_max`` (the run's updates)."""

    eta_min: float = _ranged(ge=0.0)


@dataclass
class StepScheduleConfig(Target):
    """``StepLR``; the trainer passes the optimiser."""

    step_size: int = at_least()
    gamma: float = unit_interval(open_low=True)


@dataclass
class SoftUpdateConfig(Target):
    """TorchRL's ``SoftUpdate`` (Polyak averaging of the target networks)."""

    tau: float = unit_interval(open_low=True)


@dataclass
class ValueEstimatorConfig:
    """Keyword arguments of ``LossModule.make_value_estimator``."""

    gamma: float = unit_interval()


class BCScale(str, enum.Enum):
    """``bc_scale=...`` of the SQIL / IQ-Learn losses: what the anchor's weight multiplies."""

    actor_loss = "actor_loss"
    expert_value = "expert_value"


@dataclass
class SACStyleLossConfig(Target):
    """``SQILLoss`` (and the SAC arguments ``IQLearnLoss`` shares)."""

    alpha_init: float = positive()
    min_alpha: float = positive()
    max_alpha: float = positive()
    target_entropy: Any = MISSING  # "auto" (-|A|) or a number
    absorbing: bool = MISSING  # absorbing states after termination, for expert and policy data
    goal_value: Optional[GoalValue] = None  # null: the goal is worth zero (the paper); expert: r_E / (1 - gamma)
    bc_weight: Optional[float] = _ranged(gt=0.0, default=None)  # null: no behaviour-cloning anchor on the actor
    bc_scale: BCScale = BCScale.actor_loss  # the anchor's scale: |loss_actor| (~ mean Q), or r_E / (1 - gamma)
    bc_separate_pass: bool = False  # true: the anchor's own actor pass, as the runs before issue 56 (their random stream)


class GoalValue(str, enum.Enum):
    """``goal_value=...`` of the SQIL / IQ-Learn losses (null: zero, the paper's objective)."""

    expert = "expert"


class Precision(str, enum.Enum):
    """``algo.precision`` of the soft-Q and BC updates (null: fp32, the default)."""

    fp32 = "fp32"
    bf16 = "bf16"  # matmuls under a bf16 autocast; weights, optimiser state and loss reductions fp32


@dataclass
class WarmStartConfig:
    """``algo.warm_start``: behaviour-clone the actor, then fit the critics to it, before the soft-Q updates."""

    bc_updates: int = at_least(0)
    critic_updates: int = at_least(0)


@dataclass
class GAILWarmStartConfig:
    """``algo.warm_start`` of GAIL: behaviour-clone the actor, then hold it while the critic
    (and the discriminator) learn its rounds, before PPO moves it. Not in the paper."""

    bc_updates: int = at_least(0)
    critic_rounds: int = at_least(0)


class IQLearnVariant(str, enum.Enum):
    """``IQLearnLoss(variant=...)``: the paper's Algorithm 3, or Garg et al.'s online objective.

    A ``str`` enum, so the instantiated loss receives a value equal to its string."""

    paper = "paper"
    iq_learn = "iq_learn"


@dataclass
class IQLearnLossConfig(SACStyleLossConfig):
    num_value_samples: int = at_least()
    variant: IQLearnVariant = MISSING


@dataclass
class HuberBCLossConfig(Target):
    delta: float = positive()


class GAILReward(str, enum.Enum):
    """``make_gail_losses(reward=...)``: the discriminator's logit, or ``-log(1 - D)``."""

    logit = "logit"
    positive = "positive"


@dataclass
class GAILLossConfig(Target):
    """``make_gail_losses``: the discriminator and PPO settings."""

    gamma: float = unit_interval()
    gae_lambda: float = unit_interval()
    clip_epsilon: float = positive()
    entropy_coeff: float = _ranged(ge=0.0)
    critic_coeff: float = _ranged(ge=0.0)
    gp_lambda: float = _ranged(ge=0.0)
    normalize_advantage: bool = MISSING
    reward: GAILReward = MISSING
    absorbing: bool = MISSING


# ---------------------------------------------------------------------- groups


@dataclass
class PaperFamilyConfig:
    """Appendix E's hyperparameters that differ between the environment families."""

    window_k: int = at_least(0)
    utd_ratio: float = positive()
    iq_value_samples: int = at_least()
    ppo_epochs: int = at_least()
    episodes_per_round: int = at_least()
    gail_rounds: int = at_least()
    bc_epochs: int = at_least()
    bc_patience: int = at_least()


@dataclass
class EnvConfig:
    """A confounded env: ``make`` is instantiated with ``regime``, ``batch_size``,
    ``horizon``, ``confounding_strength`` and ``seed`` (and ``shift`` when it is set);
    ``expert`` with the env.

    ``shift`` is what deploying changes in a gust-confounded maze: null (the default, what
    every run made before the option did) or ``rotation`` turn the compass's reading by
    ``confounding_strength * pi``; ``prior`` moves the wind's distribution P(U) instead
    (:class:`~torchrl_causal.envs.base.PriorShift`). A string checked by
    :func:`validate_config`, so that a bad value is refused in one line naming it."""

    name: str = MISSING
    horizon: int = at_least()
    confounding_strength: float = unit_interval()
    position_key: Optional[str] = None
    shift: Optional[str] = None
    make: Any = MISSING
    expert: Any = MISSING  # null: none yet (training refuses the env)
    paper: PaperFamilyConfig = MISSING


class WindowMode(enum.Enum):
    exact = "exact"
    relaxed = "relaxed"


@dataclass
class WindowConfig:
    """Arguments of ``CausalWindowTransform.from_env`` (``causal`` is the top-level key)."""

    k: int = at_least(0)
    mode: WindowMode = MISSING
    window_matched: bool = MISSING
    drop: list[str] = field(default_factory=list)


#: Pixels per side of the final evaluation's videos (``eval.video``).
EVAL_VIDEO_SIZE = 240


class VideoFormat(str, enum.Enum):
    """``eval.video_format`` of the final evaluation's videos."""

    mp4 = "mp4"  # H.264 through PyAV
    gif = "gif"  # through imageio and Pillow


@dataclass
class EvalConfig:
    episodes: int = at_least()
    final_episodes: int = at_least()
    num_envs: int = at_least()
    trajectories: int = at_least(0)
    # Best-checkpoint selection by train-regime success, the mean return breaking ties;
    # false: by the mean return alone (what every run before the option did).
    select_by_success: bool = False
    # Videos of the first `video` episodes of the final evaluation in each regime, written
    # to <run_dir>/logs/videos/<regime>/episode_<i>.<video_format> (the [video] extra); the
    # evaluation's records are the same with or without them.
    video: int = at_least(0, default=0)
    video_format: VideoFormat = VideoFormat.mp4
    video_every: int = at_least(1, default=1)  # a frame every this many env steps (and the last)
    # Also the first `video` episodes of every periodic (train-regime) evaluation, to
    # <run_dir>/logs/videos/periodic/step_<progress>/; each video also goes to the logger.
    video_periodic: bool = False


@dataclass
class DemosConfig:
    episodes: int = at_least()
    seed: int = at_least(0)
    path: str = MISSING
    successful_only: bool = MISSING
    source: Optional[str] = MISSING  # null: our format at path; minari:<dataset id or path>


@dataclass
class LoggerConfig(Target):
    """A TorchRL logger; the run directory passes ``log_dir``."""

    exp_name: str = MISSING


@dataclass
class WandbLoggerConfig(LoggerConfig):
    """TorchRL's ``WandbLogger``: ``exp_name`` is the W&B run's name, ``id`` its id (a
    resumed run keeps logging to the same W&B run)."""

    offline: bool = MISSING
    project: Optional[str] = MISSING
    id: Optional[str] = MISSING


#: Schema of each ``conf/logger`` option that has keys beyond ``LoggerConfig``'s, stored
#: as ``hydra/schema/logger/<name>`` (see :func:`register_configs`).
LOGGER_SCHEMAS: dict[str, type[LoggerConfig]] = {"wandb": WandbLoggerConfig}

#: The ``_target_`` of ``logger=wandb`` (whose online mode needs a login).
WANDB_TARGET = "torchrl.record.loggers.WandbLogger"

#: The optional package each logger needs (``_target_`` -> the ``logger=`` option and the module).
LOGGER_MODULES: dict[str, tuple[str, str]] = {
    "torchrl.record.loggers.TensorboardLogger": ("tensorboard", "tensorboard"),
    WANDB_TARGET: ("wandb", "wandb"),
}


@dataclass
class AlgoConfig:
    """What every algorithm has: its name and the trainer class (``None``: nothing to
    train, the expert)."""

    name: str = MISSING
    trainer: Optional[str] = MISSING


@dataclass
class TrainedAlgoConfig(AlgoConfig):
    eval_every: int = at_least()


@dataclass
class BCConfig(TrainedAlgoConfig):
    actor: BCActorConfig = MISSING
    loss: HuberBCLossConfig = MISSING
    optimizer: OptimizerConfig = MISSING
    batch_size: int = at_least()
    epochs: int = at_least()
    patience: int = at_least()
    val_fraction: float = unit_interval(open_low=True, open_high=True)
    # null (fp32, what every run made before the key existed holds) or bf16: the updates' matmuls
    precision: Optional[Precision] = None
    # Keep the epoch of the lowest validation loss instead of the best periodic evaluation
    # (false: what every run before the key did).
    select_by_val_loss: bool = False


@dataclass
class GAILConfig(TrainedAlgoConfig):
    actor: ResidualMLPConfig = MISSING
    value: MLPConfig = MISSING
    discriminator: DiscriminatorConfig = MISSING
    loss: GAILLossConfig = MISSING
    actor_optimizer: OptimizerConfig = MISSING
    critic_optimizer: OptimizerConfig = MISSING
    discriminator_optimizer: OptimizerConfig = MISSING
    discriminator_scheduler: StepScheduleConfig = MISSING
    batch_size: int = at_least()
    max_grad_norm: float = positive()
    ppo_epochs: int = at_least()
    discriminator_epochs: int = at_least()
    discriminator_batch_size: int = at_least()
    episodes_per_round: int = at_least()
    rounds: int = at_least()
    warm_start: Optional[GAILWarmStartConfig] = None  # null: the paper's random initial actor


@dataclass
class OffPolicyConfig(TrainedAlgoConfig):
    actor: ResidualMLPConfig = MISSING
    critic: ResidualMLPConfig = MISSING
    loss: SACStyleLossConfig = MISSING
    value_estimator: ValueEstimatorConfig = MISSING
    target_update: SoftUpdateConfig = MISSING
    actor_optimizer: OptimizerConfig = MISSING
    critic_optimizer: OptimizerConfig = MISSING
    alpha_optimizer: OptimizerConfig = MISSING
    critic_scheduler: Optional[CosineScheduleConfig] = MISSING  # None: a constant learning rate
    schedule_updates: Optional[int] = _ranged(ge=1, default=None)  # the schedule's span; null: the run's updates
    warm_start: Optional[WarmStartConfig] = None  # null: the paper's cold start (random warm-up actions)
    # null (fp32, what every run made before the key existed holds) or bf16: the updates' matmuls
    precision: Optional[Precision] = None
    batch_size: int = at_least(2)
    max_grad_norm: float = positive()
    buffer_size: int = at_least()
    expert_ratio: float = unit_interval(open_low=True, open_high=True)
    random_steps: int = at_least(0)
    utd_ratio: float = positive()
    total_steps: int = at_least()
    num_envs: int = at_least()
    frames_per_batch: int = at_least()


@dataclass
class IQLearnConfig(OffPolicyConfig):
    loss: IQLearnLossConfig = MISSING


@dataclass
class Config:
    """The top level of ``conf/config.yaml``."""

    env: EnvConfig = MISSING
    algo: AlgoConfig = MISSING
    window: WindowConfig = MISSING
    eval: EvalConfig = MISSING
    demos: DemosConfig = MISSING
    logger: LoggerConfig = MISSING
    seed: int = at_least(0)
    causal: bool = MISSING
    device: str = "cpu"  # cpu | cuda | cuda:N | mps | auto; validate_config checks this machine has it
    compile: bool = MISSING
    log_every: int = at_least()
    collector_workers: int = at_least()  # must divide algo.num_envs (off-policy)
    threads: int = at_least()
    resume: bool = MISSING
    progress_bar: bool = MISSING
    checkpoint_every_s: float = _ranged(ge=0.0)  # 0: after every training iteration
    max_memory_gb: Optional[float] = _ranged(gt=0.0, default=None)  # None: the memory available when the run starts
    run_root: str = MISSING
    run_name: str = MISSING
    run_dir: str = MISSING


#: The schemas of the ``conf/algo`` options (an algorithm names its own in
#: :mod:`torchrl_causal.algorithms`), stored as ``hydra/schema/algo/<name>`` (see :func:`register_configs`).
ALGO_SCHEMAS: dict[str, type[AlgoConfig]] = {
    "expert": AlgoConfig,
    "bc": BCConfig,
    "gail": GAILConfig,
    "sqil": OffPolicyConfig,
    "iq_learn": IQLearnConfig,
}


def algo_schema(name: str) -> type[AlgoConfig]:
    """The schema of the registered algorithm ``name`` (:mod:`torchrl_causal.algorithms`),
    or :class:`AlgoConfig` for an algorithm the registry does not know."""
    try:
        return ALGO_SCHEMAS[algorithm(name).schema]
    except KeyError:
        return AlgoConfig


def algo_schema_of(cfg: DictConfig) -> type:
    """The type of ``cfg.algo``: the schema it was composed with (``dict`` when untyped)."""
    schema = OmegaConf.get_type(cfg.algo)
    if schema is None:
        raise ConfigValueError(f"algo is null: choose an algorithm ({', '.join(ALGO_SCHEMAS)})")
    return schema


#: Where the group schemas are stored in Hydra's ConfigStore (no option of any group).
SCHEMA_GROUP = "hydra/schema"


def register_configs() -> None:
    """Stores the schemas in Hydra's ConfigStore (idempotent): ``schema`` for the top
    level, ``hydra/schema/algo/<algo>`` and ``hydra/schema/logger/<logger>`` (each
    ``conf/algo/<algo>.yaml`` lists its schema first in its defaults, ``@_here_``); and the
    ``row`` group, one option per :data:`~torchrl_causal.algorithms.ROWS` entry, which sets
    the algorithm, ``causal`` and the window.

    The schemas live below ``hydra/`` so that they are no option of the ``algo`` and
    ``logger`` groups: Hydra lists every option of a group in ``train --help`` and in its
    "Available options" line, and ``algo=schema_bc`` (a schema with no values) would be
    offered there and then fail. Groups below ``hydra/`` are Hydra's own, left out of both.
    """
    store = ConfigStore.instance()
    store.store(name="schema", node=Config)
    for name, schema in ALGO_SCHEMAS.items():
        store.store(group=f"{SCHEMA_GROUP}/algo", name=name, node=schema)
    for name, logger_schema in LOGGER_SCHEMAS.items():
        store.store(group=f"{SCHEMA_GROUP}/logger", name=name, node=logger_schema)
    for row in ROWS:
        defaults = [{"override /algo": row.algorithm}, {"override /window": row.window}, "_self_"]
        store.store(group="row", name=row.name, package="_global_", node={"defaults": defaults, "causal": row.causal})


# ---------------------------------------------------------------------- ranges


def _check_ranges(node: DictConfig, where: str) -> None:
    schema = OmegaConf.get_type(node)
    if schema is None or not dataclasses.is_dataclass(schema):
        return
    for spec in dataclasses.fields(schema):
        value = node[spec.name]
        key = f"{where}{spec.name}"
        if isinstance(value, DictConfig):
            _check_ranges(value, f"{key}.")
            continue
        for bound, limit in spec.metadata.items():
            if value is None or isinstance(value, bool) or not isinstance(value, (int, float)):
                continue
            if math.isnan(value) or not _BOUND_TEST[bound](float(value), float(limit)):
                raise ConfigValueError(f"config value {key}={value!r} is out of range: it must be {_BOUND_TEXT[bound]} {limit:g}")


def _leaves(node: Any, where: str) -> list[str]:
    if isinstance(node, DictConfig) and config_holds_value(node) and len(node):
        return [leaf for key in node.keys() for leaf in _leaves(config_child(node, key), f"{where}.{key!s}")]
    return [where]


def _unknown_keys(node: DictConfig, where: str) -> list[str]:
    """Keys of ``node`` (and below) that its schema does not declare, down to their leaves.
    A ``+key=value`` override adds a key even to a typed node, so composition alone does
    not refuse it."""
    schema = OmegaConf.get_type(node)
    if schema is None or not dataclasses.is_dataclass(schema):
        return []  # a free-form node (``env.make``, ``env.expert``): its target's arguments
    declared = {spec.name for spec in dataclasses.fields(schema)}
    unknown = [leaf for key in node.keys() if key not in declared for leaf in _leaves(config_child(node, key), f"{where}{key!s}")]
    for key in declared & set(node.keys()):
        value = config_child(node, key)
        if isinstance(value, DictConfig) and config_holds_value(value):
            unknown += _unknown_keys(value, f"{where}{key}.")
    return unknown


def _known_keys(schema: type, where: str = "") -> list[str]:
    """Every key ``schema`` declares, nested schemas' included (for a did-you-mean hint)."""
    keys = []
    for name, hint in typing.get_type_hints(schema).items():
        keys.append(f"{where}{name}")
        if isinstance(hint, type) and dataclasses.is_dataclass(hint):
            keys += _known_keys(hint, f"{where}{name}.")
    return keys


def _check_known_keys(cfg: DictConfig) -> None:
    unknown = _unknown_keys(cfg, "")
    if not unknown:
        return
    key = unknown[0]
    schema = algo_schema(str(OmegaConf.select(cfg, "algo.name")))
    close = difflib.get_close_matches(key, _known_keys(Config) + _known_keys(schema, "algo."), n=1)
    hint = f"; did you mean {close[0]}?" if close else ""
    raise ConfigValueError(
        f"config key {key} is unknown (added with +{key}=...?): no schema declares it, so the run would store it and ignore it{hint}"
    )


def _check_sizes(cfg: DictConfig) -> None:
    """Sizes that must agree with each other; what they cost in memory is checked with the
    window built (:mod:`~torchrl_causal.experiment.memory`)."""
    if cfg.window.k >= cfg.env.horizon:
        raise ConfigValueError(
            f"window.k={cfg.window.k} must be < env.horizon={cfg.env.horizon}: a window reaches "
            "at most horizon - 1 steps back (each lag adds a copy of the state to every observation)"
        )


def _check_expert(cfg: DictConfig) -> None:
    if cfg.env.expert is None:
        raise ConfigValueError(
            f"env {cfg.env.name!r} has no expert (env.expert is null), and every algorithm needs one "
            "(demonstrations, or the expert row): name a class taking the env, e.g. "
            "'env.expert={_target_: torchrl_causal.experts.HumanoidMazeExpert, weights: PATH}' for a humanoid skill body of your own."
        )


def _check_shift(cfg: DictConfig) -> None:
    """``env.shift`` is null or one of the shifts, and the env's class takes it."""
    shift = OmegaConf.select(cfg, "env.shift")
    if shift is None:
        return
    from hydra.utils import get_class

    from torchrl_causal.envs.base import SHIFTS

    if shift not in SHIFTS:
        raise ConfigValueError(f"config value env.shift={shift!r} is not a shift: it must be null (the rotation), {' or '.join(SHIFTS)}")
    target = str(cfg.env.make._target_)
    if not hasattr(get_class(target), "prior_shift"):
        raise ConfigValueError(
            f"config value env.shift={shift!r} is for the gust-confounded mazes: env {cfg.env.name!r} ({target}) has one "
            "deployment shift of its own; leave env.shift null"
        )


def _check_device(cfg: DictConfig) -> None:
    try:
        device = resolve_device(cfg.device)
    except ValueError as error:
        raise ConfigValueError(str(error)) from None
    reason = compile_unavailable(device) if cfg.compile else None
    if reason:
        raise ConfigValueError(f"compile=true cannot run on {device} here: {reason}; set compile=false")
    precision = OmegaConf.select(cfg, "algo.precision")
    reason = bf16_unavailable(device) if precision is not None and Precision(precision) is Precision.bf16 else None
    if reason:
        raise ConfigValueError(f"algo.precision=bf16 cannot run natively on {device} here: {reason}; set algo.precision=fp32")


def _check_algorithm(cfg: DictConfig) -> None:
    """What one algorithm needs beyond the ranges of its fields."""
    algo, schema = cfg.algo, algo_schema_of(cfg)
    if schema is GAILConfig and algo.actor.dropout != 0:
        raise ConfigValueError(
            f"algo.actor.dropout must be 0 for GAIL, got {algo.actor.dropout}: PPO's probability "
            "ratio needs the actor that collected the rollout, not a copy with a fresh dropout mask"
        )
    if not issubclass(schema, OffPolicyConfig):
        return
    if algo.total_steps <= algo.random_steps:
        raise ConfigValueError(
            f"algo.total_steps={algo.total_steps} must be > algo.random_steps={algo.random_steps}: "
            "the run would end in its random warm-up without a gradient step; raise "
            "algo.total_steps or lower algo.random_steps"
        )
    if algo.random_steps % algo.frames_per_batch:
        raise ConfigValueError(
            f"algo.random_steps={algo.random_steps} must be a multiple of algo.frames_per_batch="
            f"{algo.frames_per_batch}: random actions are drawn for whole collector batches"
        )
    if algo.num_envs % cfg.collector_workers:
        raise ConfigValueError(
            f"collector_workers={cfg.collector_workers} must divide algo.num_envs={algo.num_envs}: "
            "each worker process steps the same number of envs"
        )


def _check_target_entropy(cfg: DictConfig) -> None:
    value = OmegaConf.select(cfg, "algo.loss.target_entropy")
    if value is not None and value != "auto" and (isinstance(value, bool) or not isinstance(value, (int, float))):
        raise ConfigValueError(f"config value algo.loss.target_entropy={value!r} must be 'auto' or a number")


def _check_videos(cfg: DictConfig) -> None:
    """Periodic evaluations' videos (``eval.video_periodic``) say how many episodes in ``eval.video``."""
    if OmegaConf.select(cfg, "eval.video_periodic", default=False) and not cfg.eval.video:
        raise ConfigValueError(
            "config value eval.video_periodic=true records the first eval.video episodes of each periodic evaluation, "
            "but eval.video=0: set eval.video=<episodes> too"
        )


def _check_extras(cfg: DictConfig) -> None:
    """An optional package the config needs (a logger's, Minari's) is installed."""
    from torchrl_causal.data.sources import source_problem
    from torchrl_causal.extras import missing_extra

    if cfg.logger._target_ in LOGGER_MODULES:
        choice, module = LOGGER_MODULES[cfg.logger._target_]
        if message := missing_extra(f"logger={choice}", module):
            raise ConfigValueError(message)
    if cfg.logger._target_ == WANDB_TARGET and not cfg.logger.offline and not wandb_login_found():
        raise ConfigValueError(
            "logger.offline=false logs to W&B online, but no W&B login was found (run `wandb login` or set "
            "WANDB_API_KEY); leave logger.offline=true to log offline and `wandb sync` the run later"
        )
    if message := source_problem(cfg.demos.source):
        raise ConfigValueError(message)
    if cfg.eval.video:
        fmt = VideoFormat(cfg.eval.video_format)
        if message := missing_extra(f"eval.video={cfg.eval.video} ({fmt.value})", "imageio", *(("av",) if fmt is VideoFormat.mp4 else ())):
            raise ConfigValueError(message)


def wandb_login_found(environ: Mapping[str, str] | None = None) -> bool:
    """Whether W&B can log online without asking for a key: ``WANDB_API_KEY`` is set, the
    environment asks W&B for an offline or disabled mode anyway, or the netrc file (where
    ``wandb login`` writes the key) holds one for W&B's host.

    Examples:
        >>> wandb_login_found({"WANDB_API_KEY": "0123"}), wandb_login_found({"WANDB_MODE": "offline", "NETRC": "/nonexistent"})
        (True, True)
        >>> wandb_login_found({"NETRC": "/nonexistent"})
        False
    """
    import netrc
    from urllib.parse import urlparse

    environ = os.environ if environ is None else environ
    if environ.get("WANDB_API_KEY") or environ.get("WANDB_MODE") in ("offline", "dryrun", "disabled"):
        return True
    host = urlparse(environ.get("WANDB_BASE_URL", "https://api.wandb.ai")).hostname or "api.wandb.ai"
    try:
        return netrc.netrc(environ.get("NETRC") or None).authenticators(host) is not None
    except (OSError, netrc.NetrcParseError):
        return False


def validate_config(cfg: DictConfig) -> None:
    """Resolves every interpolation of a composed config and checks every range.

    Raises:
        ConfigValueError: naming the key, its value and the allowed range; a key no
            schema declares (added with ``+key=value``); a window as long as the horizon;
            an off-policy budget no longer than its random warm-up; a device this
            machine lacks; ``compile=true`` where torch.compile cannot run; GAIL's actor with dropout; off-policy counts that do not
            divide (``random_steps`` by ``frames_per_batch``, ``num_envs`` by
            ``collector_workers``); the env without an expert; a logger, a
            ``demos.source`` or ``eval.video`` whose package is not installed (naming the
            extra), or a malformed ``demos.source``.
        omegaconf.errors.OmegaConfBaseException: an interpolation that does not resolve or
            a mandatory value left unset, naming the key.

    Examples:
        >>> from torchrl_causal.experiment.config import compose_config
        >>> validate_config(compose_config(["eval.final_episodes=0"]))
        Traceback (most recent call last):
        ...
        torchrl_causal.experiment.schema.ConfigValueError: config value eval.final_episodes=0 is out of range: it must be >= 1
    """
    OmegaConf.to_container(cfg, resolve=True, throw_on_missing=True)
    _check_known_keys(cfg)
    _check_ranges(cfg, "")
    _check_sizes(cfg)
    _check_device(cfg)
    _check_algorithm(cfg)
    _check_target_entropy(cfg)
    _check_expert(cfg)
    _check_shift(cfg)
    _check_videos(cfg)
    _check_extras(cfg)
