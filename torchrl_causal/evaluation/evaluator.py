"""Evaluating the policies of one run config: the env they act in, the episodes, the records.

:class:`Evaluator` builds the evaluation env of a run (the imitator's view through the
run's adjustment window, or the raw env for the expert, which reads the latent
variables), runs :func:`~torchrl_causal.evaluation.evaluate_policy` on it, and turns a
result into the record stored in ``eval/*.json`` (with the maze geometry the report's
trajectory figure draws). Training uses it for periodic train-regime evaluation, the
run's end for the final evaluation in both regimes, ``python -m torchrl_causal.evaluate``
for evaluations with other settings.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import torch
from omegaconf import DictConfig, OmegaConf
from tensordict.nn import TensorDictModuleBase
from torchrl.envs import EnvBase
from torchrl.record.loggers import Logger

from torchrl_causal.envs.base import REGIMES
from torchrl_causal.evaluation.metrics import EpisodeObserver, EvaluationResult, Policy, evaluate_policy
from torchrl_causal.evaluation.video import EpisodeVideos
from torchrl_causal.evaluation.video_log import VideoLog
from torchrl_causal.experiment.builders import make_env, make_expert, make_imitator_env, make_policy
from torchrl_causal.experiment.device import for_cpu_env, resolve_device
from torchrl_causal.experiment.run_directory import CONFIG_FILE, PERIODIC_VIDEOS, WINDOW_FILE, CheckpointError, RunDirectory
from torchrl_causal.experiment.schema import EVAL_VIDEO_SIZE, VideoFormat
from torchrl_causal.graphs.window import AdjustmentWindow

__all__ = ["Evaluator", "maze_geometry", "PERIODIC_EVAL_SEED", "FINAL_EVAL_SEED"]

# Evaluation envs are seeded apart from the training env (and from each other), with the
# same seed at every periodic evaluation so checkpoints are compared on the same episodes.
PERIODIC_EVAL_SEED, FINAL_EVAL_SEED = 10_000, 20_000


def maze_geometry(env: EnvBase) -> dict[str, Any] | None:
    """Walls (axis-aligned ``[x0, y0, x1, y1]`` rectangles), start and goal of a maze env
    with a :class:`~torchrl_causal.envs.MazeLayout`, for the report's trajectory figure;
    ``None`` for envs without a maze (Route Choice).

    Examples:
        >>> from torchrl_causal.envs import RoverMazeEnv
        >>> geometry = maze_geometry(RoverMazeEnv(maze="u", batch_size=(1,), seed=0))
        >>> len(geometry["walls"]), geometry["walls"][0]
        (18, [-2.5, 1.5, -1.5, 2.5])
    """
    layout = getattr(env, "layout", None)
    if layout is None:
        return None
    half = layout.cell_size / 2
    centres = layout.cell_center(layout.walls.nonzero()).tolist()
    position = lambda name: getattr(env, name).reshape(-1)[:2].tolist() if hasattr(env, name) else None  # noqa: E731
    return {
        "walls": [[x - half, y - half, x + half, y + half] for x, y in centres],
        "start": position("start_position"),
        "goal": position("goal_position"),
    }


_UNRECORDED = object()


def _check_weights_fit(run: RunDirectory, expected: dict[str, torch.Tensor], found: dict[str, torch.Tensor]) -> None:
    """Refuses weights of another shape than the policy the run's config and window build
    (an edited ``window.json`` or ``config.yaml``), naming the first difference."""
    names = sorted(set(expected) ^ set(found))
    if names:
        what = f"parameter {names[0]!r} is {'missing from' if names[0] in expected else 'unknown to'} them"
    else:
        name = next((n for n in sorted(expected) if tuple(expected[n].shape) != tuple(found[n].shape)), None)
        if name is None:
            return
        what = f"{name!r} is {tuple(found[name].shape)} there, {tuple(expected[name].shape)} here"
    raise CheckpointError(
        f"{run.best_checkpoint} does not fit the policy that {CONFIG_FILE} and {WINDOW_FILE} of {run.path} describe ({what}): "
        "one of them was edited; nothing was evaluated; restore the run's files (an archive keeps a copy) or train it again"
    )


class Evaluator:
    """Evaluates policies of the run configured by ``cfg``.

    Args:
        cfg: the run's config (``env``, ``eval``, ``seed``, ``algo.actor``).
        window: the adjustment window the policy conditions on; ``None`` evaluates in
            the raw env (the expert).
        progress: report progress over episodes.
        device: where :meth:`load_best_policy` puts the policy: ``cfg.device`` as the caller
            resolved it, resolved when a policy is loaded if not given.
    """

    def __init__(
        self, cfg: DictConfig, window: AdjustmentWindow | None, *, progress: bool = False, device: torch.device | None = None
    ) -> None:
        self.cfg = cfg
        self.window = window
        self.progress = progress
        self.device = device

    def make_env(self, regime: str, batch_size: int, seed: int) -> EnvBase:
        """The env a policy of this run acts in."""
        if self.window is None:
            return make_env(self.cfg, regime, batch_size, seed)
        return make_imitator_env(self.cfg, self.window, regime, batch_size, seed)

    def acting_policy(self, policy: Policy | None, env: EnvBase) -> Policy:
        """``policy``, or for ``None`` the env's expert built on ``env`` (it reads that env's latent state)."""
        return make_expert(self.cfg, env) if policy is None else policy

    def evaluate(
        self,
        policy: Policy | None,
        regime: str,
        episodes: int,
        seed: int,
        *,
        trajectories: int = 0,
        num_envs: int | None = None,
        observer: EpisodeObserver | None = None,
    ) -> EvaluationResult:
        """Runs ``policy`` in eval mode (no dropout, deterministic actions) for ``episodes``
        episodes in batches of ``num_envs`` (default ``cfg.eval.num_envs``); ``observer``
        watches them (e.g. records videos) without changing them.

        ``policy=None`` evaluates the env's expert, built for each evaluation env (it
        reads that env's latent state). A policy whose parameters live off the CPU acts
        through :func:`~torchrl_causal.experiment.device.for_cpu_env` (the env steps on the CPU).
        """
        env = self.make_env(regime, min(num_envs or self.cfg.eval.num_envs, episodes), seed)
        acting = self.acting_policy(policy, env)
        module = acting if isinstance(acting, torch.nn.Module) else None  # scripted experts may be plain callables
        was_training = module is not None and module.training
        if module is not None:
            module.eval()
        try:
            return evaluate_policy(
                env,
                for_cpu_env(acting),
                episodes=episodes,
                max_steps=self.cfg.env.horizon,
                regime=regime,
                seeds=[self.cfg.seed],
                position_key=self.cfg.env.position_key,
                trajectories=trajectories,
                progress=self.progress,
                observer=observer,
            )
        finally:
            if module is not None:
                module.train(was_training)
            env.close()

    def periodic(self, policy: Policy, *, video_dir: Path | None = None, logger: Logger | None = None, step: int = 0) -> EvaluationResult:
        """The train-regime evaluation that selects the best checkpoint (``cfg.eval.episodes``
        episodes, the same ones every time); with ``video_dir`` (``eval.video_periodic``),
        its first ``cfg.eval.video`` episodes recorded there and, with ``logger``, logged as
        ``video/periodic/episode_<i>`` at ``step`` (the result is the same with or without them)."""
        observer = None
        if video_dir is not None:
            observer = self.videos(video_dir, VideoLog(logger, f"video/{PERIODIC_VIDEOS}", step) if logger is not None else None)
        return self.evaluate(policy, "train", self.cfg.eval.episodes, PERIODIC_EVAL_SEED + self.cfg.seed, observer=observer)

    def final(
        self, policy: Policy | None, video_dir: Path | None = None, *, logger: Logger | None = None, step: int = 0
    ) -> dict[str, EvaluationResult]:
        """Both regimes on ``cfg.eval.final_episodes`` episodes, ``cfg.eval.trajectories``
        deploy-regime positions kept for the figure; with ``video_dir``, the first
        ``cfg.eval.video`` episodes of each regime recorded to ``<video_dir>/<regime>/``
        and, with ``logger``, logged there as ``video/final/<regime>/episode_<i>`` at
        ``step`` (the results are the same with or without them)."""

        def videos(regime: str) -> EpisodeVideos | None:
            if video_dir is None:
                return None
            return self.videos(video_dir / regime, VideoLog(logger, f"video/final/{regime}", step) if logger is not None else None)

        return {
            regime: self.evaluate(
                policy,
                regime,
                self.cfg.eval.final_episodes,
                FINAL_EVAL_SEED + 1000 * offset + self.cfg.seed,
                trajectories=self.cfg.eval.trajectories,
                observer=videos(regime),
            )
            for offset, regime in enumerate(REGIMES)
        }

    def videos(
        self,
        folder: Path,
        log: VideoLog | None = None,
        *,
        count: int | None = None,
        fmt: str | None = None,
        every: int | None = None,
    ) -> EpisodeVideos | None:
        """The recorder of ``count`` episodes into ``folder``, each also handed to ``log``
        (``None`` when there are none to record). ``count``, ``fmt`` and ``every`` default
        to the config's ``eval.video``, ``eval.video_format`` and ``eval.video_every``."""
        count = int(OmegaConf.select(self.cfg, "eval.video", default=0) or 0) if count is None else count
        if not count:
            return None
        return EpisodeVideos(
            folder,
            count,
            fmt=VideoFormat(OmegaConf.select(self.cfg, "eval.video_format", default="mp4") if fmt is None else fmt).value,
            every=int(OmegaConf.select(self.cfg, "eval.video_every", default=1)) if every is None else every,
            width=EVAL_VIDEO_SIZE,
            height=EVAL_VIDEO_SIZE,
            log=log,
        )

    def record(self, result: EvaluationResult) -> dict[str, Any]:
        """The JSON record of ``result`` (with the maze geometry)."""
        env = make_env(self.cfg, result.regime, 1, 0)
        try:
            return {**result.to_dict(), "maze": maze_geometry(env)}
        finally:
            env.close()

    def load_best_policy(self, run: RunDirectory) -> TensorDictModuleBase:
        """The run's actor rebuilt from the config on ``cfg.device`` with ``checkpoints/best.pt`` loaded."""
        device = resolve_device(self.cfg.device) if self.device is None else self.device
        state = run.load_checkpoint(best=True, map_location=device)
        if state is None:
            raise CheckpointError(
                f"run {run.path} has no checkpoints/best.pt to evaluate (an archived run keeps its "
                "records only): evaluate the original run directory, or train the run again"
            )
        run.check_policy_identity(state["policy"])
        env = self.make_env("train", 1, 0)
        try:
            policy = make_policy(self.cfg, env).to(device)
        finally:
            env.close()
        _check_weights_fit(run, policy.state_dict(), state["policy"])
        policy.load_state_dict(state["policy"])
        return policy

    def check_records(self, run: RunDirectory) -> None:
        """Refuses a run whose config describes another maze than the one its final
        evaluations were recorded in (``eval/<regime>.json``'s ``maze``): an edited
        ``config.yaml`` would evaluate another task under the run's name.

        Raises:
            CheckpointError: naming the record and the config.
        """
        for regime in REGIMES:
            path = run.eval_path(regime)
            if not path.is_file():
                continue
            recorded = run.read_json(path).get("maze", _UNRECORDED)
            if recorded is _UNRECORDED:
                continue
            env = make_env(self.cfg, regime, 1, 0)
            try:
                geometry = json.loads(json.dumps(maze_geometry(env)))  # as the record stores it (lists, not tuples)
            finally:
                env.close()
            if geometry != recorded:
                raise CheckpointError(
                    f"{run.config_file} describes another maze than the one {path.relative_to(run.path)} was recorded in "
                    f"(env.name {self.cfg.env.name!r}): the config was edited; nothing was evaluated; restore it (an "
                    "archive keeps a copy) or train a run of the new config"
                )
