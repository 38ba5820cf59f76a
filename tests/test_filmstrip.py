"""Frame strips of single episodes: the frames are the env's own renders at the steps
they are labelled with, and the strip ends where the episode ends."""

from __future__ import annotations

import matplotlib.image
import numpy as np
import pytest

from torchrl_causal.envs import AntMazeEnv, RouteChoiceEnv
from torchrl_causal.evaluation.rendering import record_filmstrip, save_filmstrips
from torchrl_causal.experts import AntMazeExpert

SIZE = 48


def _episode(seed: int, max_steps: int, **kwargs):
    env = AntMazeEnv(maze="medium", regime="deploy", batch_size=[1], seed=seed)
    return env, record_filmstrip(env, AntMazeExpert(env), max_steps=max_steps, width=SIZE, height=SIZE, **kwargs)


def test_first_frame_is_the_render_after_the_seeded_reset():
    _, strip = _episode(seed=3, max_steps=20, frames=3, every=5)
    fresh = AntMazeEnv(maze="medium", regime="deploy", batch_size=[1], seed=3)
    fresh.reset()
    np.testing.assert_array_equal(strip.frames[0], fresh.render(width=SIZE, height=SIZE)[0])
    assert strip.steps == (0, 10, 20) and strip.length == 20 and not strip.success
    assert not np.array_equal(strip.frames[0], strip.frames[-1])  # the ant moved


def test_a_successful_episode_ends_the_strip_at_the_goal():
    _, strip = _episode(seed=0, max_steps=1000, frames=4, every=100)
    assert strip.success and strip.length < 1000
    assert strip.steps[0] == 0 and strip.steps[-1] == strip.length
    assert list(strip.steps) == sorted(set(strip.steps))


def test_strips_are_saved_one_row_each(tmp_path):
    _, strip = _episode(seed=1, max_steps=10, frames=2, every=5)
    path = save_filmstrips({"Expert": strip, "Expert again": strip}, tmp_path / "strip.png")
    height, width, _ = matplotlib.image.imread(path).shape
    assert height > width / 2  # two rows of two frames


def test_refuses_batches_and_envs_that_cannot_render():
    env = AntMazeEnv(maze="medium", batch_size=[2], seed=0)
    with pytest.raises(ValueError, match="batch size"):
        record_filmstrip(env, AntMazeExpert(env), max_steps=5)
    route_choice = RouteChoiceEnv(batch_size=(1,), seed=0)  # no renderer (RoverMaze has a top-down one)
    with pytest.raises(TypeError, match="cannot render"):
        record_filmstrip(route_choice, lambda td: td, max_steps=5)


def test_cli_draws_one_row_per_run_from_the_same_start(tmp_path, capsys):
    from torchrl_causal.cli.filmstrip import filmstrip_of_run, main
    from torchrl_causal.experiment import compose_config
    from torchrl_causal.lifecycle import run

    tiny = [
        "env=antmaze_medium",
        "env.horizon=30",
        "window.k=2",
        f"run_root={tmp_path}",
        "progress_bar=false",
        "demos.episodes=2",
        "eval.episodes=1",
        "eval.num_envs=1",
        "eval.final_episodes=1",
    ]
    bc = compose_config(
        [
            *tiny,
            "algo=bc",
            "causal=true",
            "algo.actor.hidden=16",
            "algo.actor.num_blocks=1",
            "algo.epochs=1",
            "algo.eval_every=1",
            "algo.batch_size=16",
        ]
    )
    expert = compose_config([*tiny, "algo=expert", "causal=false"])
    for cfg in (bc, expert):
        run(cfg)
    out = tmp_path / "strip.png"
    main([f"runs=[{bc.run_dir},{expert.run_dir}]", "labels=[C-BC,Expert]", f"out={out}", "frames=2", "every=15", "size=32"])
    assert out.is_file() and "C-BC:" in capsys.readouterr().out
    starts = [filmstrip_of_run(cfg.run_dir, frames=2, every=30, size=32).frames[0] for cfg in (bc, expert)]
    np.testing.assert_array_equal(*starts)  # one seed: every row starts from the same state
    with pytest.raises(SystemExit, match="labels"):
        main([f"runs=[{bc.run_dir}]", "labels=[a,b]", f"out={out}"])
    # One video per run, named after its label; the same episode as the strip's.
    videos = tmp_path / "videos"
    main([f"runs=[{bc.run_dir},{expert.run_dir}]", "labels=[C-BC,Expert]", f"out={videos}", "format=gif", "every=15", "size=32"])
    assert sorted(path.name for path in videos.iterdir()) == ["C-BC.gif", "Expert.gif"]
    import imageio.v3 as iio

    frames = iio.imread(videos / "Expert.gif", index=None)
    assert np.abs(frames[0].astype(int) - starts[1].astype(int)).mean() < 3  # GIF's palette: close, not equal
    assert frames.shape[0] == len(filmstrip_of_run(expert.run_dir, frames=1000, every=15, size=32).frames)
    with pytest.raises(SystemExit, match="format='avi' must be one of png, mp4, gif"):
        main([f"runs=[{bc.run_dir}]", f"out={videos}", "format=avi"])
