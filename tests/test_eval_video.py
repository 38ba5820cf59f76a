"""Videos of evaluation episodes (``eval.video``): the per-episode records and every random
generator are the same with and without them, each video is its episode (first frame the
render after that row's reset, as many frames as its recorded length asks for, last frame
the row's end state), and a run that cannot make them refuses before it trains."""

from __future__ import annotations

import ctypes.util
import sys

import numpy as np
import pytest
import torch

iio = pytest.importorskip("imageio.v3", reason="the [video] extra is not installed")

from tiny_runs import tiny  # noqa: E402

from torchrl_causal.envs import RouteChoiceEnv, RoverMazeEnv  # noqa: E402
from torchrl_causal.errors import RenderingUnavailable  # noqa: E402
from torchrl_causal.evaluation.metrics import evaluate_policy  # noqa: E402
from torchrl_causal.evaluation.video import EpisodeVideos, check_can_record  # noqa: E402
from torchrl_causal.experts import RoverExpert  # noqa: E402

WIDTH, EPISODES, HORIZON, SIZE = 6, 8, 60, 32


def _evaluate(observer=None, seed=5, regime="deploy"):
    """The expert's evaluation on fresh envs of one seed; the env's and torch's RNG states after it."""
    torch.manual_seed(0)
    env = RoverMazeEnv(maze="u", batch_size=(WIDTH,), regime=regime, horizon=HORIZON, seed=seed)
    result = evaluate_policy(env, RoverExpert(env), episodes=EPISODES, max_steps=HORIZON, regime=regime, observer=observer)
    return env, result, env.rng.get_state(), torch.get_rng_state()


def _gif_frames(path, fps: int) -> np.ndarray:
    """Every frame of a GIF written at ``fps``: the writer (Pillow) merges a frame identical
    to the one before it into that one's duration, which tells how many it stands for."""
    from PIL import Image, ImageSequence

    frames = []
    with Image.open(path) as gif:
        for frame in ImageSequence.Iterator(gif):
            frames += [np.asarray(frame.convert("RGB"))] * round(frame.info["duration"] * fps / 1000)
    return np.stack(frames)


def _frames_of(length: int, every: int) -> int:
    """Frames a recorded episode of ``length`` steps has: after the reset, after every
    ``every``-th step, and after the last one when that is not already a multiple."""
    return 1 + length // every + (1 if length % every else 0)


@pytest.mark.parametrize("every", [1, 7])
def test_videos_change_no_record_and_draw_no_random_number(tmp_path, every: int) -> None:
    _, plain, plain_rng, plain_torch = _evaluate()
    # 7 of 8 episodes over two rounds of 6: the second round records its first row only.
    videos = EpisodeVideos(tmp_path, 7, fmt="gif", every=every, fps=10, width=SIZE, height=SIZE)
    env, recorded, recorded_rng, recorded_torch = _evaluate(videos)
    assert (recorded.successes, recorded.returns, recorded.lengths) == (plain.successes, plain.returns, plain.lengths)
    assert torch.equal(recorded_rng, plain_rng) and torch.equal(recorded_torch, plain_torch)
    assert [path.name for path in videos.paths] == [f"episode_{i}.gif" for i in range(7)]
    for path, frames, length in zip(videos.paths, videos.frames, recorded.lengths):
        assert frames == _frames_of(length, every) == len(_gif_frames(path, fps=10)), path.name
    # The second round's recorded episode (row 0) ended where the env still holds it: its
    # last frame is that state (a rover frame has a few colours: the GIF is exact).
    last = _gif_frames(videos.paths[6], fps=10)[-1]
    np.testing.assert_array_equal(last, env.render(width=SIZE, height=SIZE, rows=[0])[0])


def test_first_frame_is_the_rows_render_after_the_seeded_reset(tmp_path) -> None:
    videos = EpisodeVideos(tmp_path, 3, fmt="gif", every=10, fps=10, width=SIZE, height=SIZE)
    _evaluate(videos)
    fresh = RoverMazeEnv(maze="u", batch_size=(WIDTH,), regime="deploy", horizon=HORIZON, seed=5)
    fresh.reset()
    starts = fresh.render(width=SIZE, height=SIZE)
    firsts = [_gif_frames(path, fps=10)[0] for path in videos.paths]
    for row, first in enumerate(firsts):
        np.testing.assert_array_equal(first, starts[row])
    assert not np.array_equal(firsts[0], firsts[1])  # the rows start apart (jitter and heading)


def test_render_rows_draws_those_rows_of_the_full_render() -> None:
    env = RoverMazeEnv(maze="u", batch_size=(2, 3), seed=1)
    env.reset()
    full = env.render(width=16, height=12).reshape(6, 12, 16, 3)
    np.testing.assert_array_equal(env.render(width=16, height=12, rows=[4, 1]), full[[4, 1]])
    assert env.render(width=16, height=12, rows=[]).shape == (0, 12, 16, 3)
    with pytest.raises(ValueError, match="render row 6 is outside the batch of 6"):
        env.render(width=16, height=12, rows=[6])


def test_refuses_an_env_without_a_renderer_in_one_line() -> None:
    with pytest.raises(RenderingUnavailable, match="RouteChoiceEnv cannot render frames") as caught:
        check_can_record(RouteChoiceEnv(batch_size=(1,), seed=0))
    assert "\n" not in str(caught.value) and isinstance(caught.value, TypeError)


