"""Frame strips of one evaluation episode per run, rendered offscreen, one row per run:
``python -m torchrl_causal.filmstrip runs=[<dir>,<dir>] labels=[C-SQIL,SQIL] out=strip.png``;
or a video of that episode per run, ``format=mp4`` or ``format=gif`` (the ``[video]`` extra):
``out`` is then a folder that gets ``<label>.mp4`` for each run (every ``every``-th step
is a frame, at ``fps`` frames per second).

Each run's selected policy (``checkpoints/best.pt``; the expert row rebuilds its expert)
acts in one ``regime`` episode (default ``deploy``) seeded with ``seed``, in the
imitator's view of its own run; ``frames`` evenly spaced frames are kept, looked at from
above the whole maze (``camera=<name>`` picks an MJCF camera, e.g. ``track``). Every run
gets the same seed, so every row starts from the same state and sees the same gusts.
Needs a maze env: RoverMaze draws its top-down view with torch; the MuJoCo mazes need an
offscreen GL context (EGL on a headless machine, or ``MUJOCO_GL=osmesa``).
"""

from __future__ import annotations

import re
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from pathlib import Path
from typing import Any

from torchrl.envs import EnvBase

from torchrl_causal.cli.arguments import Option, argv_or_sys, one_line_errors, parse_arguments
from torchrl_causal.evaluation.metrics import Policy
from torchrl_causal.evaluation.rendering import Filmstrip, RenderingUnavailable, record_filmstrip, save_filmstrips
from torchrl_causal.evaluation.video import VIDEO_FORMATS, RecordedVideo, record_video
from torchrl_causal.experiment import CheckpointError
from torchrl_causal.lifecycle import REGIMES, open_run

__all__ = ["OPTIONS", "episode_of_run", "filmstrip_of_run", "main", "video_of_run"]

# Bounded here so that a bad value is refused before any run is opened (record_filmstrip and
# record_video check theirs again, for callers of the library).
OPTIONS: dict[str, Option] = {
    "runs": Option(list, placeholder="[<dir>,...]", help="the run directories, one row (or video) each"),
    "out": Option(str, placeholder="<png, or a folder for videos>", help="the PNG file, or the folder that gets one video per run"),
    "labels": Option(list, None, placeholder="<the runs>", help="each run's row label (and video file name)"),
    "format": Option(str, "png", choices=("png", *VIDEO_FORMATS), help="a frame strip, or videos"),
    "regime": Option(str, "deploy", choices=REGIMES, help="the regime of the episode"),
    "seed": Option(int, 0, ge=0, help="the episode's seed, the same for every run"),
    "frames": Option(int, 6, ge=2, help="frames kept per strip (png)"),
    "every": Option(int, None, ge=1, placeholder="<10 (png), 1 (videos)>", help="one frame every this many steps"),
    "fps": Option(int, 30, ge=1, help="frames per second (videos)"),
    "size": Option(int, 240, ge=1, help="frame width and height in pixels"),
    "camera": Option(str, None, placeholder="<above the whole maze>", help="an MJCF camera, e.g. track"),
}
EXAMPLE = "python -m torchrl_causal.filmstrip runs=[runs/a/c_sqil/seed0,runs/a/sqil/seed0] labels=[C-SQIL,SQIL] out=strip.png"


@contextmanager
def episode_of_run(run_dir: str | Path, regime: str, seed: int) -> Iterator[tuple[EnvBase, Policy, int]]:
    """The imitator's env of ``run_dir`` (batch 1, seeded), its selected policy acting in
    it (the expert for the expert row) and the episode limit."""
    _, evaluator, policy = open_run(run_dir, device="cpu")
    env = evaluator.make_env(regime, 1, seed)
    try:
        if policy is not None:
            policy.eval()  # no dropout
        yield env, evaluator.acting_policy(policy, env), evaluator.cfg.env.horizon
    finally:
        env.close()


def filmstrip_of_run(
    run_dir: str | Path,
    *,
    regime: str = "deploy",
    seed: int = 0,
    frames: int = 6,
    every: int = 10,
    size: int = 240,
    camera: str | None = None,
) -> Filmstrip:
    """One ``regime`` episode of the selected policy of ``run_dir`` (see the module docstring)."""
    with episode_of_run(run_dir, regime, seed) as (env, acting, horizon):
        return record_filmstrip(env, acting, max_steps=horizon, frames=frames, every=every, width=size, height=size, camera=camera)


def video_of_run(
    run_dir: str | Path,
    path: str | Path,
    *,
    regime: str = "deploy",
    seed: int = 0,
    every: int = 1,
    fps: int = 30,
    size: int = 240,
    camera: str | None = None,
) -> RecordedVideo:
    """The same episode as :func:`filmstrip_of_run`, as a video at ``path`` (``.mp4`` / ``.gif``)."""
    with episode_of_run(run_dir, regime, seed) as (env, acting, horizon):
        return record_video(env, acting, path, max_steps=horizon, every=every, fps=fps, width=size, height=size, camera=camera)


def _file_name(label: str) -> str:
    return re.sub(r"[^\w.-]+", "_", label).strip("_") or "run"


def _record_all(runs: list[str], labels: list[str], record: Callable[[str, str], Any]) -> dict[str, Any]:
    recorded = {}
    for label, run in zip(labels, runs):
        result = record(label, run)
        outcome = f"goal at step {result.length}" if result.success else f"no goal in {result.length} steps"
        print(f"{label}: {run} {outcome}")
        recorded[label] = result
    return recorded


def main(argv: Sequence[str] | None = None) -> Path:
    """The command line (see the module docstring); a missing run, a broken checkpoint or an
    env that cannot render stops with one line."""
    args = parse_arguments("filmstrip", argv_or_sys(argv), OPTIONS, about=__doc__, example=EXAMPLE)
    with one_line_errors(CheckpointError, RenderingUnavailable):
        return _main(args)


def _main(args: dict[str, Any]) -> Path:
    runs = args["runs"]
    labels = args["labels"] or runs
    if len(labels) != len(runs):
        raise SystemExit(f"error: labels names {len(labels)} rows for {len(runs)} runs")
    fmt = args["format"]
    # every's default is the recorder's own (10 for a strip, 1 for a video)
    episode = {key: args[key] for key in ("regime", "seed", "every", "size", "camera") if args[key] is not None}
    if fmt == "png":
        strips = _record_all(runs, labels, lambda label, run: filmstrip_of_run(run, **episode, frames=args["frames"]))
        path = save_filmstrips(strips, args["out"])
        print(f"wrote {path}")
        return path
    folder = Path(args["out"])
    if len({_file_name(label) for label in labels}) != len(labels):
        raise SystemExit(f"error: labels {labels} do not give one file name each")
    _record_all(
        runs,
        labels,
        lambda label, run: video_of_run(run, folder / f"{_file_name(label)}.{fmt}", **episode, fps=args["fps"]),
    )
    print(f"wrote {len(runs)} {fmt} file(s) to {folder}")
    return folder


if __name__ == "__main__":
    main()
