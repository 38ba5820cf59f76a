"""Report generation on a fixture of fake runs (no training).

The fixture reproduces the paper's AntMaze-Medium raw results (Appendix F,
tab:raw-results): the report must turn them into Table 1's normalised E[Y] and success
rates with the paper's standard errors.
"""

from __future__ import annotations

import csv
import json
import math
import shutil
from pathlib import Path

import pytest
from omegaconf import OmegaConf

from torchrl_causal.cli.archive import main as archive_main
from torchrl_causal.cli.report import main as report_main
from torchrl_causal.cli.status import main as status_main
from torchrl_causal.cli.status import run_statuses
from torchrl_causal.evaluation import (
    CSV_COLUMNS,
    TABLE1_ALGORITHMS,
    EvaluationResult,
    aggregate,
    effect_checks,
    load_runs,
    normalised_returns,
    write_report,
)
from torchrl_causal.evaluation.reporting import NOTES_BEGIN, NOTES_END
from torchrl_causal.evaluation.runs import archive_runs, eval_path
from torchrl_causal.evaluation.tables import EffectTargets, seed_effect_checks, seed_spread, seeds_markdown
from torchrl_causal.experiment import RunDirectory

# Appendix F, AntMaze-Medium column: raw E[Y] and success rate (%), deployment regime.
PAPER_RAW = {
    "expert": (-104.0, 87.6),
    "c_bc": (-125.2, 77.9),
    "c_gail": (-135.8, 74.1),
    "c_sqil": (-99.6, 90.7),
    "c_iq_learn": (-118.2, 84.3),
    "bc": (-375.3, 0.0),
    "gail": (-364.9, 0.0),
    "sqil": (-370.7, 0.0),
    "iq_learn": (-372.5, 0.0),
}
# Table 1, AntMaze-Medium: normalised E[Y] (the paper rounds the raw values first, so the
# last digit can differ by 0.1) and success-rate standard errors (%).
PAPER_NORMALISED = {
    "expert": 271.4,
    "c_bc": 250.1,
    "c_gail": 239.5,
    "c_sqil": 275.8,
    "c_iq_learn": 257.1,
    "bc": 0.0,
    "gail": 10.4,
    "sqil": 4.7,
    "iq_learn": 2.8,
}
PAPER_SUCCESS_SE = {"expert": 1.0, "c_bc": 1.3, "c_gail": 1.4, "c_sqil": 0.9, "c_iq_learn": 1.2, "bc": 0.0}


def _episodes(mean_return: float, success_percent: float, n: int, spread: float = 50.0):
    successes = [i < round(success_percent * n / 100) for i in range(n)]
    # symmetric deviations: the mean is exactly mean_return
    returns = [mean_return + (spread if i % 2 else -spread) for i in range(n)]
    lengths = [300 + (i % 7) if s else 1000 for i, s in enumerate(successes)]
    return successes, returns, lengths


def make_fake_run(
    root: Path,
    label: str,
    *,
    seed: int = 0,
    env: str = "antmaze_medium",
    k: int = 10,
    horizon: int = 1000,
    strength: float = 1.0,
    deploy=(None, None),
    train=(None, None),
    episodes: int = 1000,
    curve: bool = True,
    status: str = "complete",
) -> Path:
    """A run directory as the trainers write it: resolved config, status, eval JSONs, curve CSV."""
    causal = label.startswith("c_")
    algo = label[2:] if causal else label
    run_dir = root / env / f"h{horizon}-cs{strength}-k{k}" / label / f"seed{seed}"
    (run_dir / "eval").mkdir(parents=True)
    OmegaConf.save(
        OmegaConf.create(
            {
                "env": {"name": env, "horizon": horizon, "confounding_strength": strength},
                "window": {"k": k, "window_matched": False},
                "algo": {"name": algo},
                "causal": causal,
                "seed": seed,
                "run_dir": str(run_dir),  # with env, algo and seed: what makes the folder provably a run's
            }
        ),
        run_dir / "config.yaml",
    )
    (run_dir / "status.json").write_text(json.dumps({"status": status, "progress": 4, "total": 4, "unit": "epochs"}))
    for regime, (mean_return, success) in (("deploy", deploy), ("train", train)):
        if mean_return is None:
            continue
        s, r, n = _episodes(mean_return, success, episodes)
        result = EvaluationResult(
            regime, s, r, n, seeds=[seed], trajectories=[[[0.0, 0.0], [1.0, 1.0], [2.0, 1.5]]] if regime == "deploy" else ()
        )
        data = result.to_dict()
        data["maze"] = {"walls": [[-1.0, -1.0, 3.0, -0.5]], "goal": [2.0, 2.0], "start": [0.0, 0.0]}
        eval_path(run_dir, regime).write_text(json.dumps(data))
    if curve and label != "expert":
        scalars = run_dir / "logs" / "scalars" / "eval"
        scalars.mkdir(parents=True)
        (scalars / "train_return.csv").write_text("".join(f"{s},{train[0] - 100 + s / 100}\n" for s in (0, 5000, 10000)))
    return run_dir


