"""Minari datasets in and out: every template variable kept, a bit-exact round trip, the
same refusals as our own format."""

from __future__ import annotations

import json
import os
import sys
from pathlib import Path

import pytest
import torch

pytest.importorskip("minari", reason="the [minari] extra is not installed")
h5py = pytest.importorskip("h5py")

from torchrl_causal.data import (  # noqa: E402
    DatasetError,
    collect_demonstrations,
    export_minari,
    load_demonstrations,
    load_minari_demonstrations,
    read_metadata,
)
from torchrl_causal.data.minari_format import action_space, from_minari_replay, read_minari_metadata  # noqa: E402
from torchrl_causal.envs import RouteChoiceEnv, RouteChoiceExpert, RoverExpert, RoverMazeEnv  # noqa: E402
from torchrl_causal.transforms import CausalWindowTransform  # noqa: E402

EPISODES = 3
DATASET_ID = "causal/rovermaze-u-v0"


def _env(batch: int = EPISODES) -> RoverMazeEnv:
    return RoverMazeEnv(maze="u", batch_size=(batch,), horizon=300)


@pytest.fixture(scope="module")
def exported(tmp_path_factory) -> tuple[Path, Path]:
    folder = tmp_path_factory.mktemp("minari")
    env = _env()
    collect_demonstrations(env, RoverExpert(env, seed=0), EPISODES, folder / "ours", seed=0, progress=False)
    return folder / "ours", export_minari(folder / "ours", DATASET_ID, root=folder / "datasets")


def _assert_same(actual, expected) -> None:
    keys = set(expected.keys(include_nested=True, leaves_only=True))
    assert set(actual.keys(include_nested=True, leaves_only=True)) == keys
    for key in keys:
        assert actual.get(key).dtype == expected.get(key).dtype, key
        assert torch.equal(actual.get(key), expected.get(key)), key


def _encoded(data):
    window = CausalWindowTransform.from_env(_env(1), 4, causal=True).window
    return CausalWindowTransform(window).encode_trajectories(data)


def test_export_keeps_every_template_variable_and_the_env_config(exported):
    ours, directory = exported
    template = _env(1).causal_template
    metadata = read_minari_metadata(directory)
    space = json.loads(metadata["observation_space"])["subspaces"]
    latent = set(template.latent)
    for variable in template.variables:
        if variable == template.action:
            continue
        where = space["latent"]["subspaces"] if variable in latent else space
        assert variable in where, variable
    assert "U" in space["scm"]["subspaces"]  # the confounder
    assert metadata["torchrl_causal"]["env"] == read_metadata(ours)["env"]
    assert metadata["torchrl_causal"]["env"]["maze"] == "u"
    assert metadata["total_episodes"] == EPISODES
    assert metadata["total_steps"] == load_demonstrations(ours).shape[0]


def test_round_trip_is_bit_exact_and_encodes_alike(exported):
    ours, directory = exported
    expected = load_demonstrations(ours)
    loaded = load_minari_demonstrations(directory, expected=_env(1))
    _assert_same(loaded, expected.to_tensordict())
    _assert_same(_encoded(loaded), _encoded(expected))


def test_loads_by_id_under_minari_datasets_path(exported, monkeypatch):
    ours, directory = exported
    monkeypatch.setenv("MINARI_DATASETS_PATH", str(directory.parent.parent))
    assert load_minari_demonstrations(DATASET_ID).shape == load_demonstrations(ours).shape


@pytest.mark.xfail(
    strict=True,
    reason="torchrl 0.14.1 MinariExperienceReplay writes its data with memmap_like, "
    "which keeps shapes, not values: every tensor it returns is zero",
)
def test_through_torchrl_minari_experience_replay(exported, tmp_path, monkeypatch):
    from torchrl.data.datasets import MinariExperienceReplay

    ours, directory = exported
    monkeypatch.setenv("MINARI_DATASETS_PATH", str(directory.parent.parent))
    replay = MinariExperienceReplay(DATASET_ID, batch_size=4, root=tmp_path, download=False, load_from_local_minari=True)
    loaded = from_minari_replay(replay[:].to_tensordict(), read_minari_metadata(directory)["torchrl_causal"])
    _assert_same(_encoded(loaded), _encoded(load_demonstrations(ours)))


