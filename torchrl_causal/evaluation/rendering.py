"""Frame strips of single evaluation episodes, rendered offscreen (the report's picture of
a non-causal imitator walking into walls at deployment while its causal twin reaches the
goal)."""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import matplotlib

matplotlib.use("Agg")  # strips are written on headless machines
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import torch  # noqa: E402
from torchrl.envs import EnvBase, TransformedEnv  # noqa: E402
from torchrl.envs.utils import ExplorationType, set_exploration_type, step_mdp  # noqa: E402

from torchrl_causal.errors import InvalidValueError, RenderingUnavailable
from torchrl_causal.evaluation.figures import save_figure  # noqa: E402
from torchrl_causal.evaluation.metrics import Policy  # noqa: E402

__all__ = [
    "EpisodeOutcome",
    "Filmstrip",
    "RenderingUnavailable",
    "record_filmstrip",
    "renderable_scene",
    "rendered_episode",
    "save_filmstrips",
]


@dataclass(frozen=True)
class Filmstrip:
    """Frames of one episode: ``frames[i]`` is the scene after ``steps[i]`` env steps."""

    frames: tuple[np.ndarray, ...]
    steps: tuple[int, ...]
    success: bool
    length: int


def renderable_scene(env: EnvBase) -> EnvBase:
    """The env that draws ``env``'s frames: ``env`` itself, or the base env under a
    ``TransformedEnv`` (the imitator's view renders the scene it acts in).

    Raises:
        RenderingUnavailable: the env has no ``render`` method.
    """
    base = env.base_env if isinstance(env, TransformedEnv) else env
    if not callable(getattr(base, "render", None)):
        raise RenderingUnavailable(
            f"{type(base).__name__} cannot render frames (no render method): videos and filmstrips need a "
            "maze env (rovermaze_*, antmaze_*, humanoidmaze_*)"
        )
    return base


def _evenly_spaced(count: int, available: int) -> list[int]:
    """``count`` indices from ``range(available)``, first and last included."""
    if available <= count:
        return list(range(available))
    return sorted({round(i * (available - 1) / (count - 1)) for i in range(count)})


@dataclass
class EpisodeOutcome:
    """How a rendered episode ended (filled in as :func:`rendered_episode` runs)."""

    success: bool = False
    length: int = 0


@torch.no_grad()
def rendered_episode(
    env: EnvBase,
    policy: Policy,
    *,
    max_steps: int,
    every: int,
    width: int,
    height: int,
    camera: str | None = None,
    outcome: EpisodeOutcome | None = None,
) -> Iterator[tuple[int, np.ndarray]]:
    """Runs one episode of ``policy`` (its deterministic mode) in ``env`` and yields
    ``(step, frame)``: the render after reset (step 0), after every ``every``-th step, and
    after the last step. ``outcome`` (when given) holds the episode's success and length
    once the generator is exhausted.

    Args:
        env: a MuJoCo maze env with batch size ``(1,)``, possibly inside a
            ``TransformedEnv`` (the imitator's view), seeded by the caller.
        policy: reads the env's observation, writes ``"action"``.
        max_steps: the longest episode to run (the env's horizon).
        every: a frame is rendered every this many steps (and at the end).
        width, height, camera: passed to the env's ``render`` (``camera=None`` looks down
            on the whole maze).
    """
    if tuple(env.batch_size) != (1,):
        raise InvalidValueError(f"recording needs an env with batch size (1,), got {tuple(env.batch_size)}")
    if every < 1 or max_steps < 1:
        raise InvalidValueError(f"need every >= 1 and max_steps >= 1, got {every}, {max_steps}")
    scene = renderable_scene(env)
    outcome = EpisodeOutcome() if outcome is None else outcome

    def render() -> np.ndarray:
        return scene.render(width=width, height=height, camera=camera)[0]

    with set_exploration_type(ExplorationType.DETERMINISTIC):
        td = env.reset()
        yield 0, render()
        for step in range(1, max_steps + 1):
            td = env.step(policy(td))
            outcome.length = step
            outcome.success = bool(td["next", "success"].any())
            done = bool(td["next", "done"].any())
            if step % every == 0 or done or step == max_steps:
                yield step, render()
            if done:
                break
            td = step_mdp(td, keep_other=True)


def record_filmstrip(
    env: EnvBase,
    policy: Policy,
    *,
    max_steps: int,
    frames: int = 6,
    every: int = 10,
    width: int = 240,
    height: int = 240,
    camera: str | None = None,
) -> Filmstrip:
    """Runs one episode of ``policy`` (see :func:`rendered_episode`) and keeps ``frames``
    evenly spaced frames of it, the first (after reset) and the last included.

    Args:
        env, policy, max_steps, width, height, camera: as :func:`rendered_episode` takes them.
        frames: how many frames the strip keeps.
        every: a candidate frame is rendered every this many steps (and at the end).

    Examples:
        >>> from torchrl_causal.envs import AntMazeEnv
        >>> from torchrl_causal.experts import AntMazeExpert
        >>> env = AntMazeEnv(maze="medium", regime="deploy", batch_size=[1], seed=0)
        >>> strip = record_filmstrip(env, AntMazeExpert(env), max_steps=30, frames=3, every=10, width=32, height=32)
        >>> strip.steps, strip.frames[0].shape, strip.length
        ((0, 20, 30), (32, 32, 3), 30)
    """
    if frames < 2:
        raise InvalidValueError(f"need frames >= 2, got {frames}")
    outcome = EpisodeOutcome()
    steps, candidates = zip(
        *rendered_episode(env, policy, max_steps=max_steps, every=every, width=width, height=height, camera=camera, outcome=outcome)
    )
    keep = _evenly_spaced(frames, len(candidates))
    return Filmstrip(tuple(candidates[i] for i in keep), tuple(steps[i] for i in keep), outcome.success, outcome.length)


def save_filmstrips(strips: dict[str, Filmstrip], path: str | Path) -> Path:
    """One row of frames per labelled strip, each frame titled with its step."""
    if not strips:
        raise InvalidValueError("save_filmstrips needs at least one strip")
    columns = max(len(strip.frames) for strip in strips.values())
    fig, axes = plt.subplots(len(strips), columns, figsize=(2.2 * columns, 2.4 * len(strips)), squeeze=False)
    for row, (label, strip) in zip(axes, strips.items()):
        outcome = f"reached the goal at step {strip.length}" if strip.success else f"no goal in {strip.length} steps"
        row[0].set_ylabel(f"{label}\n({outcome})", fontsize=8)
        for ax, index in zip(row, range(columns)):
            ax.set_xticks([])
            ax.set_yticks([])
            if index < len(strip.frames):
                ax.imshow(strip.frames[index])
                ax.set_title(f"t = {strip.steps[index]}", fontsize=8)
            else:
                ax.axis("off")
    return save_figure(fig, path, dpi=110)
