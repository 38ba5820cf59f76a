"""Evaluation videos in the run's logger, beside their files.

Each recorded episode's file (``<run_dir>/logs/videos/...``) is handed to the run's TorchRL
logger under the tag ``<prefix>/episode_<i>`` at the run's step:

* :class:`~torchrl.record.loggers.TensorboardLogger`: a video summary (an animated GIF in
  TensorBoard's Images tab, what ``SummaryWriter.add_video`` writes);
* :class:`~torchrl.record.loggers.WandbLogger`: a ``wandb.Video`` of the file, logged through
  ``log_metrics`` (so its step goes to the tag group's step key, ``<prefix>/step``, as
  TorchRL logs scalars); offline, the file is copied into the run's ``files/media/videos/``;
* :class:`~torchrl.record.loggers.CSVLogger`: a row ``step,tag,path`` appended to
  ``<logs>/videos.csv`` (the path relative to that folder): a record of where the video is,
  not a second copy of it;
* any other TorchRL logger: its ``log_video``.

Why not TorchRL's ``log_video`` for TensorBoard and W&B: in TorchRL 0.14.1 both need
moviepy (TensorBoard's raises without it; W&B encodes tensors with it), and
``SummaryWriter.add_video`` imports ``moviepy.editor``, which moviepy 2 removed: it prints
a line and writes nothing. The GIF here is encoded with Pillow (the ``[video]`` extra), and
W&B takes the file already written, so no further package is needed.
"""

from __future__ import annotations

import csv
import os
from dataclasses import dataclass
from pathlib import Path

import torch
from torchrl.record.loggers import CSVLogger, Logger, TensorboardLogger, WandbLogger

from torchrl_causal.evaluation.video_encoding import encode_gif, frames_of
from torchrl_causal.experiment.run_directory import VIDEO_INDEX

__all__ = ["VideoLog", "log_video_file", "read_video_index"]


@dataclass(frozen=True)
class VideoLog:
    """Where a group of evaluation videos goes besides its files: ``logger``, under the tags
    ``<prefix>/<file stem>``, at ``step`` (the run's progress when they were recorded)."""

    logger: Logger
    prefix: str
    step: int

    def tag(self, path: Path) -> str:
        """The tag of the video written to ``path``.

        Examples:
            >>> import tempfile
            >>> log = VideoLog(CSVLogger("logs", log_dir=tempfile.mkdtemp()), "video/final/deploy", step=0)
            >>> log.tag(Path("runs/x/episode_3.mp4"))
            'video/final/deploy/episode_3'
        """
        return f"{self.prefix}/{path.stem}"


def log_video_file(log: VideoLog, path: Path, video: torch.Tensor, fps: int) -> None:
    """Hands the video just written to ``path`` (its frames ``video``, ``[1, T, C, H, W]``
    uint8) to ``log.logger`` (see the module docstring)."""
    tag, logger = log.tag(path), log.logger
    if isinstance(logger, TensorboardLogger):
        _tensorboard(logger, tag, path, video, log.step, fps)
    elif isinstance(logger, WandbLogger):
        import wandb

        logger.log_metrics({tag: wandb.Video(str(path))}, step=log.step)
    elif isinstance(logger, CSVLogger):
        _csv_index(Path(logger.experiment.log_dir), tag, path, log.step)
    else:
        logger.log_video(tag, video, step=log.step, fps=fps)


def _tensorboard(logger: TensorboardLogger, tag: str, path: Path, video: torch.Tensor, step: int, fps: int) -> None:
    """The summary ``SummaryWriter.add_video`` would write (an image summary holding a GIF),
    encoded without moviepy: a GIF file's own bytes, an MP4's frames as a GIF."""
    from tensorboard.compat.proto.summary_pb2 import Summary

    frames = frames_of(video)
    encoded = path.read_bytes() if path.suffix == ".gif" else encode_gif(frames, fps)
    height, width, channels = frames.shape[1:]
    image = Summary.Image(height=height, width=width, colorspace=channels, encoded_image_string=encoded)
    logger.experiment.file_writer.add_summary(Summary(value=[Summary.Value(tag=tag, image=image)]), step)


def _csv_index(folder: Path, tag: str, path: Path, step: int) -> None:
    folder.mkdir(parents=True, exist_ok=True)
    with open(folder / VIDEO_INDEX, "a", newline="") as index:
        csv.writer(index).writerow([step, tag, Path(os.path.relpath(path, folder)).as_posix()])


def read_video_index(folder: Path) -> list[tuple[int, str, Path]]:
    """``(step, tag, path)`` of each video the CSV logger of ``folder`` (``<run_dir>/logs``)
    recorded, in the order they were logged; the paths resolved against ``folder``."""
    index = folder / VIDEO_INDEX
    if not index.is_file():
        return []
    with open(index, newline="") as rows:
        return [(int(step), tag, folder / relative) for step, tag, relative in csv.reader(rows)]
