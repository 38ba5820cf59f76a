"""Demonstration datasets: round trip, format invariants, atomic writes and corruption handling."""

from __future__ import annotations

import json
import os
import shutil
import stat
from pathlib import Path

import pytest
import torch
from tensordict import MemoryMappedTensor, TensorDict

from torchrl_causal.data import (
    DatasetError,
    collect_demonstrations,
    load_demonstrations,
    read_metadata,
    successful_episodes,
)
from torchrl_causal.envs import RouteChoiceEnv, RoverMazeEnv
from torchrl_causal.experts import RoverExpert

EPISODES = 12


def _collect(path: Path, seed: int = 0, **kwargs):
    env = RoverMazeEnv(maze="u", batch_size=(EPISODES,), horizon=400)
    return collect_demonstrations(env, RoverExpert(env, seed=seed), EPISODES, path, seed=seed, progress=False, **kwargs)


@pytest.fixture(scope="module")
def dataset(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("demos") / "u"
    _collect(path)
    return path


@pytest.fixture
def copy(dataset, tmp_path) -> Path:
    target = tmp_path / "copy"
    shutil.copytree(dataset, target)
    return target


def test_round_trip_and_format(dataset):
    data = load_demonstrations(dataset)
    assert data.batch_dims == 1 and isinstance(data["P"], MemoryMappedTensor)
    for key in ("P", "L", "W", ("latent", "O"), ("scm", "U"), "action", "success", ("next", "P"), ("next", "reward")):
        assert key in data.keys(include_nested=True), key
    episode, is_init, done = data["episode"], data["is_init"].squeeze(-1), data["next", "done"].squeeze(-1)
    assert episode.dtype == torch.int64 and data["is_init"].shape == (data.shape[0], 1)
    assert torch.equal(episode.unique_consecutive(), torch.arange(EPISODES))
    # each episode starts with is_init, ends with its only done, and is a contiguous trajectory
    starts = torch.cat((torch.tensor([True]), episode[1:] != episode[:-1]))
    ends = torch.cat((episode[1:] != episode[:-1], torch.tensor([True])))
    assert torch.equal(is_init, starts) and torch.equal(done, ends)
    inner = ~ends[:-1]
    assert torch.equal(data["next", "P"][:-1][inner], data["P"][1:][inner])
    assert (data["L"][is_init] == 0).all()


def test_metadata_records_the_collection(dataset):
    metadata = read_metadata(dataset)
    assert metadata["env"]["class"].endswith("RoverMazeEnv")
    assert (metadata["env"]["maze"], metadata["env"]["horizon"], metadata["env"]["confounding_strength"]) == ("u", 400, 1.0)
    assert metadata["regime"] == "train" and metadata["seed"] == 0 and metadata["episodes"] == EPISODES
    data = load_demonstrations(dataset)
    assert metadata["transitions"] == data.shape[0]
    success = data["next", "success"][data["next", "done"]].float().mean().item()
    assert metadata["expert_success_rate"] == success == 1.0


def test_dataset_directory_gets_the_umask_mode(dataset):
    umask = os.umask(0)
    os.umask(umask)
    assert stat.S_IMODE(dataset.stat().st_mode) == 0o777 & ~umask  # not mkdtemp's private 0700


def test_seed_reproduces_the_dataset(dataset, tmp_path):
    again = _collect(tmp_path / "again")
    assert (again == load_demonstrations(dataset)).all()


def test_expected_metadata_is_enforced(dataset):
    load_demonstrations(dataset, expected={"regime": "train", "env": {"maze": "u"}})
    load_demonstrations(dataset, expected=RoverMazeEnv(maze="u", batch_size=(3,), horizon=400))
    with pytest.raises(DatasetError, match="env.maze"):
        load_demonstrations(dataset, expected={"env": {"maze": "large"}})
    with pytest.raises(DatasetError, match="horizon"):
        load_demonstrations(dataset, expected=RoverMazeEnv(maze="u", batch_size=(3,), horizon=1000))
    with pytest.raises(DatasetError, match="regime"):
        load_demonstrations(dataset, expected={"regime": "deploy"})


def test_truncated_file_is_refused(copy):
    file = copy / "data" / "P.memmap"
    file.write_bytes(file.read_bytes()[:-16])
    with pytest.raises(DatasetError, match="'P' is truncated"):
        load_demonstrations(copy)


def test_edited_metadata_is_refused(copy):
    metadata = json.loads((copy / "metadata.json").read_text())
    metadata["regime"] = "deploy"
    (copy / "metadata.json").write_text(json.dumps(metadata))
    with pytest.raises(DatasetError, match="checksum"):
        load_demonstrations(copy)


def test_edited_values_are_refused(copy):
    file = copy / "data" / "action.memmap"
    raw = bytearray(file.read_bytes())
    raw[0] ^= 0xFF
    file.write_bytes(bytes(raw))
    with pytest.raises(DatasetError, match="checksum"):
        load_demonstrations(copy)
    assert load_demonstrations(copy, verify_checksum=False).shape[0] > 0


def test_missing_key_is_named(copy):
    meta_file = copy / "data" / "latent" / "meta.json"
    meta = json.loads(meta_file.read_text())
    del meta["O"]
    meta_file.write_text(json.dumps(meta))
    (copy / "data" / "latent" / "O.memmap").unlink()
    with pytest.raises(DatasetError, match="latent.O"):
        load_demonstrations(copy)


def test_not_a_dataset_or_wrong_version(copy, tmp_path):
    with pytest.raises(DatasetError, match="metadata.json"):
        load_demonstrations(tmp_path / "nowhere")
    metadata = json.loads((copy / "metadata.json").read_text())
    metadata["format_version"] = 99
    (copy / "metadata.json").write_text(json.dumps(metadata))
    with pytest.raises(DatasetError, match="format_version"):
        load_demonstrations(copy)


def test_existing_dataset_is_not_overwritten_unless_asked(dataset, tmp_path):
    with pytest.raises(FileExistsError):
        _collect(dataset)
    target = tmp_path / "replace"
    shutil.copytree(dataset, target)
    env = RouteChoiceEnv(batch_size=(16,))
    expert = lambda td: td.set("action", (td["Z"] != td["latent", "O"]).float())  # noqa: E731
    replaced = collect_demonstrations(env, expert, 20, target, overwrite=True, progress=False)
    assert replaced.shape == (20,) and read_metadata(target)["env"]["class"].endswith("RouteChoiceEnv")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["replace"]  # nothing left beside it


def test_interrupted_collection_leaves_nothing(tmp_path, monkeypatch):
    env = RoverMazeEnv(maze="u", batch_size=(4,))
    expert = RoverExpert(env, seed=0)
    calls = {"n": 0}

    def interrupted(td):
        calls["n"] += 1
        if calls["n"] > 20:
            raise KeyboardInterrupt
        return expert(td)

    with pytest.raises(KeyboardInterrupt):
        collect_demonstrations(env, interrupted, 4, tmp_path / "demos", progress=False)
    assert list(tmp_path.iterdir()) == []

    # a failure while writing the files removes the half-written staging directory too
    def failing_memmap(self, *args, **kwargs):
        raise OSError("disk full")

    monkeypatch.setattr(TensorDict, "memmap", failing_memmap)
    with pytest.raises(OSError, match="disk full"):
        collect_demonstrations(RouteChoiceEnv(batch_size=(4,)), lambda td: td.set("action", td["Z"]), 4, tmp_path / "demos", progress=False)
    assert list(tmp_path.iterdir()) == []


def test_successful_episodes_keeps_whole_successful_episodes_only(tmp_path):
    # The rover expert needs 188-201 steps on this maze: a 198-step horizon truncates some episodes
    # (7 of 12 succeed with these seeds; unseeded, the env drew its seed from whatever the tests
    # before this one left in torch's global generator, and once all 12 succeeded).
    env = RoverMazeEnv(maze="u", batch_size=(EPISODES,), horizon=198, seed=0)
    data = collect_demonstrations(env, RoverExpert(env, seed=0), EPISODES, tmp_path / "u", progress=False)
    ends = data["next", "done"].reshape(-1)
    outcome = dict(zip(data["episode"][ends].tolist(), data["next", "success"].reshape(-1)[ends].tolist()))
    assert 0 < sum(outcome.values()) < EPISODES

    kept = successful_episodes(data)
    expected = [episode for episode, success in outcome.items() if success]
    assert kept["episode"].unique().tolist() == expected
    assert kept.shape[0] == sum(int((data["episode"] == episode).sum()) for episode in expected)
    # whole episodes: each starts at is_init and ends at its goal-reaching step
    assert int(kept["is_init"].sum()) == len(expected) == int(kept["next", "success"].sum())
    assert kept["next", "done"].reshape(-1)[-1]


def test_successful_episodes_refuses_a_set_without_success(dataset):
    data = load_demonstrations(dataset)
    with pytest.raises(DatasetError, match="no .'next', 'success'. key"):
        successful_episodes(data.exclude(("next", "success")))
    failed = data.clone()
    failed.set(("next", "success"), torch.zeros_like(failed["next", "success"]))
    with pytest.raises(DatasetError, match=f"no episode of the {EPISODES}"):
        successful_episodes(failed)
