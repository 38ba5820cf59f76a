"""Episode videos: decoded back, one frame per recorded step, the first one the env's own
render after the seeded reset."""

from __future__ import annotations

import numpy as np
import pytest
import torch

iio = pytest.importorskip("imageio.v3", reason="the [video] extra is not installed")

from torchrl_causal.envs import AntMazeEnv, RouteChoiceEnv  # noqa: E402
from torchrl_causal.evaluation.video import VideoFile, record_video  # noqa: E402
from torchrl_causal.experts import AntMazeExpert  # noqa: E402

SIZE, STEPS, EVERY, SEED = 64, 60, 10, 3


def _render(env: AntMazeEnv) -> np.ndarray:
    # The ant's tracking camera: the view changes as the ant moves (from above the whole
    # maze, 60 steps of the ant change a few pixels).
    return env.render(width=SIZE, height=SIZE, camera="track")[0].astype(np.int16)


@pytest.mark.parametrize("fmt, tolerance", [("gif", 2.0), ("mp4", 6.0)])
def test_video_decodes_to_the_recorded_steps_from_reset_to_end(tmp_path, fmt: str, tolerance: float) -> None:
    if fmt == "mp4":
        pytest.importorskip("av", reason="the [video] extra is not installed")
    fresh = AntMazeEnv(maze="medium", regime="deploy", batch_size=[1], seed=SEED)
    fresh.reset()
    after_reset = _render(fresh)
    env = AntMazeEnv(maze="medium", regime="deploy", batch_size=[1], seed=SEED)
    video = record_video(
        env, AntMazeExpert(env), tmp_path / f"episode.{fmt}", max_steps=STEPS, every=EVERY, fps=10, width=SIZE, height=SIZE, camera="track"
    )
    at_end = _render(env)  # the env is left in the episode's last state
    decoded = iio.imread(video.path, index=None, **({"plugin": "pyav"} if fmt == "mp4" else {})).astype(np.int16)
    assert video.length == STEPS and video.frames == STEPS // EVERY + 1 == decoded.shape[0]
    assert decoded.shape[1:] == (SIZE, SIZE, 3)
    # Both formats are lossy (GIF's palette, H.264's chroma): each end of the video is close
    # to the env's render of that state and far from the other end's.
    first_error, last_error = np.abs(decoded[0] - after_reset).mean(), np.abs(decoded[-1] - at_end).mean()
    assert first_error < tolerance and last_error < tolerance
    assert np.abs(decoded[0] - at_end).mean() > 5 * tolerance and np.abs(decoded[-1] - after_reset).mean() > 5 * tolerance


def test_every_keeps_a_frame_per_stride_and_the_last(tmp_path) -> None:
    env = AntMazeEnv(maze="medium", regime="deploy", batch_size=[1], seed=SEED)
    video = record_video(env, AntMazeExpert(env), tmp_path / "strided.gif", max_steps=10, every=4, width=16, height=16)
    assert video.frames == 4 == iio.imread(video.path, index=None).shape[0]  # steps 0, 4, 8, 10


def test_refuses_a_format_and_an_env_it_cannot_write(tmp_path) -> None:
    with pytest.raises(ValueError, match=r"must end in one of \['.mp4', '.gif'\]"):
        VideoFile(tmp_path / "episode.avi")
    with pytest.raises(TypeError, match="cannot render"):
        record_video(RouteChoiceEnv(batch_size=(1,), seed=0), lambda td: td, tmp_path / "x.gif", max_steps=2)
    with pytest.raises(ValueError, match="even width and height"):
        VideoFile(tmp_path / "odd.mp4").log_video("odd", torch.zeros(1, 2, 3, 5, 5, dtype=torch.uint8))
