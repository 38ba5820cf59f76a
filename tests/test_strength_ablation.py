"""The strength ablation re-evaluates trained runs: a policy that does not read the compass
is unaffected by any strength, strength 0 is the train regime, records are reused."""

from __future__ import annotations

from pathlib import Path

import pytest
import torch
from tiny_runs import tiny

import torchrl_causal.cli.strength_ablation as ablation
from torchrl_causal.evaluation.reporting import NOTES_BEGIN, NOTES_END
from torchrl_causal.evaluation.runs import archive_runs
from torchrl_causal.experiment import compose_config
from torchrl_causal.lifecycle import evaluate_run, run

EPISODES = 8
TINY_BC = tiny("bc", "eval.final_episodes=4", "algo.epochs=2")


@pytest.fixture(scope="module")
def runs_root(tmp_path_factory) -> Path:
    root = tmp_path_factory.mktemp("strength") / "runs"
    for causal in (True, False):
        run(compose_config([*TINY_BC, f"causal={str(causal).lower()}", f"run_root={root}"]))
    return root


def _by_label(records):
    return {(r.label, r.setting.strength): r.evaluations["deploy"] for r in records}


def test_a_causal_policy_is_the_same_at_every_strength_and_strength_zero_is_training(runs_root: Path) -> None:
    results = _by_label(ablation.strength_ablation(runs_root, (0.0, 0.5, 1.0), EPISODES))
    assert {label for label, _ in results} == {"c_bc", "bc"}
    # C-BC's window excludes W: the rotated compass changes nothing it reads
    assert results["c_bc", 0.0].returns == results["c_bc", 0.5].returns == results["c_bc", 1.0].returns
    # BC reads W: turning it changes the episodes
    assert results["bc", 0.0].returns != results["bc", 1.0].returns
    for label in ("c_bc", "bc"):
        run_dir = next(p.parent for p in runs_root.rglob("config.yaml") if p.parent.parent.name == label)
        train = evaluate_run(run_dir, "train", EPISODES, num_envs=4, save=False)
        assert results[label, 0.0].returns == train.returns  # deploy at strength 0 is the train regime


def _refuse_evaluation(monkeypatch) -> None:
    def evaluate_again(*args, **kwargs):
        raise AssertionError("re-evaluated a stored record")

    monkeypatch.setattr("torchrl_causal.lifecycle.open_run", evaluate_again)


def test_stored_records_are_read_back_not_evaluated_again(runs_root: Path, monkeypatch) -> None:
    first = _by_label(ablation.strength_ablation(runs_root, (0.85,), EPISODES))
    _refuse_evaluation(monkeypatch)
    again = _by_label(ablation.strength_ablation(runs_root, (0.85,), EPISODES))
    assert {key: r.returns for key, r in again.items()} == {key: r.returns for key, r in first.items()}
    assert len(list(runs_root.rglob("deploy-n8-seed30000-envs4-cs0.85.json"))) == 2


def test_the_report_has_one_row_per_algorithm_and_a_figure(runs_root: Path, tmp_path: Path, torch_threads) -> None:
    path = ablation.main([f"runs={runs_root}", "strengths=[0,1]", f"episodes={EPISODES}", f"out={tmp_path}", "name=ablation", "threads=2"])
    assert torch.get_num_threads() == 2
    text = path.read_text()
    assert "| Algorithm | Seeds | 0 | 1 |" in text and "| C-BC | 0 |" in text and "| BC | 0 |" in text
    assert (tmp_path / "ablation.png").stat().st_size > 0
    assert f"python -m torchrl_causal.strength_ablation runs={runs_root}" in text


def test_bad_strengths_and_mixed_settings_are_refused(runs_root: Path, tmp_path: Path) -> None:
    with pytest.raises(ValueError, match=r"\[0, 1\]"):
        ablation.strength_ablation(runs_root, (1.5,), EPISODES)
    mixed = tmp_path / "mixed"
    run(compose_config([*TINY_BC, "causal=true", "window.k=1", f"run_root={mixed}"]))
    run(compose_config([*TINY_BC, "causal=true", f"run_root={mixed}"]))
    with pytest.raises(ValueError, match="differ in more than the strength"):
        ablation.strength_ablation(mixed, (1.0,), EPISODES)


def test_an_archive_gives_back_the_stored_records_without_the_checkpoints(runs_root: Path, tmp_path: Path, monkeypatch) -> None:
    first = _by_label(ablation.strength_ablation(runs_root, (0.5,), EPISODES))
    archive_runs(runs_root, tmp_path / "archive")
    assert not list((tmp_path / "archive").rglob("*.pt"))
    _refuse_evaluation(monkeypatch)
    again = _by_label(ablation.strength_ablation(tmp_path / "archive", (0.5,), EPISODES))
    assert {key: r.returns for key, r in again.items()} == {key: r.returns for key, r in first.items()}


def test_notes_written_by_hand_survive_a_rerun(runs_root: Path, tmp_path: Path) -> None:
    args = [f"runs={runs_root}", "strengths=[0,1]", f"episodes={EPISODES}", f"out={tmp_path}", "name=ablation"]
    path = ablation.main(args)
    empty = f"{NOTES_BEGIN}\n{NOTES_END}"
    assert path.read_text().count(empty) == 1  # the place for notes, in every file written
    path.write_text(path.read_text().replace(empty, f"{NOTES_BEGIN}\nWhy BC falls.\n{NOTES_END}"))
    text = ablation.main(args).read_text()
    assert text.count("Why BC falls.") == 1 and "| C-BC | 0 |" in text
    assert text.index("Why BC falls.") < text.index("| Algorithm |")


def test_an_archived_run_without_a_record_is_left_out_at_every_strength_with_a_warning(runs_root: Path, tmp_path: Path, caplog) -> None:
    ablation.strength_ablation(runs_root, (0.5, 1.0), EPISODES)
    archive = tmp_path / "archive"
    archive_runs(runs_root, archive)
    bc_record = next(archive.rglob("bc/seed0/eval/deploy-n8-seed30000-envs4-cs0.5.json"))
    bc_record.unlink()
    records = ablation.strength_ablation(archive, (0.5, 1.0), EPISODES)
    assert {(r.label, r.setting.strength) for r in records} == {("c_bc", 0.5), ("c_bc", 1.0)}
    assert str(bc_record.parents[1]) in caplog.text and "no checkpoints/best.pt" in caplog.text
    table = ablation.strength_markdown(records)
    assert "| Algorithm | Seeds | 0.5 | 1 |" in table and "| C-BC | 0 |" in table and "| BC |" not in table
    with pytest.raises(FileNotFoundError, match="selected policies are gone"):
        ablation.strength_ablation(archive, (0.3,), EPISODES)
