"""Videos of single evaluation episodes (``pip install 'torchrl-causal[video]'``).

The frames go through TorchRL's :class:`~torchrl.record.VideoRecorder`, which hands the
episode to a logger's ``log_video``; :class:`VideoFile` is that logger for one file: an
MP4 (H.264, written with PyAV) or a GIF (Pillow, through imageio), then, given a
:class:`~torchrl_causal.evaluation.video_log.VideoLog`, handed on to the run's own logger.
TorchRL's own ``CSVLogger(video_format="mp4")`` needs torchcodec and a system FFmpeg; PyAV
bundles its FFmpeg, so a ``pip install`` is enough.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch
from tensordict import TensorDict
from torchrl.envs import EnvBase
from torchrl.record import VideoRecorder

from torchrl_causal.errors import InvalidValueError
from torchrl_causal.evaluation.metrics import Policy
from torchrl_causal.evaluation.rendering import EpisodeOutcome, renderable_scene, rendered_episode
from torchrl_causal.evaluation.video_encoding import encode_gif, frames_of, write_mp4
from torchrl_causal.evaluation.video_log import VideoLog, log_video_file

__all__ = [
    "VIDEO_FORMATS",
    "EpisodeVideos",
    "VideoFile",
    "RecordedVideo",
    "check_can_record",
    "record_video",
    "side_by_side",
    "write_video",
]

VIDEO_FORMATS = ("mp4", "gif")


class VideoFile:
    """A logger whose ``log_video`` writes the video to ``path`` (format from its suffix)
    and, with ``log``, hands it on to the run's logger
    (:func:`~torchrl_causal.evaluation.video_log.log_video_file`).

    Args:
        path: ``<name>.mp4`` or ``<name>.gif``.
        fps: frames per second.
        log: the run's logger, the tag prefix and step (``None``: the file only).

    Examples:
        >>> import tempfile
        >>> import imageio.v3 as iio
        >>> path = Path(tempfile.mkdtemp()) / "ramp.gif"
        >>> video = torch.arange(4, dtype=torch.uint8).mul(60).view(1, 4, 1, 1, 1).expand(1, 4, 3, 8, 8)
        >>> VideoFile(path, fps=5).log_video("ramp", video)
        >>> iio.imread(path, index=None)[:, 0, 0, 0].tolist()
        [0, 60, 120, 180]
    """

    def __init__(self, path: str | Path, fps: int = 30, log: VideoLog | None = None) -> None:
        self.path = Path(path)
        if self.path.suffix.lstrip(".") not in VIDEO_FORMATS:
            raise InvalidValueError(f"video file {self.path} must end in one of {['.' + f for f in VIDEO_FORMATS]}")
        if fps < 1:
            raise InvalidValueError(f"fps must be >= 1, got {fps}")
        self.fps = fps
        self.log = log

    def log_video(self, name: str, video: torch.Tensor, step: int | None = None, *, fps: float | None = None, **kwargs: object) -> None:
        """Writes ``video`` (``[1, T, C, H, W]`` or ``[T, C, H, W]`` uint8, as
        :class:`~torchrl.record.VideoRecorder` passes it) at ``fps`` (default: this file's);
        ``name``, ``step`` and other options of other loggers are unused (the run's logger
        gets the tag and step of ``log``)."""
        frames = frames_of(video)
        fps = int(self.fps if fps is None else fps)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        if self.path.suffix == ".gif":
            self.path.write_bytes(encode_gif(frames, fps))
        else:
            write_mp4(self.path, frames, fps)
        if self.log is not None:
            log_video_file(self.log, self.path, video.reshape(1, -1, *video.shape[-3:]), fps)


def _recorder(path: Path, fps: int, log: VideoLog | None = None) -> VideoRecorder:
    """TorchRL's recorder of one episode's frames (``[H, W, 3]`` uint8 under ``"pixels"``),
    whose ``dump`` writes them to ``path`` (and hands them to ``log``'s logger)."""
    return VideoRecorder(logger=VideoFile(path, fps=fps, log=log), tag=path.stem, in_keys=["pixels"], skip=1, make_grid=False)


def _add_frame(recorder: VideoRecorder, frame: np.ndarray) -> None:
    recorder(TensorDict({"pixels": torch.from_numpy(np.ascontiguousarray(frame))}))


@dataclass(frozen=True)
class RecordedVideo:
    """Where one episode's video went and how the episode ended."""

    path: Path
    frames: int
    success: bool
    length: int


def record_video(
    env: EnvBase,
    policy: Policy,
    path: str | Path,
    *,
    max_steps: int,
    every: int = 1,
    fps: int = 30,
    width: int = 240,
    height: int = 240,
    camera: str | None = None,
) -> RecordedVideo:
    """Records one episode of ``policy`` in ``env`` to ``path`` (``.mp4`` or ``.gif``).

    The frames (the render after reset, after every ``every``-th step and after the last;
    see :func:`~torchrl_causal.evaluation.rendering.rendered_episode`) pass through
    TorchRL's :class:`~torchrl.record.VideoRecorder` into a :class:`VideoFile`.

    Examples:
        >>> import tempfile
        >>> from torchrl_causal.envs import AntMazeEnv
        >>> from torchrl_causal.experts import AntMazeExpert
        >>> env = AntMazeEnv(maze="medium", regime="deploy", batch_size=[1], seed=0)
        >>> video = record_video(env, AntMazeExpert(env), Path(tempfile.mkdtemp()) / "ant.gif", max_steps=8,
        ...                      every=4, width=16, height=16)
        >>> video.frames, video.length
        (3, 8)
    """
    path = Path(path)
    recorder = _recorder(path, fps)
    outcome = EpisodeOutcome()
    frames = 0
    for _, frame in rendered_episode(
        env, policy, max_steps=max_steps, every=every, width=width, height=height, camera=camera, outcome=outcome
    ):
        _add_frame(recorder, frame)
        frames += 1
    recorder.dump()
    return RecordedVideo(path, frames, outcome.success, outcome.length)


def write_video(frames: Sequence[np.ndarray], path: str | Path, *, fps: int = 30) -> Path:
    """Writes ``frames`` (each ``[H, W, 3]`` uint8) to ``path`` (``.mp4`` or ``.gif``)
    through TorchRL's :class:`~torchrl.record.VideoRecorder`."""
    path = Path(path)
    recorder = _recorder(path, fps)
    for frame in frames:
        _add_frame(recorder, frame)
    recorder.dump()
    return path


def side_by_side(clips: Sequence[Sequence[np.ndarray]], *, gap: int = 4, gap_colour: int = 255) -> list[np.ndarray]:
    """The frames of ``clips`` (each a sequence of ``[H, W, 3]`` frames of one height) put
    next to each other, left to right, ``gap`` pixels apart: a clip that ends first holds
    its last frame until the longest one ends.

    Examples:
        >>> a = [np.full((2, 2, 3), v, np.uint8) for v in (10, 20, 30)]
        >>> b = [np.full((2, 3, 3), 99, np.uint8)]
        >>> frames = side_by_side([a, b], gap=1)
        >>> len(frames), frames[0].shape, frames[2][0, :, 0].tolist()
        (3, (2, 6, 3), [30, 30, 255, 99, 99, 99])
    """
    if not clips or any(len(clip) == 0 for clip in clips):
        raise InvalidValueError(f"side_by_side needs at least one clip and a frame in each, got clip lengths {[len(c) for c in clips]}")
    heights = {clip[0].shape[0] for clip in clips}
    if len(heights) != 1:
        raise InvalidValueError(f"side_by_side needs clips of one height, got heights {sorted(heights)}")
    spacer = np.full((heights.pop(), gap, 3), gap_colour, dtype=np.uint8)
    frames = []
    for t in range(max(len(clip) for clip in clips)):
        row = [clip[min(t, len(clip) - 1)] for clip in clips]
        frames.append(np.concatenate([part for frame in row for part in (frame, spacer)][:-1], axis=1))
    return frames


def check_can_record(env: EnvBase, *, width: int = 16, height: int = 16, camera: str | None = None) -> None:
    """Draws one small frame of ``env`` (reset here): a run asked for videos learns that
    this machine cannot make them before it trains, not after.

    Raises:
        RenderingUnavailable: the env has no renderer, or no GL context opens for it.
    """
    scene = renderable_scene(env)
    env.reset()
    scene.render(width=width, height=height, camera=camera, rows=[0])


class EpisodeVideos:
    """An :class:`~torchrl_causal.evaluation.metrics.EpisodeObserver` that records the
    first ``count`` episodes of an evaluation as videos ``<folder>/episode_<i>.<fmt>``.

    Each frame is the env's render of the recorded rows only (after the reset, after every
    ``every``-th step and after the episode's last), through TorchRL's
    :class:`~torchrl.record.VideoRecorder` into a :class:`VideoFile`. Rendering reads the
    env's state and draws no random number, so the evaluation's episodes and result are
    the same with or without videos. Frames are held in memory until the episode ends:
    ``count * (horizon / every) * width * height * 3`` bytes at most.

    Args:
        folder: where the files go (created when the first one is written).
        count: how many episodes (the first ones) to record.
        fmt: ``"mp4"`` or ``"gif"``.
        every, fps, width, height, camera: as :func:`record_video` takes them.
        log: also hand each video to this run logger, tagged ``<log.prefix>/episode_<i>``
            at ``log.step`` (:mod:`~torchrl_causal.evaluation.video_log`).

    Examples:
        >>> import tempfile
        >>> from torchrl_causal.envs import RoverMazeEnv
        >>> from torchrl_causal.evaluation import evaluate_policy
        >>> from torchrl_causal.experts import RoverExpert
        >>> env = RoverMazeEnv(maze="u", batch_size=(4,), regime="deploy", horizon=30, seed=0)
        >>> videos = EpisodeVideos(Path(tempfile.mkdtemp()), 2, fmt="gif", every=10, width=32, height=32)
        >>> result = evaluate_policy(env, RoverExpert(env), episodes=4, max_steps=30, regime="deploy", observer=videos)
        >>> [path.name for path in videos.paths], videos.frames
        (['episode_0.gif', 'episode_1.gif'], [4, 4])
    """

    def __init__(
        self,
        folder: str | Path,
        count: int,
        *,
        fmt: str = "mp4",
        every: int = 1,
        fps: int = 30,
        width: int = 240,
        height: int = 240,
        camera: str | None = None,
        log: VideoLog | None = None,
    ) -> None:
        if count < 1 or every < 1:
            raise InvalidValueError(f"EpisodeVideos needs count >= 1 and every >= 1, got {count}, {every}")
        if fmt not in VIDEO_FORMATS:
            raise InvalidValueError(f"video format {fmt!r} is not one of {list(VIDEO_FORMATS)}")
        self.folder, self.count, self.fmt, self.every, self.fps = Path(folder), count, fmt, every, fps
        self.size, self.camera, self.log = (width, height), camera, log
        self.paths: list[Path] = []
        self.frames: list[int] = []
        # batch row -> (index of its video in paths and frames, its episode's recorder)
        self._recorders: dict[int, tuple[int, VideoRecorder]] = {}
        self._steps = 0

    def _render(self, env: EnvBase, rows: list[int]) -> None:
        width, height = self.size
        frames = renderable_scene(env).render(width=width, height=height, camera=self.camera, rows=rows)
        for row, frame in zip(rows, frames):
            video, recorder = self._recorders[row]
            _add_frame(recorder, frame)
            self.frames[video] += 1

    def on_reset(self, env: EnvBase, episodes: range) -> None:
        """Starts a recorder for each row whose episode is among the first ``count``."""
        self._steps = 0
        for row, episode in enumerate(episodes):
            if episode < self.count:
                path = self.folder / f"episode_{episode}.{self.fmt}"
                self._recorders[row] = (len(self.paths), _recorder(path, self.fps, self.log))
                self.paths.append(path)
                self.frames.append(0)
        if self._recorders:
            self._render(env, list(self._recorders))

    def on_step(self, env: EnvBase, stepped: torch.Tensor, ended: torch.Tensor) -> None:
        """Draws the recorded rows that stepped, at every ``every``-th step and at their end."""
        self._steps += 1
        rows = [row for row in self._recorders if stepped[row] and (ended[row] or self._steps % self.every == 0)]
        if rows:
            self._render(env, rows)

    def on_round_end(self) -> None:
        """Writes the round's videos."""
        for _, recorder in self._recorders.values():
            recorder.dump()
        self._recorders = {}