@pytest.fixture
def paper_runs(tmp_path: Path) -> Path:
    for label, (mean_return, success) in PAPER_RAW.items():
        train_success = 87.0 if label != "expert" else 90.0
        make_fake_run(tmp_path, label, deploy=(mean_return, success), train=(-110.0, train_success))
    return tmp_path


def test_normalised_table_reproduces_paper_table1(paper_runs: Path) -> None:
    ((setting, table),) = aggregate(load_runs(paper_runs)).items()
    assert setting.env == "antmaze_medium" and setting.k == 10
    normalised = normalised_returns(table)
    for label, expected in PAPER_NORMALISED.items():
        assert normalised[label] == pytest.approx(expected, abs=0.15), label
    assert min(normalised.values()) == 0.0
    for label, se in PAPER_SUCCESS_SE.items():
        assert round(100 * table[label]["deploy"].success_se, 1) == se, label
        assert table[label]["deploy"].success_rate == pytest.approx(PAPER_RAW[label][1] / 100)


def test_report_writes_markdown_csv_and_figures(paper_runs: Path, tmp_path: Path) -> None:
    out = tmp_path / "out"
    report = write_report(paper_runs, out, name="antmaze_medium", command="python -m torchrl_causal.train ...")
    with open(report.csv, newline="") as handle:
        reader = csv.DictReader(handle)
        assert tuple(reader.fieldnames) == CSV_COLUMNS
        rows = list(reader)
    assert [(r["algorithm"], r["regime"]) for r in rows] == [(a, g) for a in TABLE1_ALGORITHMS for g in ("train", "deploy")]
    expert_deploy = next(r for r in rows if r["algorithm"] == "expert" and r["regime"] == "deploy")
    assert float(expert_deploy["success_rate"]) == pytest.approx(0.876)
    assert float(expert_deploy["return_mean"]) == pytest.approx(-104.0)
    assert int(expert_deploy["n_episodes"]) == 1000 and int(expert_deploy["seeds"]) == 1
    bc_deploy = next(r for r in rows if r["algorithm"] == "bc" and r["regime"] == "deploy")
    assert bc_deploy["ep_len_mean"] == ""  # no successful episode: no length

    text = report.markdown.read_text()
    header = next(line for line in text.splitlines() if line.startswith("|  | Expert"))
    assert header.split("|")[2:-1] == [
        " " + h + " " for h in ("Expert", "C-BC", "C-GAIL", "C-SQIL", "C-IQ-Learn", "BC", "GAIL", "SQIL", "IQ-Learn")
    ]
    assert "**275.7** ± 50.0" in text  # best non-expert normalised E[Y] in bold (C-SQIL)
    assert "**90.7** ± 0.9" in text
    assert "python -m torchrl_causal.train ..." in text
    names = {p.name for p in report.figures}
    # no success curve in these runs; the aggregate needs only the final evaluations
    assert names == {"antmaze_medium_training_curves.png", "antmaze_medium_trajectories.png", "antmaze_medium_aggregate.png"}
    assert all(p.stat().st_size > 1000 for p in report.figures)


