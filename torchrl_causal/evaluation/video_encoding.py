"""Encoding frames as MP4 (H.264, written with PyAV) or GIF (Pillow, through imageio): what
:class:`~torchrl_causal.evaluation.video.VideoFile` writes to disk and what a TensorBoard
video summary carries (an animated GIF, :mod:`~torchrl_causal.evaluation.video_log`).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import torch

from torchrl_causal.errors import InvalidValueError
from torchrl_causal.extras import require_extra

__all__ = ["encode_gif", "frames_of", "write_mp4"]


def frames_of(video: torch.Tensor) -> np.ndarray:
    """``[T, H, W, C]`` uint8 frames of a ``[1, T, C, H, W]`` or ``[T, C, H, W]`` video (as
    TorchRL's :class:`~torchrl.record.VideoRecorder` hands it to a logger).

    Examples:
        >>> frames_of(torch.zeros(1, 5, 3, 4, 6, dtype=torch.uint8)).shape
        (5, 4, 6, 3)
    """
    return video.reshape(-1, *video.shape[-3:]).permute(0, 2, 3, 1).contiguous().numpy()


def encode_gif(frames: np.ndarray, fps: int) -> bytes:
    """The looping GIF of ``frames`` (``[T, H, W, 3]`` uint8) at ``fps``.

    Pillow stores a frame identical to the one before it as a longer duration of that one:
    the GIF plays the same, with fewer frames to decode. GIF durations are whole
    centiseconds, so an fps that divides 100 plays at exactly fps.

    Examples:
        >>> encode_gif(np.zeros((2, 4, 4, 3), np.uint8), fps=10)[:6]
        b'GIF89a'
    """
    require_extra("writing GIF videos", "imageio")
    import imageio.v3 as iio

    return iio.imwrite("<bytes>", frames, extension=".gif", duration=1000 / fps, loop=0)


def write_mp4(path: Path, frames: np.ndarray, fps: int, crf: int = 17) -> None:
    """Writes ``frames`` (``[T, H, W, 3]`` uint8) to ``path`` as H.264 in yuv420p (what every
    player reads; it needs even sides); ``crf`` 17 is visually lossless."""
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
