"""logger=csv|tensorboard|wandb: each writes the same scalars a CSV run of the same config
writes (training is deterministic; the ``speed/`` measurements at the same steps), the
run's resolved config once and its speed; a missing extra, or W&B online without a login,
stops the run before its run directory exists, in one line."""

from __future__ import annotations

import math
import sys
import time
from pathlib import Path

import pytest
from omegaconf import OmegaConf
from test_trainers import tiny_config

from torchrl_causal.evaluation.runs import read_scalar_csv
from torchrl_causal.experiment import ConfigValueError
from torchrl_causal.lifecycle import run
from torchrl_causal.trainers.telemetry import SPEED_PREFIX

BC = ("algo.epochs=4", "algo.eval_every=2")
CONFIG_SAMPLE = {"algo.name": "bc", "algo.epochs": 4, "algo.eval_every": 2, "seed": 0, "causal": True}


def _config_leaves(run_dir: Path) -> int:
    """The number of leaves of the run's saved config (an empty mapping counts as one)."""

    def count(node) -> int:
        return sum(count(value) for value in node.values()) if isinstance(node, dict) and node else 1

    return count(OmegaConf.to_container(OmegaConf.load(run_dir / "config.yaml"), resolve=True))


def _assert_same_series(logged: dict, expected: dict) -> None:
    """Same tags, the same steps; the same values but for the speed measurements."""
    assert logged.keys() == expected.keys()
    for tag, series in expected.items():
        if tag.startswith(SPEED_PREFIX):
            assert len(logged[tag]) == len(series), tag
        else:
            assert logged[tag] == pytest.approx(series, rel=1e-6), tag


def _scalars_of_csv(run_dir: Path) -> dict[str, list[tuple[int, float]]]:
    scalars = run_dir / "logs" / "scalars"
    return {str(path.relative_to(scalars).with_suffix("")): read_scalar_csv(path) for path in scalars.rglob("*.csv")}


@pytest.fixture(scope="module")
def csv_scalars(tmp_path_factory) -> dict[str, list[tuple[int, float]]]:
    cfg = tiny_config(tmp_path_factory.mktemp("csv"), "route_choice", "bc", True, *BC)
    started = time.monotonic()
    run(cfg)
    scalars = _scalars_of_csv(Path(cfg.run_dir))
    scalars["elapsed"] = [(0, time.monotonic() - started)]  # not a logged tag: the run's measured length
    scalars["run_dir"] = cfg.run_dir
    assert "eval/train_return" in scalars and len(scalars["eval/train_return"]) >= 2
    return scalars


def _logged(csv_scalars) -> dict[str, list[tuple[int, float]]]:
    return {tag: series for tag, series in csv_scalars.items() if tag not in ("elapsed", "run_dir")}


def test_csv_logs_the_resolved_config_once(csv_scalars) -> None:
    run_dir = Path(csv_scalars["run_dir"])
    (hparams,) = (run_dir / "logs" / "texts").glob("hparams*.txt")
    lines = dict(line.split(": ", 1) for line in hparams.read_text().splitlines())
    assert len(lines) == _config_leaves(run_dir)  # every leaf of config.yaml, once
    for key, value in CONFIG_SAMPLE.items():
        assert lines[key] == str(value), key
    assert lines["run_dir"] == str(run_dir)


def test_speed_is_logged_at_every_evaluation(csv_scalars) -> None:
    logged = _logged(csv_scalars)
    steps = [step for step, _ in logged["eval/train_return"]]
    wall = logged[f"{SPEED_PREFIX}wall_time_s"]
    assert [step for step, _ in wall] == steps
    assert [step for step, _ in logged[f"{SPEED_PREFIX}updates_per_s"]] == steps
    assert f"{SPEED_PREFIX}env_steps_per_s" not in logged  # BC steps no env while it trains
    times = [value for _, value in wall]
    assert times == sorted(times) and 0 < times[0] and times[-1] <= csv_scalars["elapsed"][0][1]
    assert all(0 < value < math.inf for _, value in logged[f"{SPEED_PREFIX}updates_per_s"])


def test_off_policy_speed_counts_env_steps_and_updates(tmp_path) -> None:
    cfg = tiny_config(tmp_path, "route_choice", "sqil", True)
    run(cfg)
    scalars = _scalars_of_csv(Path(cfg.run_dir))
    steps = [step for step, _ in scalars["eval/train_return"]]
    for name in ("env_steps_per_s", "updates_per_s", "wall_time_s"):
        assert [step for step, _ in scalars[f"{SPEED_PREFIX}{name}"]] == steps, name
        assert all(0 < value < math.inf for _, value in scalars[f"{SPEED_PREFIX}{name}"]), name
    status = (Path(cfg.run_dir) / "status.json").read_text()
    assert '"wall_time_s"' in status