def test_effect_checks_on_the_paper_numbers(paper_runs: Path) -> None:
    (table,) = aggregate(load_runs(paper_runs)).values()
    checks = {c.claim: c.passed for c in effect_checks(table)}
    assert len(checks) == 2 + 4 + 4
    assert all(checks.values())  # the paper's own numbers satisfy the paper's claims
    # a non-causal method at half the expert's deploy success breaks the <= 20% claim
    table["sqil"]["deploy"] = EvaluationResult("deploy", *_episodes(-200.0, 45.0, 100))
    failed = [c for c in effect_checks(table) if not c.passed]
    assert [c.claim for c in failed] == ["SQIL deploy success <= 20% of the expert's"]


def test_effect_targets_set_the_checks_thresholds(paper_runs: Path, tmp_path: Path) -> None:
    (table,) = aggregate(load_runs(paper_runs)).values()
    expert = table["expert"]["deploy"].success_rate
    c_iq_fraction = table["c_iq_learn"]["deploy"].success_rate / expert  # the paper's 84.3 / 87.6 = 0.962
    below, above = EffectTargets(causal_fraction=c_iq_fraction - 0.01), EffectTargets(causal_fraction=c_iq_fraction + 0.01)
    claim = "C-IQ-Learn deploy success >= {:.0%} of the expert's"
    assert {c.claim: c.passed for c in effect_checks(table, below)}[claim.format(c_iq_fraction - 0.01)]
    assert not {c.claim: c.passed for c in effect_checks(table, above)}[claim.format(c_iq_fraction + 0.01)]
    table["sqil"]["train"] = EvaluationResult("train", *_episodes(-110.0, 80.0, 100))  # 7 points below C-SQIL
    gap_claim = "SQIL within {:g} points of C-SQIL (train regime)"
    assert {c.claim: c.passed for c in effect_checks(table)}[gap_claim.format(10)]
    assert not {c.claim: c.passed for c in effect_checks(table, EffectTargets(train_gap_points=5))}[gap_claim.format(5)]

    out = tmp_path / "out"
    report_main([f"runs={paper_runs}", f"out={out}", "name=t", "causal_fraction=0.9", "non_causal_fraction=0.1"])
    text = (out / "t.md").read_text()
    assert "C-SQIL deploy success >= 90% of the expert's" in text and "BC deploy success <= 10%" in text
    with pytest.raises(SystemExit, match="causal_fraction=-0.5"):
        report_main([f"runs={paper_runs}", f"out={out}", "causal_fraction=-0.5"])
    for bad in (float("nan"), True, "0.9"):
        with pytest.raises(ValueError, match="finite and >= 0"):
            EffectTargets(non_causal_fraction=bad)


def test_seeds_pool_and_ablation_plots(tmp_path: Path) -> None:
    for seed in (0, 1):
        make_fake_run(tmp_path, "c_sqil", seed=seed, deploy=(-100.0 - seed * 10, 80.0 + seed * 10), train=(-90.0, 90.0), episodes=100)
    for k, success in ((0, 20.0), (2, 85.0)):
        make_fake_run(tmp_path, "c_sqil", k=k, deploy=(-150.0, success), train=(-90.0, 90.0), episodes=100)
    aggregated = aggregate(load_runs(tmp_path))
    assert len(aggregated) == 3
    main = max(aggregated, key=lambda s: aggregated[s]["c_sqil"]["deploy"].n_episodes)
    pooled = aggregated[main]["c_sqil"]["deploy"]
    assert (pooled.n_episodes, len(set(pooled.seeds))) == (200, 2)
    assert pooled.success_rate == pytest.approx(0.85) and pooled.return_mean == pytest.approx(-105.0)

    report = write_report(tmp_path, tmp_path / "out")
    assert report.main_setting.k == 10  # the setting with the most runs (two seeds)
    assert "antmaze_medium_ablation_k.png" in {p.name for p in report.figures}
    assert not any("ablation_horizon" in p.name for p in report.figures)
    with open(report.all_csv, newline="") as handle:
        assert sorted(int(r["k"]) for r in csv.DictReader(handle)) == [0, 0, 2, 2, 10, 10]


