"""Videos of single evaluation episodes (``pip install 'torchrl-causal[video]'``).

The frames go through TorchRL's :class:`~torchrl.record.VideoRecorder`, which hands the
episode to a logger's ``log_video``; :class:`VideoFile` is that logger for one file: an
MP4 (H.264, written with PyAV) or a GIF (Pillow, through imageio). TorchRL's own
``CSVLogger(video_format="mp4")`` needs torchcodec and a system FFmpeg; PyAV bundles its
FFmpeg, so a ``pip install`` is enough.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch
from tensordict import TensorDict
from torchrl.envs import EnvBase
from torchrl.record import VideoRecorder

from torchrl_causal.errors import InvalidValueError
from torchrl_causal.evaluation.metrics import Policy
from torchrl_causal.evaluation.rendering import EpisodeOutcome, rendered_episode
from torchrl_causal.extras import require_extra

__all__ = ["VIDEO_FORMATS", "VideoFile", "RecordedVideo", "record_video"]

VIDEO_FORMATS = ("mp4", "gif")


class VideoFile:
    """A logger whose ``log_video`` writes the video to ``path`` (format from its suffix).

    Args:
        path: ``<name>.mp4`` or ``<name>.gif``.
        fps: frames per second.

    Examples:
        >>> import tempfile
        >>> import imageio.v3 as iio
        >>> path = Path(tempfile.mkdtemp()) / "ramp.gif"
        >>> video = torch.arange(4, dtype=torch.uint8).mul(60).view(1, 4, 1, 1, 1).expand(1, 4, 3, 8, 8)
        >>> VideoFile(path, fps=5).log_video("ramp", video)
        >>> iio.imread(path, index=None)[:, 0, 0, 0].tolist()
        [0, 60, 120, 180]
    """

    def __init__(self, path: str | Path, fps: int = 30) -> None:
        self.path = Path(path)
        if self.path.suffix.lstrip(".") not in VIDEO_FORMATS:
            raise InvalidValueError(f"video file {self.path} must end in one of {['.' + f for f in VIDEO_FORMATS]}")
        if fps < 1:
            raise InvalidValueError(f"fps must be >= 1, got {fps}")
        self.fps = fps

    def log_video(self, name: str, video: torch.Tensor, step: int | None = None, *, fps: float | None = None, **kwargs: object) -> None:
        """Writes ``video`` (``[1, T, C, H, W]`` or ``[T, C, H, W]`` uint8, as
        :class:`~torchrl.record.VideoRecorder` passes it) at ``fps`` (default: this file's);
        ``name``, ``step`` and other options of other loggers are unused."""
        require_extra("writing videos", "imageio")
        import imageio.v3 as iio

        frames = video.reshape(-1, *video.shape[-3:]).permute(0, 2, 3, 1).contiguous().numpy()
        fps = int(self.fps if fps is None else fps)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        if self.path.suffix == ".gif":
            iio.imwrite(self.path, frames, extension=".gif", duration=1000 / fps, loop=0)
            return
        _write_mp4(self.path, frames, fps)


def _write_mp4(path: Path, frames: np.ndarray, fps: int, crf: int = 17) -> None:
    """H.264 in yuv420p (what every player reads; it needs even sides); ``crf`` 17 is
    visually lossless."""
    av = require_extra("writing MP4 videos", "av")
    height, width = frames.shape[1:3]
    if height % 2 or width % 2:
        raise InvalidValueError(f"an MP4 needs an even width and height, got {width}x{height}")
    with av.open(str(path), "w") as container:
        stream = container.add_stream("libx264", rate=fps, options={"crf": str(crf)})
        stream.width, stream.height, stream.pix_fmt = width, height, "yuv420p"
        for frame in frames:
            container.mux(stream.encode(av.VideoFrame.from_ndarray(frame, format="rgb24")))
        container.mux(stream.encode())  # flush the encoder


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
    writer = VideoFile(path, fps=fps)
    recorder = VideoRecorder(logger=writer, tag=Path(path).stem, in_keys=["pixels"], skip=1, make_grid=False)
    outcome = EpisodeOutcome()
    frames = 0
    for _, frame in rendered_episode(
        env, policy, max_steps=max_steps, every=every, width=width, height=height, camera=camera, outcome=outcome
    ):
        recorder(TensorDict({"pixels": torch.from_numpy(np.ascontiguousarray(frame))}))
        frames += 1
    recorder.dump()
    return RecordedVideo(writer.path, frames, outcome.success, outcome.length)