def test_refuses_another_env(exported):
    _, directory = exported
    with pytest.raises(DatasetError, match="env.maze"):
        load_minari_demonstrations(directory, expected=RoverMazeEnv(maze="medium", batch_size=(1,), horizon=300))
    with pytest.raises(DatasetError, match="env.horizon"):
        load_minari_demonstrations(directory, expected=_env(1).__class__(maze="u", batch_size=(1,), horizon=200))


@pytest.fixture
def copy(exported, tmp_path) -> Path:
    import shutil

    target = tmp_path / "rovermaze-u-v0"
    shutil.copytree(exported[1], target)
    return target


def _edit(directory: Path, edit) -> None:
    with h5py.File(directory / "data" / "main_data.hdf5", "a") as file:
        edit(file)


def test_refuses_a_missing_key(copy):
    def drop(file):
        for episode in file.values():
            del episode["observations"]["latent"]["O"]

    _edit(copy, drop)
    with pytest.raises(DatasetError, match="latent"):
        load_minari_demonstrations(copy)


def test_refuses_modified_data(copy):
    def nudge(file):
        values = file["episode_1"]["observations"]["P"]
        values[5] = values[5] + 1e-3

    _edit(copy, nudge)
    with pytest.raises(DatasetError, match="checksum"):
        load_minari_demonstrations(copy)
    assert load_minari_demonstrations(copy, verify_checksum=False).shape[0] > 0