def test_across_seeds_table_has_each_seed_and_the_seed_standard_error(tmp_path: Path) -> None:
    for seed, deploy_success in ((0, 80.0), (1, 90.0), (2, 100.0)):
        make_fake_run(tmp_path, "c_sqil", seed=seed, deploy=(-100.0, deploy_success), train=(-90.0, 90.0), episodes=100)
    make_fake_run(tmp_path, "sqil", seed=0, deploy=(-300.0, 0.0), train=(-90.0, 95.0), episodes=100)
    table = seeds_markdown(load_runs(tmp_path))
    c_sqil = next(line for line in table.splitlines() if line.startswith("| C-SQIL"))
    # deploy: pooled 270 / 300 episodes; mean 90, sample std 10, SE 10 / sqrt(3) = 5.77; IQM of
    # 3 seeds = their mean; the bootstrap distribution of the mean puts 1/27 = 3.7% > 2.5% on 80
    # (all three draws seed 0), so its 2.5% quantile is 80, and symmetrically 100 above: [80, 100].
    assert c_sqil == (
        "| C-SQIL | 0: 90.0, 1: 90.0, 2: 90.0 | 90.0 | 90.0 ± 0.0 | 90.0 [90.0, 90.0] "
        "| 0: 80.0, 1: 90.0, 2: 100.0 | 90.0 | 90.0 ± 5.8 | 90.0 [80.0, 100.0] |"
    )
    assert "| SQIL | 0: 95.0 | 95.0 | 95.0 | 95.0 | 0: 0.0 | 0.0 | 0.0 | 0.0 |" in table  # one seed: no spread
    assert seed_spread([0.2, 0.4]) == pytest.approx((0.3, 0.1))
    with pytest.raises(ValueError, match="at least one"):
        seed_spread([])
    make_fake_run(tmp_path, "expert", deploy=(-90.0, 100.0), train=(-90.0, 100.0), episodes=100)
    (check,) = seed_effect_checks(load_runs(tmp_path), EffectTargets(causal_fraction=0.85))
    assert (check.measured, check.passed) == ("seed 0: 80%, seed 1: 90%, seed 2: 100%", False)
    assert seed_effect_checks(load_runs(tmp_path), EffectTargets(causal_fraction=0.8))[0].passed
    report = write_report(tmp_path, tmp_path / "out")
    text = report.markdown.read_text()
    assert "### Across seeds" in text and "of the expert's in every seed" in text


def test_notes_survive_regeneration_and_cli(paper_runs: Path, tmp_path: Path, capsys) -> None:
    out = tmp_path / "out"
    report_main([f"runs={paper_runs}", f"out={out}", "name=t"])
    md = out / "t.md"
    empty = f"{NOTES_BEGIN}\n{NOTES_END}"
    assert md.read_text().count(empty) == 1  # every report has the place for notes
    md.write_text(md.read_text().replace(empty, f"{NOTES_BEGIN}\nWhy X.\n{NOTES_END}"))
    report_main([f"runs={paper_runs}", f"out={out}", "name=t"])
    assert md.read_text().count("Why X.") == 1
    md.write_text(md.read_text().replace(NOTES_BEGIN, "").replace(NOTES_END, ""))  # markers lost by hand
    with pytest.raises(SystemExit, match="has no notes markers"):
        report_main([f"runs={paper_runs}", f"out={out}", "name=t"])
    assert "Why X." in md.read_text()  # refused, not overwritten
    assert "Norm. E[Y]" in capsys.readouterr().out
    with pytest.raises(SystemExit, match="unknown argument"):
        report_main([f"runs={paper_runs}", "colour=red"])
    with pytest.raises(FileNotFoundError, match="no evaluated runs"):
        write_report(tmp_path / "out", tmp_path / "elsewhere")