def test_tensorboard_logs_the_csv_runs_scalars(tmp_path, csv_scalars) -> None:
    pytest.importorskip("tensorboard", reason="the [tensorboard] extra is not installed")
    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator
    from tensorboard.plugins.hparams import plugin_data_pb2

    cfg = tiny_config(tmp_path, "route_choice", "bc", True, *BC, "logger=tensorboard")
    run(cfg)
    accumulators = []
    for events in sorted({path.parent for path in Path(cfg.run_dir).rglob("events.out.tfevents.*")}):
        accumulators.append(EventAccumulator(str(events)))
        accumulators[-1].Reload()
    # the scalars in the run's event file, the hparams in the one add_hparams writes beside it
    (scalars,) = [accumulator for accumulator in accumulators if accumulator.Tags()["scalars"]]
    logged = {tag: [(event.step, event.value) for event in scalars.Scalars(tag)] for tag in scalars.Tags()["scalars"]}
    expected = _logged(csv_scalars)
    assert {tag: [step for step, _ in series] for tag, series in logged.items()} == {
        tag: [step for step, _ in series] for tag, series in expected.items()
    }
    _assert_same_series(
        {tag: [value for _, value in series] for tag, series in logged.items()},
        {tag: [value for _, value in series] for tag, series in expected.items()},
    )
    hparams = {}
    for accumulator in accumulators:
        try:
            contents = accumulator.PluginTagToContent("hparams")
        except KeyError:  # the scalars' event file: no hparams in it
            continue
        for content in contents.values():
            info = plugin_data_pb2.HParamsPluginData.FromString(content).session_start_info
            hparams.update(
                {key: value.WhichOneof("kind") and getattr(value, value.WhichOneof("kind")) for key, value in info.hparams.items()}
            )
    assert len(hparams) == _config_leaves(Path(cfg.run_dir))
    for key, value in CONFIG_SAMPLE.items():
        assert hparams[key] == value, key


def test_wandb_offline_logs_the_csv_runs_scalars(tmp_path, csv_scalars, monkeypatch) -> None:
    wandb = pytest.importorskip("wandb", reason="the [wandb] extra is not installed")
    monkeypatch.setenv("WANDB_SILENT", "true")
    monkeypatch.delenv("WANDB_MODE", raising=False)
    monkeypatch.delenv("WANDB_API_KEY", raising=False)
    monkeypatch.setenv("NETRC", str(tmp_path / "no-netrc"))  # no login: offline is the default
    logged: dict[str, list[float]] = {}
    original = wandb.sdk.wandb_run.Run.log

    def spy(self, data, *args, **kwargs):  # what reaches W&B's run, in order
        for key, value in data.items():
            if key in csv_scalars:
                logged.setdefault(key, []).append(value)
        return original(self, data, *args, **kwargs)

    monkeypatch.setattr(wandb.sdk.wandb_run.Run, "log", spy)
    cfg = tiny_config(tmp_path, "route_choice", "bc", True, *BC, "logger=wandb", "logger.project=torchrl-causal-tests")
    assert cfg.logger.offline is True
    run(cfg)
    expected = _logged(csv_scalars)
    _assert_same_series(logged, {tag: [value for _, value in series] for tag, series in expected.items()})
    # The offline run is on disk under the run directory, named by the run's stable id,
    # holding every tag (W&B's records are protobuf: the tag names appear verbatim).
    (record,) = Path(cfg.run_dir).glob(f"wandb/offline-run-*-{cfg.logger.id}/run-{cfg.logger.id}.wandb")
    content = record.read_bytes()
    assert all(tag.encode() in content for tag in expected)
    # the run's config: every flattened key of it
    assert all(key.encode() in content for key in CONFIG_SAMPLE)


def test_wandb_online_without_a_login_is_refused_before_the_run_directory(tmp_path, monkeypatch) -> None:
    pytest.importorskip("wandb", reason="the [wandb] extra is not installed")
    for name in ("WANDB_API_KEY", "WANDB_MODE", "WANDB_BASE_URL"):
        monkeypatch.delenv(name, raising=False)
    monkeypatch.setenv("NETRC", str(tmp_path / "no-netrc"))
    cfg = tiny_config(tmp_path / "runs", "route_choice", "bc", True, *BC, "logger=wandb", "logger.offline=false")
    with pytest.raises(ConfigValueError, match=r"^logger.offline=false .* no W&B login was found .*wandb sync") as refused:
        run(cfg)
    assert "\n" not in str(refused.value)
    assert not (tmp_path / "runs").exists()


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
