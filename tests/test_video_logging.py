"""Evaluation videos in the run's logger and from ``evaluate video=N``: TensorBoard's event
file holds each video as the GIF summary TensorBoard shows, at the step of its evaluation;
a W&B offline run holds each video file as its media; the CSV logger records each file's
path and step; ``evaluate video=N`` writes N videos per regime beside its record (below the
run root for a run not ours) and the same per-episode records as without videos."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
import torch

pytest.importorskip("imageio.v3", reason="the [video] extra is not installed")

from tiny_runs import tiny  # noqa: E402

from torchrl_causal.evaluation.runs import read_scalar_csv  # noqa: E402
from torchrl_causal.evaluation.video_log import read_video_index  # noqa: E402
from torchrl_causal.experiment import compose_config  # noqa: E402
from torchrl_causal.experiment.run_directory import RunDirectory  # noqa: E402
from torchrl_causal.lifecycle import evaluate_run, evaluation_record, evaluation_videos, run  # noqa: E402

# Three BC epochs evaluated at epochs 2 and 3; one GIF video per evaluation, a frame every 20 steps.
FILMED = ("eval.video=1", "eval.video_format=gif", "eval.video_every=20")


def _bc_run(root: Path, *extra: str):
    cfg = compose_config([*tiny("bc", *FILMED, "eval.video_periodic=true", *extra), f"run_root={root}"])
    run(cfg)
    return cfg, RunDirectory(cfg.run_dir)


def _expected_videos(run_dir: RunDirectory, evaluated_at: list[int], final_step: int) -> dict[tuple[str, int], Path]:
    """``(tag, step) -> file`` of every video such a run writes: one per periodic evaluation, one per regime at the end."""
    expected = {("video/periodic/episode_0", step): run_dir.periodic_video_dir(step) / "episode_0.gif" for step in evaluated_at}
    for regime in ("train", "deploy"):
        expected[(f"video/final/{regime}/episode_0", final_step)] = run_dir.video_dir / regime / "episode_0.gif"
    assert all(path.is_file() for path in expected.values())
    return expected


def test_csv_logger_records_each_videos_path_and_step(tmp_path) -> None:
    cfg, run_dir = _bc_run(tmp_path)
    evaluated_at = [step for step, _ in read_scalar_csv(run_dir.train_curve_file)]
    assert evaluated_at == [2, 3]  # the BC run's periodic evaluations: every 2 epochs, and the last
    index = read_video_index(run_dir.log_dir)
    assert {(tag, step): path for step, tag, path in index} == _expected_videos(run_dir, evaluated_at, final_step=3)
    assert len(index) == 4


def test_tensorboard_event_file_holds_each_video_at_its_step(tmp_path) -> None:
    pytest.importorskip("tensorboard", reason="the [tensorboard] extra is not installed")
    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

    cfg, run_dir = _bc_run(tmp_path, "logger=tensorboard")
    images: dict[tuple[str, int], bytes] = {}
    evaluated_at: list[int] = []
    for events in sorted({path.parent for path in run_dir.path.rglob("events.out.tfevents.*")}):
        accumulator = EventAccumulator(str(events), size_guidance={"images": 0})
        accumulator.Reload()
        for tag in accumulator.Tags()["images"]:
            for image in accumulator.Images(tag):
                assert (tag, image.step) not in images, (tag, image.step)
                images[(tag, image.step)] = image.encoded_image_string
                assert (image.width, image.height) == (240, 240)
        if "eval/train_return" in accumulator.Tags()["scalars"]:
            evaluated_at = [event.step for event in accumulator.Scalars("eval/train_return")]
    assert evaluated_at == [2, 3]
    expected = _expected_videos(run_dir, evaluated_at, final_step=3)
    assert images.keys() == expected.keys()
    for key, path in expected.items():
        assert images[key] == path.read_bytes(), key  # the video's own GIF, as TensorBoard plays it
    assert not run_dir.video_dir.with_name("videos.csv").exists()  # the CSV record is the CSV logger's only


def test_wandb_offline_run_holds_each_video_file(tmp_path, monkeypatch) -> None:
    pytest.importorskip("wandb", reason="the [wandb] extra is not installed")
    monkeypatch.setenv("WANDB_SILENT", "true")
    monkeypatch.delenv("WANDB_MODE", raising=False)
    monkeypatch.delenv("WANDB_API_KEY", raising=False)
    monkeypatch.setenv("NETRC", str(tmp_path / "no-netrc"))  # no login: offline is the default
    # The expert row (no training): its only W&B run is the one the final evaluation opens.
    cfg = compose_config(
        [*tiny("expert", *FILMED, "eval.video=2", "logger=wandb", "logger.project=torchrl-causal-tests"), f"run_root={tmp_path}"]
    )
    run(cfg)
    run_dir = RunDirectory(cfg.run_dir)
    (offline,) = run_dir.path.glob(f"wandb/offline-run-*-{cfg.logger.id}")
    media = sorted((offline / "files" / "media" / "videos").rglob("*.gif"))
    for regime in ("train", "deploy"):
        for episode in range(2):
            video = run_dir.video_dir / regime / f"episode_{episode}.gif"
            (logged,) = [path for path in media if path.parent.name == regime and path.name.startswith(f"episode_{episode}_")]
            assert logged.read_bytes() == video.read_bytes(), logged
    assert len(media) == 4
    # the history rows name each tag and its step key (W&B's records are protobuf: tags appear verbatim)
    content = (offline / f"run-{cfg.logger.id}.wandb").read_bytes()
    assert b"video/final/deploy/episode_1" in content and b"video/final/deploy/step" in content


@pytest.fixture(scope="module")
def expert_run(tmp_path_factory) -> Path:
    root = tmp_path_factory.mktemp("expert")
    cfg = compose_config([*tiny("expert", "eval.final_episodes=5", "eval.num_envs=3"), f"run_root={root}"])
    run(cfg)
    return Path(cfg.run_dir)


@pytest.mark.parametrize("regime", ["train", "deploy"])
def test_evaluate_video_writes_n_files_and_the_same_records(expert_run, tmp_path, regime: str) -> None:
    settings = dict(num_envs=3, seed=7, run_root=tmp_path)
    # The expert's action noise is drawn from torch's generator (the evaluate command starts a
    # fresh process): the same state for both evaluations.
    torch.manual_seed(0)
    plain = evaluate_run(expert_run, regime, 5, **settings)
    record = evaluation_record(expert_run, regime, 5, **settings)
    plain_record = json.loads(record.read_text())
    torch.manual_seed(0)
    filmed = evaluate_run(expert_run, regime, 5, **settings, video=4, video_format="gif", video_every=8)
    assert (filmed.successes, filmed.returns, filmed.lengths) == (plain.successes, plain.returns, plain.lengths)
    assert json.loads(record.read_text()) == plain_record
    folder = evaluation_videos(expert_run, regime, 5, **settings)
    assert folder == expert_run / "logs" / "videos" / f"{regime}-n5-seed7-envs3"  # the run is ours: beside its record
    assert sorted(path.name for path in folder.iterdir()) == [f"episode_{i}.gif" for i in range(4)]


def test_evaluate_video_of_a_run_not_ours_goes_below_the_run_root(expert_run, tmp_path) -> None:
    users = expert_run / "notes.txt"  # a file no run wrote: the folder is the user's, not ours to write into
    users.write_text("mine")
    try:
        before = sorted(expert_run.rglob("*"))
        evaluate_run(expert_run, "deploy", 3, num_envs=3, seed=1, run_root=tmp_path / "runs", video=2, video_format="gif", video_every=20)
        folder = evaluation_videos(expert_run, "deploy", 3, num_envs=3, seed=1, run_root=tmp_path / "runs")
        assert folder.is_relative_to(tmp_path / "runs" / "evaluated")
        assert sorted(path.name for path in folder.iterdir()) == ["episode_0.gif", "episode_1.gif"]
        assert sorted(expert_run.rglob("*")) == before
    finally:
        users.unlink()


@pytest.mark.parametrize(
    "arguments, message",
    [
        (["video=-1"], r"^error: video=-1 .*>= 0"),
        (["video=two"], r"^error: video='two' must be an integer"),
        (["episodes=4", "video=5"], r"^error: video=5 asks for more videos than episodes=4"),
        (["video=1", "reuse=true"], r"^error: video=1 records the episodes of a new evaluation, but reuse=true"),
        (["video=1", "video_format=avi"], r"^error: video_format='avi' must be one of mp4, gif"),
        (["video=1", "video_every=0"], r"^error: video_every=0"),
    ],
)
def test_evaluate_refuses_bad_video_settings_in_one_line(expert_run, arguments: list[str], message: str) -> None:
    from torchrl_causal.cli.evaluate import main

    before = sorted(expert_run.rglob("*"))
    with pytest.raises(SystemExit, match=message) as refused:
        main([f"run_dir={expert_run}", *arguments])
    assert "\n" not in str(refused.value)
    assert sorted(expert_run.rglob("*")) == before


def test_periodic_videos_need_a_count() -> None:
    from torchrl_causal.experiment.schema import ConfigValueError, validate_config

    with pytest.raises(ConfigValueError, match=r"eval.video_periodic=true .* eval.video=0"):
        validate_config(compose_config([*tiny("bc"), "eval.video_periodic=true"]))


def test_a_resumed_run_drops_the_video_records_of_the_lost_attempt(tmp_path) -> None:
    from torchrl.record.loggers import CSVLogger

    from torchrl_causal.evaluation.video_log import VideoLog, log_video_file
    from torchrl_causal.trainers.base import _truncate_scalar_logs

    logger = CSVLogger("logs", log_dir=str(tmp_path))
    for step in (100, 200, 300):  # three periodic evaluations; the checkpoint resumed from is at 200
        path = tmp_path / "logs" / "videos" / "periodic" / f"step_{step}" / "episode_0.gif"
        log_video_file(VideoLog(logger, "video/periodic", step), path, torch.zeros(1, 2, 3, 4, 4, dtype=torch.uint8), fps=10)
    _truncate_scalar_logs(tmp_path / "logs", 200)
    assert [(step, tag, path.relative_to(tmp_path)) for step, tag, path in read_video_index(tmp_path / "logs")] == [
        (step, "video/periodic/episode_0", Path(f"logs/videos/periodic/step_{step}/episode_0.gif")) for step in (100, 200)
    ]