def test_command_survives_regeneration_without_one(paper_runs: Path, tmp_path: Path) -> None:
    out = tmp_path / "out"
    write_report(paper_runs, out, name="t", command="python -m torchrl_causal.train seed=0 &&\n  make report")
    md = out / "t.md"
    write_report(paper_runs, out, name="t")
    assert "```bash\npython -m torchrl_causal.train seed=0 &&\n  make report\n```" in md.read_text()
    write_report(paper_runs, out, name="t", command="make demo")
    text = md.read_text()
    assert "make demo" in text and "seed=0" not in text and text.count("Regenerate with:") == 1
    write_report(paper_runs, tmp_path / "fresh", name="t")
    assert "Regenerate with:" not in (tmp_path / "fresh" / "t.md").read_text()


def test_corrupt_run_is_named(tmp_path: Path) -> None:
    run = make_fake_run(tmp_path, "bc", deploy=(-1.0, 1.0), train=(-1.0, 1.0), episodes=4)
    OmegaConf.save(OmegaConf.create({"env": {"name": "x"}}), run / "config.yaml")
    with pytest.raises(ValueError, match="env.horizon"):
        load_runs(tmp_path)
    assert math.isnan(EvaluationResult("deploy", [], [], []).success_rate)


def test_a_run_training_again_is_left_out_with_a_warning(tmp_path: Path, caplog) -> None:
    make_fake_run(tmp_path, "c_sqil", deploy=(-100.0, 90.0), train=(-100.0, 90.0))
    extended = make_fake_run(tmp_path, "sqil", deploy=(-300.0, 0.0), train=(-100.0, 90.0), status="interrupted")
    with caplog.at_level("WARNING"):
        runs = load_runs(tmp_path)
    assert [run.label for run in runs] == ["c_sqil"]
    assert f"left out {extended}: it is interrupted (4 of 4 epochs)" in caplog.text


def test_status_lists_every_run_with_its_state(tmp_path: Path, capsys) -> None:
    make_fake_run(tmp_path, "c_sqil", deploy=(-100.0, 90.0), train=(-100.0, 87.0))
    failed = make_fake_run(tmp_path, "sqil", status="failed", curve=False)
    (failed / "status.json").write_text(
        json.dumps({"status": "failed", "error": "ValueError: bad", "progress": 3, "total": 10, "unit": "rounds"})
    )
    stale = make_fake_run(tmp_path, "c_bc", deploy=(-100.0, 50.0), train=(-100.0, 50.0), status="running")
    (stale / ".hydra").mkdir()
    (stale / ".hydra" / "config.yaml").write_text("{}")
    attempt = {"source": "a", "torch": "2.13.0", "demonstrations": "d1", "compile": True, "device": "cpu"}
    RunDirectory(stale).record_attempt(attempt, progress=0)
    RunDirectory(stale).record_attempt(attempt, progress=2)
    RunDirectory(failed).record_attempt(attempt, progress=0)
    RunDirectory(failed).record_attempt({**attempt, "python": "3.12"}, progress=1)  # not a field that changes numbers
    RunDirectory(failed).record_attempt({**attempt, "demonstrations": "d2", "source": "b"}, progress=2)
    RunDirectory(failed).record_attempt_cost(0, {"wall_s": 7560.0, "cpu_s": 42.4})
    RunDirectory(failed).record_attempt_cost(2, {"wall_s": 750.0, "cpu_s": 700.0})
    rows = {row["run"].split("/")[-2]: row for row in run_statuses(tmp_path)}
    assert sorted(rows) == ["c_bc", "c_sqil", "sqil"]
    assert [rows[label]["attempts"] for label in ("c_sqil", "c_bc", "sqil")] == ["—", "2", "3 (source, demonstrations changed)"]
    # attempts recorded before they had a cost (and one killed outright) read "—"
    assert [rows[label]["cost (wall / CPU)"] for label in ("c_sqil", "c_bc", "sqil")] == [
        "—",
        "—",
        "2.10 h / 42 s + — + 12.5 min / 11.7 min",
    ]
    assert (rows["c_sqil"]["status"], rows["c_sqil"]["progress"], rows["c_sqil"]["deploy success %"]) == (
        "complete",
        "4 / 4 epochs (100%)",
        "90.0",
    )
    assert rows["sqil"]["status"] == "failed: ValueError: bad" and rows["sqil"]["progress"] == "3 / 10 rounds (30%)"
    # no process holds its lock: the "running" it recorded is a dead writer's; its evaluations are not shown
    assert (rows["c_bc"]["status"], rows["c_bc"]["deploy success %"]) == ("killed", "—")
    status_main([f"runs={tmp_path}"])
    assert "| killed |" in capsys.readouterr().out
    with pytest.raises(SystemExit, match="does not exist"):
        status_main([f"runs={tmp_path / 'missing'}"])


