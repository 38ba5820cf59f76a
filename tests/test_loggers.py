"""logger=csv|tensorboard|wandb: each writes the same scalars a CSV run of the same config
writes (training is deterministic), and a missing extra stops the run before its run
directory exists, naming the extra."""

from __future__ import annotations

import sys
from pathlib import Path

import pytest
from test_trainers import tiny_config

from torchrl_causal.evaluation.runs import read_scalar_csv
from torchrl_causal.experiment import ConfigValueError
from torchrl_causal.lifecycle import run

BC = ("algo.epochs=4", "algo.eval_every=2")


def _scalars_of_csv(run_dir: Path) -> dict[str, list[tuple[int, float]]]:
    scalars = run_dir / "logs" / "scalars"
    return {str(path.relative_to(scalars).with_suffix("")): read_scalar_csv(path) for path in scalars.rglob("*.csv")}


@pytest.fixture(scope="module")
def csv_scalars(tmp_path_factory) -> dict[str, list[tuple[int, float]]]:
    cfg = tiny_config(tmp_path_factory.mktemp("csv"), "route_choice", "bc", True, *BC)
    run(cfg)
    scalars = _scalars_of_csv(Path(cfg.run_dir))
    assert "eval/train_return" in scalars and len(scalars["eval/train_return"]) >= 2
    return scalars


def test_tensorboard_logs_the_csv_runs_scalars(tmp_path, csv_scalars) -> None:
    pytest.importorskip("tensorboard", reason="the [tensorboard] extra is not installed")
    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

    cfg = tiny_config(tmp_path, "route_choice", "bc", True, *BC, "logger=tensorboard")
    run(cfg)
    (events,) = {path.parent for path in Path(cfg.run_dir).rglob("events.out.tfevents.*")}
    accumulator = EventAccumulator(str(events))
    accumulator.Reload()
    logged = {tag: [(event.step, event.value) for event in accumulator.Scalars(tag)] for tag in accumulator.Tags()["scalars"]}
    assert logged.keys() == csv_scalars.keys()
    for tag, series in csv_scalars.items():
        assert [step for step, _ in logged[tag]] == [step for step, _ in series], tag
        assert [value for _, value in logged[tag]] == pytest.approx([value for _, value in series], rel=1e-6), tag


def test_wandb_offline_logs_the_csv_runs_scalars(tmp_path, csv_scalars, monkeypatch) -> None:
    wandb = pytest.importorskip("wandb", reason="the [wandb] extra is not installed")
    monkeypatch.setenv("WANDB_SILENT", "true")
    monkeypatch.delenv("WANDB_MODE", raising=False)
    logged: dict[str, list[float]] = {}
    original = wandb.sdk.wandb_run.Run.log

    def spy(self, data, *args, **kwargs):  # what reaches W&B's run, in order
        for key, value in data.items():
            if key in csv_scalars:
                logged.setdefault(key, []).append(value)
        return original(self, data, *args, **kwargs)

    monkeypatch.setattr(wandb.sdk.wandb_run.Run, "log", spy)
    cfg = tiny_config(
        tmp_path, "route_choice", "bc", True, *BC, "logger=wandb", "logger.offline=true", "logger.project=torchrl-causal-tests"
    )
    run(cfg)
    assert logged.keys() == csv_scalars.keys()
    for tag, series in csv_scalars.items():
        assert logged[tag] == pytest.approx([value for _, value in series], rel=1e-6), tag
    # The offline run is on disk under the run directory, named by the run's stable id,
    # holding every tag (W&B's records are protobuf: the tag names appear verbatim).
    (record,) = Path(cfg.run_dir).glob(f"wandb/offline-run-*-{cfg.logger.id}/run-{cfg.logger.id}.wandb")
    content = record.read_bytes()
    assert all(tag.encode() in content for tag in csv_scalars)


@pytest.mark.parametrize("logger, extra", [("tensorboard", "tensorboard"), ("wandb", "wandb")])
def test_a_missing_extra_stops_the_run_before_its_directory(tmp_path, monkeypatch, logger: str, extra: str) -> None:
    monkeypatch.setitem(sys.modules, extra, None)  # as if it were not installed
    cfg = tiny_config(tmp_path, "route_choice", "bc", True, *BC, f"logger={logger}")
    with pytest.raises(
        ConfigValueError,
        match=rf"^logger={logger} needs {extra}, which is not installed: "
        rf"pip install 'torchrl-causal\[{extra}\]'$",
    ):
        run(cfg)
    assert list(tmp_path.iterdir()) == []