def test_refuses_a_truncated_file(copy):
    file = copy / "data" / "main_data.hdf5"
    os.truncate(file, file.stat().st_size // 2)
    with pytest.raises(DatasetError, match="cannot be read"):
        load_minari_demonstrations(copy)


def test_refuses_a_dataset_without_our_metadata(copy):
    metadata_file = copy / "data" / "metadata.json"
    metadata = json.loads(metadata_file.read_text())
    del metadata["torchrl_causal"]
    metadata_file.write_text(json.dumps(metadata))
    with pytest.raises(DatasetError, match="no 'torchrl_causal' metadata"):
        load_minari_demonstrations(copy)


def test_refuses_an_unknown_source(tmp_path, monkeypatch):
    monkeypatch.setenv("MINARI_DATASETS_PATH", str(tmp_path))
    with pytest.raises(DatasetError, match="no Minari dataset 'nothing-v0'"):
        load_minari_demonstrations("nothing-v0")


def test_export_refuses_an_existing_id(exported):
    ours, directory = exported
    with pytest.raises(FileExistsError, match="already exists"):
        export_minari(ours, DATASET_ID, root=directory.parent.parent)


def test_binary_actions_and_flags_come_back_as_booleans(tmp_path):
    env = RouteChoiceEnv(batch_size=(4,), seed=0)
    collect_demonstrations(env, RouteChoiceExpert(env), 6, tmp_path / "ours", seed=0, progress=False)
    directory = export_minari(tmp_path / "ours", "route-v0", root=tmp_path / "datasets")
    _assert_same(load_minari_demonstrations(directory, expected=env), load_demonstrations(tmp_path / "ours").to_tensordict())


def test_missing_extra_names_it(exported, monkeypatch):
    monkeypatch.setitem(sys.modules, "minari", None)
    with pytest.raises(ImportError, match=r"pip install 'torchrl-causal\[minari\]'"):
        load_minari_demonstrations(exported[1])


# ---------------------------------------------------------------- training from a Minari dataset


def test_training_from_the_exported_set_equals_training_from_ours(tmp_path) -> None:
    from test_trainers import tiny_config
    from torchrl_causal.lifecycle import run

    ours = tiny_config(tmp_path / "a", "route_choice", "bc", True)
    results_ours = run(ours)
    exported = export_minari(ours.demos.path, "route-choice-v0", root=tmp_path / "datasets")
    from_minari = tiny_config(tmp_path / "b", "route_choice", "bc", True, f"demos.source=minari:{exported}")
    results_minari = run(from_minari)
    assert not (tmp_path / "b" / "_demos").exists()  # nothing collected
    for regime in ("train", "deploy"):
        assert results_minari[regime].returns == results_ours[regime].returns


def test_a_run_refuses_a_minari_set_of_another_env_before_its_directory(tmp_path, exported) -> None:
    from test_trainers import tiny_config
    from torchrl_causal.lifecycle import run

    cfg = tiny_config(tmp_path / "runs", "route_choice", "bc", True, f"demos.source=minari:{exported[1]}")
    with pytest.raises(DatasetError, match="env.class"):
        run(cfg)
    assert not (tmp_path / "runs").exists()
    bad = tiny_config(tmp_path / "runs", "route_choice", "bc", True, "demos.source=hf:some/set")
    with pytest.raises(Exception, match=r"demos.source='hf:some/set' is not a source"):
        run(bad)
    assert not (tmp_path / "runs").exists()


# ---------------------------------------------------------------- the action space


def _exported_action_space(directory: Path):
    import minari

    return minari.MinariDataset(directory / "data").action_space


def test_export_writes_the_env_action_bounds_and_every_action_lies_inside(exported):
    ours, directory = exported
    env = _env(1)
    space = _exported_action_space(directory)
    low, high = env.action_spec.space.low[0].numpy(), env.action_spec.space.high[0].numpy()
    assert space.shape == tuple(env.action_spec.shape[1:])
    assert (space.low == low).all() and (space.high == high).all()
    assert float(low.min()) > -float("inf") and float(high.max()) < float("inf")
    actions = load_minari_demonstrations(directory).get("action").numpy()
    assert all(space.contains(action) for action in actions)
    # the round trip is unchanged by the bounds: the actions come back bit-identical
    assert torch.equal(torch.as_tensor(actions), load_demonstrations(ours).get("action"))


def test_a_given_env_gives_the_bounds_and_must_be_the_recorded_one(exported, tmp_path):
    ours, _ = exported
    directory = export_minari(ours, "given-v0", root=tmp_path, env=_env(2))
    assert _exported_action_space(directory) == _exported_action_space(exported[1])
    with pytest.raises(DatasetError, match="env.maze"):
        export_minari(ours, "other-v0", root=tmp_path, env=RoverMazeEnv(maze="medium", batch_size=(1,), horizon=300))
    assert not (tmp_path / "other-v0").exists()


def test_binary_actions_are_bounded_to_zero_one(tmp_path):
    env = RouteChoiceEnv(batch_size=(4,), seed=0)
    collect_demonstrations(env, RouteChoiceExpert(env), 6, tmp_path / "ours", seed=0, progress=False)
    space = _exported_action_space(export_minari(tmp_path / "ours", "route-v0", root=tmp_path / "datasets"))
    assert (space.low == 0).all() and (space.high == 1).all()
    assert set(load_demonstrations(tmp_path / "ours").get("action").unique().tolist()) <= {0.0, 1.0}


def test_a_set_whose_env_cannot_be_rebuilt_asks_for_it(exported, tmp_path):
    import shutil

    from torchrl_causal.data.demonstrations import dataset_checksum

    ours = tmp_path / "ours"
    shutil.copytree(exported[0], ours)
    metadata = json.loads((ours / "metadata.json").read_text())
    metadata["env"]["class"] = "somewhere.else.Env"
    metadata["checksum"] = dataset_checksum(load_demonstrations(ours, verify_checksum=False), metadata)
    (ours / "metadata.json").write_text(json.dumps(metadata))
    with pytest.raises(DatasetError, match="pass env="):
        export_minari(ours, "lost-v0", root=tmp_path / "datasets")
    assert not (tmp_path / "datasets" / "lost-v0").exists()


@pytest.mark.parametrize(
    "make",
    [
        lambda: RoverMazeEnv(maze="u", batch_size=(2,), regime="deploy", confounding_strength=0.5),
        lambda: RouteChoiceEnv(batch_size=(2,), regime="deploy", confounding_strength=0.25),
    ],
)
def test_an_env_rebuilt_from_its_config_records_the_same_config(make):
    from torchrl_causal.envs.base import ConfoundedEnv

    env = make()
    rebuilt = ConfoundedEnv.from_config(env.config(), batch_size=(1,))
    assert type(rebuilt) is type(env)
    assert {**rebuilt.config(), "batch_size": None} == {**env.config(), "batch_size": None}
    assert action_space(rebuilt.action_spec, (1,) if isinstance(env, RouteChoiceEnv) else (2,), torch.float32) == action_space(
        env.action_spec, (1,) if isinstance(env, RouteChoiceEnv) else (2,), torch.float32
    )