def test_the_report_of_an_archive_equals_the_report_of_its_runs(paper_runs: Path, tmp_path_factory) -> None:
    c_sqil = next(paper_runs.rglob("c_sqil/seed0"))
    (c_sqil / "checkpoints").mkdir()
    (c_sqil / "checkpoints" / "best.pt").write_bytes(bytes(64))
    (c_sqil / "replay").mkdir()
    (c_sqil / "replay" / "observation.memmap").write_bytes(bytes(64))
    unfinished = make_fake_run(paper_runs, "sqil", seed=1, deploy=(-300.0, 0.0), train=(-100.0, 90.0), status="interrupted")
    archive = tmp_path_factory.mktemp("archive")
    archived = archive_runs(paper_runs, archive)
    assert sorted(p.relative_to(archive) for p in archived) == sorted(
        p.parent.relative_to(paper_runs) for p in paper_runs.rglob("config.yaml") if p.parent != unfinished
    )
    assert not list(archive.rglob("*.pt")) and not list(archive.rglob("*.memmap"))
    assert (archive / c_sqil.relative_to(paper_runs) / "logs" / "scalars" / "eval" / "train_return.csv").is_file()
    reports = tmp_path_factory.mktemp("reports")
    from_runs = write_report(paper_runs, reports / "runs", name="t")
    from_archive = write_report(archive, reports / "archive", name="t")
    for produced in ("markdown", "csv", "all_csv"):
        assert getattr(from_archive, produced).read_text() == getattr(from_runs, produced).read_text()


def test_archiving_again_replaces_a_runs_record_and_keeps_the_others(tmp_path_factory) -> None:
    root, archive = tmp_path_factory.mktemp("runs"), tmp_path_factory.mktemp("archive")
    run = make_fake_run(root, "c_bc", deploy=(-100.0, 50.0), train=(-100.0, 50.0), episodes=4)
    elsewhere = make_fake_run(tmp_path_factory.mktemp("other_machine"), "bc", deploy=(-300.0, 0.0), train=(-100.0, 75.0), episodes=4)
    archive_runs(elsewhere.parents[3], archive)
    archive_runs(root, archive)
    eval_path(run, "deploy").write_text(json.dumps(EvaluationResult("deploy", [True] * 4, [-1.0] * 4, [9] * 4).to_dict()))
    archive_runs(root, archive)
    by_label = {r.label: r for r in load_runs(archive)}
    assert sorted(by_label) == ["bc", "c_bc"]
    assert by_label["c_bc"].evaluations["deploy"].success_rate == 1.0
    # The run trained again from scratch: an evaluation only its earlier attempt made is not kept.
    at_strength = RunDirectory(run).eval_path("deploy", "s0.5")
    at_strength.write_text(eval_path(run, "deploy").read_text())
    archive_runs(root, archive)
    archived = archive / run.relative_to(root)
    assert (archived / at_strength.relative_to(run)).is_file()
    at_strength.unlink()
    archive_runs(root, archive)
    assert not (archived / at_strength.relative_to(run)).exists()
    assert sorted(p.relative_to(archived) for p in archived.rglob("*") if p.is_file()) == sorted(
        p.relative_to(run) for p in RunDirectory(run).record_files()
    )
    with pytest.raises(ValueError, match="must not contain one another"):
        archive_runs(root, root / "archive")
    with pytest.raises(FileNotFoundError, match="does not exist"):
        archive_runs(root / "missing", archive)


