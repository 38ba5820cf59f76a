"""From a resolved config to the pieces every trainer shares: envs, the adjustment
window, the expert, demonstrations and their causal encoding.

Everything the policy sees goes through one :class:`CausalWindowTransform` built from
``cfg.window`` and ``cfg.causal``: the same window encodes online rollouts (collector and
evaluation envs) and the offline demonstrations, so train and test inputs agree.
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from pathlib import Path
from typing import Any

import torch
from hydra.utils import get_object, instantiate
from omegaconf import DictConfig, OmegaConf
from tensordict import TensorDict, TensorDictBase
from tensordict.nn import TensorDictModuleBase
from torchrl.data import Binary
from torchrl.envs import EnvBase, TransformedEnv

from torchrl_causal.experiment.expert_body import recorded_body
from torchrl_causal.experiment.schema import ConfigValueError, WindowMode
from torchrl_causal.graphs.template import TimeSliceTemplate
from torchrl_causal.graphs.window import AdjustmentWindow
from torchrl_causal.transforms import CausalWindowTransform, RelaxedBinaryAction, causal_template, imitator_window

__all__ = [
    "RelaxedBinaryAction",
    "instantiate_with_strings",
    "make_env",
    "env_template",
    "make_window",
    "make_imitator_env",
    "make_policy",
    "make_expert",
    "load_or_collect_demonstrations",
    "check_demonstrations",
    "expert_transitions",
    "observation_dim",
    "TRANSITION_KEYS",
]

log = logging.getLogger(__name__)

# What the IL losses read from a replay batch (the cross-team contract), plus the flag.
TRANSITION_KEYS: tuple = (
    "observation",
    "action",
    ("next", "observation"),
    ("next", "done"),
    ("next", "terminated"),
)


def instantiate_with_strings(node: DictConfig) -> Any:
    """``instantiate(node)`` with the schema's enum values passed as their strings, which
    is what the constructors take (``IQLearnLoss(variant="paper")``, ``reward="logit"``)."""
    return instantiate(OmegaConf.to_container(node, resolve=True, enum_to_str=True))


def make_env(cfg: DictConfig, regime: str, batch_size: int, seed: int) -> EnvBase:
    """The raw confounded env of ``cfg.env`` (every key, latent ones included); ``env.shift``
    is passed on only when it is set, so that envs without that argument build as before."""
    shift = OmegaConf.select(cfg, "env.shift")
    return instantiate(
        cfg.env.make,
        regime=regime,
        batch_size=(batch_size,),
        horizon=cfg.env.horizon,
        confounding_strength=cfg.env.confounding_strength,
        seed=seed,
        **({} if shift is None else {"shift": str(shift)}),
    )


def env_template(cfg: DictConfig) -> TimeSliceTemplate:
    """The causal template of ``cfg.env``'s env, read from its class when the class has
    ``slice_template`` (every :class:`~torchrl_causal.envs.ConfoundedEnv`: no env is built,
    where a MuJoCo maze takes up to 0.2 s to build); an env factory of another kind is built
    once and asked for ``causal_template``."""
    made = get_object(cfg.env.make._target_)
    slice_template = getattr(made, "slice_template", None) if isinstance(made, type) else None
    if callable(slice_template):
        return slice_template()
    env = make_env(cfg, "train", 1, cfg.seed)
    try:
        return causal_template(env)
    finally:
        env.close()


def make_window(cfg: DictConfig) -> AdjustmentWindow:
    """The adjustment window the imitator conditions on (``cfg.causal``, ``cfg.window``),
    computed once per run from the env's template and handed to everything that encodes
    its inputs (collector and evaluation envs, demonstrations).

    Examples:
        >>> from omegaconf import OmegaConf
        >>> cfg = OmegaConf.create({"env": {"make": {"_target_": "torchrl_causal.envs.RouteChoiceEnv"}}, "causal": True,
        ...                         "window": {"k": 0, "mode": "relaxed", "window_matched": False, "drop": []}})
        >>> make_window(cfg).lags
        {'Z': (0,)}
    """
    window = imitator_window(
        env_template(cfg), cfg.window.k, causal=cfg.causal, mode=WindowMode(cfg.window.mode).value, window_matched=cfg.window.window_matched
    )
    try:
        return window.without(cfg.window.drop)
    except ValueError as error:
        raise ConfigValueError(f"window.drop={list(cfg.window.drop)}: {error}") from None


def _needs_relaxation(env: EnvBase) -> bool:
    spec = env.full_action_spec["action"]
    return isinstance(spec, Binary)


def make_imitator_env(cfg: DictConfig, window: AdjustmentWindow, regime: str, batch_size: int, seed: int) -> TransformedEnv:
    """The env as the imitator sees it, a continuous action.

    Its outputs (what the collector stores) are the window's encoding in
    ``"observation"``, the raw admissible variables at the current step, ``"success"``,
    the reward and done flags; the excluded collider (W), the ``"latent"`` variables and
    the confounder under ``"scm"`` are removed (see
    :class:`~torchrl_causal.transforms.CausalWindowTransform`)."""
    base = make_env(cfg, regime, batch_size, seed)
    env = TransformedEnv(base, CausalWindowTransform(window))
    if _needs_relaxation(base):
        env.append_transform(RelaxedBinaryAction())
    return env


def observation_dim(env: EnvBase) -> int:
    """Width of the encoded ``"observation"`` of an imitator env."""
    return int(env.observation_spec["observation"].shape[-1])


def make_policy(cfg: DictConfig, env: EnvBase) -> TensorDictModuleBase:
    """A freshly initialised actor of ``cfg.algo.actor`` for the imitator env ``env``."""
    return instantiate(cfg.algo.actor)(observation_dim(env), env.action_spec)


def make_expert(cfg: DictConfig, env: EnvBase) -> Callable[[TensorDictBase], TensorDictBase]:
    """The env's expert policy (``cfg.env.expert``), which reads the latent variables.

    A run's stored config records the skill body its expert walked (``env.expert_body``,
    :mod:`~torchrl_causal.experiment.expert_body`): that file is walked, not the one
    ``env.expert.weights`` (or the class's default) names today, and it is refused when it is
    missing or holds another body.
    """
    body = recorded_body(cfg)
    weights = None if body is None else body.verified_file()
    if weights is None:
        return instantiate(cfg.env.expert, env)
    return instantiate(cfg.env.expert, env, weights=str(weights))


def load_or_collect_demonstrations(cfg: DictConfig) -> TensorDictBase:
    """The demonstrations of ``cfg.demos``: a Minari dataset when ``cfg.demos.source`` is
    ``minari:<id or path>``, else the set at ``cfg.demos.path``, collected with the expert
    first if it does not exist yet (train regime, ``cfg.demos.episodes`` episodes); with
    ``cfg.demos.successful_only`` only its episodes that reached the goal are returned.

    The set must have been recorded in this config's train-regime env (same maze,
    horizon, strength) by this config's expert (same class, settings and weights:
    :func:`~torchrl_causal.data.policy_record`; a retrained skill makes new demonstrations):
    :func:`~torchrl_causal.data.sources.load_source` refuses others.
    The set is a function of the config alone (``demos.seed`` seeds the env and the
    expert's noise), so runs started side by side that both collect it write the same set;
    collection is atomic and one copy wins. Collection leaves torch's random state as it
    found it, so a run that collects the set trains exactly as one that loads it.
    """
    from torchrl_causal.data import collect_demonstrations, successful_episodes
    from torchrl_causal.data.demonstrations import DatasetError
    from torchrl_causal.data.sources import load_source, minari_reference

    path = Path(cfg.demos.path)
    reference = _expected_demonstrations(cfg)
    if minari_reference(cfg.demos.source) is None and not path.exists():
        episodes = cfg.demos.episodes
        env = make_env(cfg, "train", min(episodes, 64), cfg.demos.seed)
        # The expert's noise seeds itself from the global generator. Seeding it from
        # demos.seed makes the set a function of the config alone (not of the training seed
        # or of what the run drew before), and the fork leaves the run's own draws as they
        # were, so whether this run or another collected the set changes nothing later.
        try:
            with torch.random.fork_rng():
                torch.manual_seed(cfg.demos.seed)
                collect_demonstrations(env, make_expert(cfg, env), episodes, path, seed=cfg.demos.seed, progress=cfg.progress_bar)
        except OSError:
            if not path.exists():
                raise
            # Another run finished collecting the same set first (rename onto its folder failed).
        finally:
            env.close()
    try:
        demonstrations = load_source(cfg.demos.source, path, expected=reference)
    except DatasetError as error:
        raise DatasetError(f"{error}. {_demonstrations_remedy(cfg)}") from None
    if not cfg.demos.successful_only:
        return demonstrations
    kept = successful_episodes(demonstrations)
    log.info(
        "demos.successful_only: %d of %d demonstration episodes reached the goal (%d of %d transitions kept)",
        int(kept["is_init"].sum()),
        int(demonstrations["is_init"].sum()),
        kept.shape[0],
        demonstrations.shape[0],
    )
    return kept


def _expected_demonstrations(cfg: DictConfig) -> dict[str, Any]:
    """What the demonstrations of ``cfg`` must record: the train-regime env's config and, for
    a set in our format (collected here, not a Minari dataset from elsewhere) when the env
    names an expert, that expert's :func:`~torchrl_causal.data.policy_record`."""
    from torchrl_causal.data import policy_record
    from torchrl_causal.data.demonstrations import env_expectation
    from torchrl_causal.data.sources import minari_reference

    env = make_env(cfg, "train", 1, cfg.demos.seed)
    try:
        expected = env_expectation(env)
        if minari_reference(cfg.demos.source) is None and cfg.env.get("expert") is not None:
            # An expert seeds its noise from the global generator: building one only to read its
            # record must leave the run's draws as they were.
            with torch.random.fork_rng():
                expected |= policy_record(make_expert(cfg, env))
        return expected
    finally:
        env.close()


def _demonstrations_remedy(cfg: DictConfig) -> str:
    """What to do about the unusable set at ``cfg.demos.path``. Deleting it is advised only
    for a set this package wrote (its metadata names the expert that collected it), naming
    that path and expert; a file or folder of anything else is never ours to delete."""
    from torchrl_causal.data.demonstrations import DatasetError, read_metadata

    path = Path(cfg.demos.path)
    elsewhere = "point demos.path at a good copy, or at a path that does not exist yet (the set is collected there)"
    if not path.is_dir():
        return f"demos.path={path} is not a demonstration set's folder; nothing was changed: {elsewhere}"
    try:
        metadata = read_metadata(path)
    except DatasetError:
        return f"{path} is not a demonstration set written by torchrl-causal; nothing was changed: {elsewhere}"
    expert = metadata.get("policy") or "an unrecorded expert"
    return (
        f"Nothing was changed. {path} is a set collected by {expert}: delete that folder and rerun to collect it again "
        f"(demos.seed {cfg.demos.seed}), or {elsewhere}"
    )


def check_demonstrations(cfg: DictConfig) -> None:
    """Refuses the demonstrations of ``cfg.demos`` before a run starts (see
    :func:`~torchrl_causal.data.sources.check_source`): a wrong env, a missing key,
    corrupted data. A set still to be collected passes."""
    from torchrl_causal.data.demonstrations import DatasetError
    from torchrl_causal.data.sources import check_source, minari_reference

    try:
        check_source(cfg.demos.source, cfg.demos.path, _expected_demonstrations(cfg))
    except DatasetError as error:
        if minari_reference(cfg.demos.source) is not None:
            raise
        raise DatasetError(f"{error}. {_demonstrations_remedy(cfg)}") from None


def expert_transitions(window: AdjustmentWindow, demonstrations: TensorDictBase) -> TensorDict:
    """Demonstrations encoded by ``window`` into the replay format, ``"expert"`` = True.

    Binary actions are kept as 0/1 floats, which is what :class:`RelaxedBinaryAction`
    presents to the actor.
    """
    encoded = CausalWindowTransform(window).encode_trajectories(demonstrations)
    out = encoded.select(*TRANSITION_KEYS).clone()
    out.set("action", out.get("action").to(torch.float32))
    out.set("expert", torch.ones((*out.batch_size, 1), dtype=torch.bool))
    return out