def test_run_writes_videos_in_its_logs_and_the_same_records(tmp_path) -> None:
    pytest.importorskip("av", reason="the [video] extra is not installed")
    from torchrl_causal.experiment import compose_config
    from torchrl_causal.experiment.run_directory import changed_keys
    from torchrl_causal.lifecycle import run

    overrides = tiny("expert", "eval.final_episodes=5", "eval.num_envs=3")
    plain = compose_config([*overrides, f"run_root={tmp_path / 'plain'}"])
    filmed = compose_config([*overrides, f"run_root={tmp_path / 'filmed'}", "eval.video=2", "eval.video_every=8"])
    without, with_videos = run(plain), run(filmed)
    for regime in ("train", "deploy"):
        a, b = without[regime], with_videos[regime]
        assert (a.successes, a.returns, a.lengths) == (b.successes, b.returns, b.lengths)
        folder = tmp_path / "filmed" / filmed.run_name / "logs" / "videos" / regime
        assert sorted(path.name for path in folder.iterdir()) == ["episode_0.mp4", "episode_1.mp4"]
        for episode in range(2):
            frames = iio.imread(folder / f"episode_{episode}.mp4", index=None, plugin="pyav")
            assert frames.shape == (_frames_of(b.lengths[episode], 8), 240, 240, 3)
    # Videos are no part of the run's identity: a finished run resumes with or without them.
    assert changed_keys({"eval": {"episodes": 4}}, {"eval": {"episodes": 4, "video": 3, "video_format": "gif", "video_every": 2}}) == {}


def test_run_without_a_renderer_or_encoder_refuses_before_its_directory(tmp_path, monkeypatch) -> None:
    from torchrl_causal.experiment import compose_config
    from torchrl_causal.experiment.schema import ConfigValueError
    from torchrl_causal.lifecycle import run

    route = compose_config(["env=route_choice", "algo=expert", "eval.video=1", "eval.video_format=gif", f"run_root={tmp_path}"])
    with pytest.raises(RenderingUnavailable, match="cannot render frames"):
        run(route)
    monkeypatch.setitem(sys.modules, "av", None)  # as if PyAV were not installed
    rover = compose_config([*tiny("expert"), "eval.video=1", f"run_root={tmp_path}"])
    with pytest.raises(ConfigValueError, match=r"eval.video=1 \(mp4\) needs av.*pip install 'torchrl-causal\[video\]'"):
        run(rover)
    assert not any(tmp_path.iterdir())


@pytest.mark.skipif(ctypes.util.find_library("EGL") is None, reason="MuJoCo offscreen rendering needs EGL (libegl1)")
def test_mujoco_videos_change_no_record(tmp_path) -> None:
    from torchrl_causal.envs import AntMazeEnv
    from torchrl_causal.experts import AntMazeExpert

    def evaluate(observer=None):
        torch.manual_seed(0)  # the expert's action noise is seeded from torch's generator
        env = AntMazeEnv(maze="medium", regime="deploy", batch_size=[2], horizon=12, seed=3)
        result = evaluate_policy(env, AntMazeExpert(env), episodes=2, max_steps=12, regime="deploy", observer=observer)
        env.close()
        return result, env.rng.get_state()

    plain, plain_rng = evaluate()
    videos = EpisodeVideos(tmp_path, 1, fmt="gif", every=6, width=16, height=16)
    recorded, recorded_rng = evaluate(videos)
    assert recorded.returns == plain.returns and recorded.lengths == plain.lengths and torch.equal(recorded_rng, plain_rng)
    assert videos.frames == [3]  # after reset, step 6, step 12


def test_demo_side_by_side_puts_each_runs_deploy_episode_in_its_panel(tmp_path, monkeypatch, capsys) -> None:
    from torchrl_causal.cli import demo
    from torchrl_causal.cli.filmstrip import filmstrip_of_run
    from torchrl_causal.experiment import compose_config
    from torchrl_causal.lifecycle import run

    # The demo's pair of runs, made tiny: the expert beside a 3-epoch causal BC.
    overrides = lambda algo, causal, root: tiny(algo, f"causal={str(causal).lower()}", f"run_root={root}")  # noqa: E731
    monkeypatch.setattr(demo, "demo_overrides", overrides)
    monkeypatch.setattr(demo, "SIDE_BY_SIDE", (("Expert", "expert", False), ("C-BC", "bc", True)))
    runs = [compose_config(overrides(algo, causal, tmp_path)) for _, algo, causal in demo.SIDE_BY_SIDE]
    for cfg in runs:
        run(cfg)
    # The expert's action noise is seeded from torch's generator when the expert is built
    # (the first panel's, and the first strip's): the same state for both.
    torch.manual_seed(0)
    video = demo.side_by_side_video(tmp_path, tmp_path / "side.gif", every=5, size=32)
    frames = _gif_frames(video.path, fps=20)  # side_by_side_video's default fps
    strips = []
    for cfg in runs:
        torch.manual_seed(0)
        strips.append(filmstrip_of_run(cfg.run_dir, frames=1000, every=5, size=32))
    assert frames.shape == (max(len(strip.frames) for strip in strips), 32, 2 * 32 + 4, 3)
    for panel, strip in zip((frames[:, :, :32], frames[:, :, 36:]), strips):
        np.testing.assert_array_equal(panel[: len(strip.frames)], np.stack(strip.frames))  # the run's own episode
        np.testing.assert_array_equal(panel[len(strip.frames) :], np.broadcast_to(strip.frames[-1], panel[len(strip.frames) :].shape))
        assert f"{strip.length} steps" in video.markdown or f"goal at step {strip.length}" in video.markdown
    assert (frames[:, :, 32:36] == 255).all() and video.markdown.index("Expert (") < video.markdown.index("C-BC (")