def test_archive_cli_names_what_it_copied(paper_runs: Path, tmp_path_factory, capsys) -> None:
    archive = tmp_path_factory.mktemp("archive")
    archive_main([f"runs={paper_runs}", f"out={archive}"])
    assert f"archived {len(PAPER_RAW)} run(s) below {archive}" in capsys.readouterr().out
    with pytest.raises(SystemExit, match="usage"):
        archive_main([f"runs={paper_runs}"])


def _tables(markdown: Path) -> list[str]:
    """The table lines of a report, its across-seeds section and its across-tasks aggregate
    (both drawn from runs only, which carried rows are not) left out."""
    lines, section, part = [], "", ""
    for line in markdown.read_text().splitlines():
        section = line if line.startswith("### ") else section
        part = line if line.startswith("## ") else part
        if line.startswith("|") and section != "### Across seeds" and not part.startswith("## Across tasks"):
            lines.append(line)
    return lines


def test_carried_rows_print_as_the_runs_they_stand_for(paper_runs: Path, tmp_path_factory) -> None:
    reports = tmp_path_factory.mktemp("reports")
    make_fake_run(paper_runs, "sqil", seed=1, deploy=(-360.0, 2.0), train=(-120.0, 80.0))
    full = write_report(paper_runs, reports / "full", name="t")
    survivors = tmp_path_factory.mktemp("survivors")
    for label in ("gail", "c_gail"):
        for run in (paper_runs / "antmaze_medium" / "h1000-cs1.0-k10" / label).iterdir():
            shutil.copytree(run, survivors / run.relative_to(paper_runs))
    merged = write_report(survivors, reports / "merged", name="t", carried=full.all_csv)
    assert _tables(merged.markdown) == _tables(full.markdown)
    assert merged.csv.read_text() == full.csv.read_text()
    assert merged.all_csv.read_text() == full.all_csv.read_text()
    carried_line = next(line for line in merged.markdown.read_text().splitlines() if line.startswith("Carried from"))
    assert "Expert, C-BC, C-SQIL, C-IQ-Learn, BC, SQIL, IQ-Learn." in carried_line
    assert "C-GAIL" not in carried_line and "Carried from" not in full.markdown.read_text()


def test_a_run_replaces_the_carried_row_of_its_label(paper_runs: Path, tmp_path_factory) -> None:
    reports = tmp_path_factory.mktemp("reports")
    earlier = write_report(paper_runs, reports / "earlier", name="t")
    newer = tmp_path_factory.mktemp("newer")
    make_fake_run(newer, "c_sqil", deploy=(-100.0, 50.0), train=(-100.0, 60.0))
    make_fake_run(newer, "c_sqil", k=0, deploy=(-150.0, 30.0), train=(-150.0, 30.0))
    make_fake_run(newer, "c_bc", k=0, deploy=(-150.0, 30.0), train=(-150.0, 30.0))
    merged = write_report(newer, reports / "merged", name="t", carried=earlier.all_csv)
    assert merged.main_setting.k == 10  # 1 run and 8 carried rows there, 2 runs at k = 0
    with open(merged.csv, newline="") as handle:
        rows = {(row["algorithm"], row["regime"]): row for row in csv.DictReader(handle)}
    assert float(rows["c_sqil", "deploy"]["success_rate"]) == pytest.approx(0.5)
    assert float(rows["c_gail", "deploy"]["success_rate"]) == pytest.approx(0.741)
    assert len(rows) == 2 * len(PAPER_RAW)
    with pytest.raises(ValueError, match="lacks the column"):
        write_report(newer, reports / "bad", name="t", carried=earlier.csv)


def test_a_record_keeps_trajectory_positions_to_a_tenth_of_a_millimetre_and_every_metric_exactly() -> None:
    result = EvaluationResult(
        "deploy", [True, False], [-1.23456789, -2.5], [3, 4], trajectories=[[[0.123456789, -2.0000499], [1.00005001, 3.0]]]
    )
    record = json.loads(json.dumps(result.to_dict()))
    assert record["trajectories"] == [[[0.1235, -2.0], [1.0001, 3.0]]]
    reloaded = EvaluationResult.from_dict(record)
    assert reloaded == result and reloaded.returns == (-1.23456789, -2.5)


def test_a_report_reads_several_roots_and_refuses_a_run_held_twice(tmp_path: Path, capsys) -> None:
    table1, seeds = tmp_path / "table1", tmp_path / "seeds"
    make_fake_run(table1, "expert", deploy=(-100.0, 90.0), train=(-100.0, 90.0), episodes=100)
    make_fake_run(table1, "c_sqil", seed=0, deploy=(-120.0, 60.0), train=(-120.0, 60.0), episodes=100)
    make_fake_run(seeds, "c_sqil", seed=1, deploy=(-110.0, 80.0), train=(-110.0, 80.0), episodes=100)
    pooled = aggregate(load_runs([table1, seeds]))
    (table,) = pooled.values()
    assert table["c_sqil"]["deploy"].success_rate == pytest.approx(0.7)  # (60 + 80) / 200 episodes
    assert sorted(set(table["c_sqil"]["deploy"].seeds)) == [0, 1]

    out = tmp_path / "out"
    report_main([f"runs=[{table1},{seeds}]", f"out={out}", "name=t"])
    assert "### Across seeds" in (out / "t.md").read_text()

    make_fake_run(seeds, "c_sqil", seed=0, deploy=(-300.0, 10.0), train=(-300.0, 10.0), episodes=100)
    with pytest.raises(ValueError, match="both c_sqil seed 0 .* would pool them as two seeds"):
        load_runs([table1, seeds])
    with pytest.raises(ValueError, match="would pool them as two seeds"):
        load_runs(tmp_path)  # a folder above both roots holds seed 0 twice
    with pytest.raises(FileNotFoundError, match="does not exist"):
        load_runs([table1, tmp_path / "missing"])


def test_success_curves_and_the_aggregate_across_tasks(tmp_path: Path) -> None:
    # Two tasks (envs), two seeds per row; the expert succeeds 80% on one and 50% on the other.
    expert = {"antmaze_medium": 80.0, "antmaze_large": 50.0}
    deploy = {("c_sqil", 0): 80.0, ("c_sqil", 1): 60.0, ("sqil", 0): 0.0, ("sqil", 1): 8.0}
    for env, expert_rate in expert.items():
        make_fake_run(tmp_path, "expert", env=env, deploy=(-100.0, expert_rate), train=(-100.0, expert_rate), episodes=100)
        for (label, seed), rate in deploy.items():
            shift = 10.0 if env == "antmaze_large" else 0.0  # the second task's rows differ
            run_dir = make_fake_run(
                tmp_path, label, seed=seed, env=env, deploy=(-100.0, rate / 2 + shift), train=(-100.0, 50.0), episodes=100
            )
            curve = "".join(f"{step},{0.1 * seed + step / 2000}\n" for step in (0, 500, 1000))
            (run_dir / "logs" / "scalars" / "eval" / "train_success.csv").write_text(curve)
    runs = load_runs(tmp_path)
    assert {r.success_curves["train"][-1] for r in runs if r.label == "c_sqil"} == {(1000, 0.5), (1000, 0.6)}
    report = write_report([tmp_path], tmp_path / "out", name="both")
    names = {p.name for p in report.figures}
    assert {"both_success_curves.png", "both_aggregate.png"} <= names
    text = report.markdown.read_text()
    # The main setting of each env is a task: C-SQIL's four normalised deploy scores, by hand.
    scores = sorted(
        (rate / 2 + (10.0 if env == "antmaze_large" else 0.0)) / expert[env]
        for env in expert
        for (label, _), rate in deploy.items()
        if label == "c_sqil"
    )
    iqm = (scores[1] + scores[2]) / 2  # four runs: the middle two
    row = next(line for line in text.splitlines() if line.startswith("| C-SQIL | 2 | 4 |"))
    assert f"{iqm:.2f} [" in row and f"| {sum(scores) / 4:.2f} |" in row
