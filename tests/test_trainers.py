"""End-to-end runs of every trainer on RoverMaze-U and Route Choice at toy budgets: the
loop runs, checkpoints, resumes exactly after an interrupt, refuses a changed config,
evaluates and reports."""

from __future__ import annotations

import json
import random
import signal
import subprocess
import sys
import time
from contextlib import contextmanager
from pathlib import Path

import pytest
import torch
from hydra.utils import get_class
from omegaconf import OmegaConf
from tensordict import MemoryMappedTensor, TensorDict
from tiny_runs import ALGO, QUICK, ROVER

from torchrl_causal.cli.archive import main as archive_main
from torchrl_causal.cli.status import run_statuses
from torchrl_causal.data import read_metadata
from torchrl_causal.evaluation import load_runs, write_report
from torchrl_causal.evaluation.evaluator import Evaluator
from torchrl_causal.evaluation.runs import read_scalar_csv
from torchrl_causal.experiment import (
    CheckpointError,
    ConfigMismatchError,
    ConfigValueError,
    ForeignFilesError,
    RunDirectory,
    RunInterrupted,
    RunInUseError,
    compose_config,
    load_checkpoint,
)
from torchrl_causal.experiment.builders import make_window
from torchrl_causal.experiment.provenance import COST_FIELDS, process_cpu_seconds
from torchrl_causal.experiment.run_directory import carry_runs
from torchrl_causal.graphs.window import AdjustmentWindow
from torchrl_causal.lifecycle import run
from torchrl_causal.trainers import Trainer
from torchrl_causal.trainers.telemetry import SPEED_PREFIX

TINY = [*QUICK, "eval.trajectories=2"]
ENV_TINY = {"rovermaze_u": ROVER, "route_choice": ["env=route_choice"]}


def tiny_config(root: Path, env: str, algo: str, causal: bool, *extra: str):
    return compose_config([*ENV_TINY[env], f"algo={algo}", f"causal={causal}", f"run_root={root}", *TINY, *ALGO[algo], *extra])


def build_trainer(cfg) -> Trainer:
    """The trainer :func:`~torchrl_causal.lifecycle.run` builds for ``cfg``, not yet set up,
    for tests that look inside it (``fit()`` writes to ``cfg.run_dir``)."""
    window = make_window(cfg)
    return get_class(cfg.algo.trainer)(cfg, RunDirectory(cfg.run_dir), window, Evaluator(cfg, window).periodic)


@pytest.fixture(scope="module")
def trained_runs(tmp_path_factory) -> dict[str, Path]:
    """Every algorithm, causal and not, on both envs (plus the expert), trained once."""
    roots = {}
    for env in ENV_TINY:
        root = tmp_path_factory.mktemp(env)
        for algo in ("bc", "gail", "sqil", "iq_learn"):
            for causal in (True, False):
                run(tiny_config(root, env, algo, causal))
        run(tiny_config(root, env, "expert", False))
        roots[env] = root
    return roots


@pytest.mark.parametrize("env", sorted(ENV_TINY))
def test_every_algorithm_runs_checkpoints_and_evaluates(trained_runs, env: str) -> None:
    runs = load_runs(trained_runs[env])
    assert sorted(r.label for r in runs) == sorted(["expert", "c_bc", "c_gail", "c_sqil", "c_iq_learn", "bc", "gail", "sqil", "iq_learn"])
    for record in runs:
        status = json.loads((record.path / "status.json").read_text())
        assert status["status"] == "complete"
        assert status["progress"] == status["total"] or record.label.endswith("bc")  # BC may stop early
        for regime in ("train", "deploy"):
            result = record.evaluations[regime]
            assert result.n_episodes == 8 and len(result.returns) == 8
            assert all(1 <= n <= (40 if env == "rovermaze_u" else 1) for n in result.lengths)
        config = (record.path / "config.yaml").read_text()
        assert "${" not in config and OmegaConf.create(config).run_dir == str(record.path)  # resolved
        assert "train-regime return" in (record.path / "train.log").read_text() or record.label == "expert"
        if record.label == "expert":
            assert not (record.path / "checkpoints").exists()
            continue
        window = AdjustmentWindow.from_dict(json.loads((record.path / "window.json").read_text()))
        assert ("W" in window.lags) != record.label.startswith("c_")  # the collider is what causal runs drop
        for name in ("last.pt", "best.pt"):
            state = load_checkpoint(record.path / "checkpoints" / name)  # weights_only=True
            assert state["progress"] <= status["total"]
        assert record.curve and record.curve[-1][0] == status["progress"]
        # A finished run whose cosine schedule spans its budget cannot continue: its buffer goes.
        assert not (record.path / "replay").exists()
    if env == "rovermaze_u":
        deploy = next(r for r in runs if r.label == "c_sqil").evaluations["deploy"]
        assert len(deploy.trajectories) == 2 and len(deploy.trajectories[0][0]) == 2
        assert next(r for r in runs if r.label == "c_sqil").maze["walls"]


def test_report_of_trained_runs(trained_runs, tmp_path: Path) -> None:
    report = write_report(trained_runs["rovermaze_u"], tmp_path, name="u")
    rows = report.csv.read_text().splitlines()
    assert rows[0] == "algorithm,regime,success_rate,success_se,return_mean,return_std,ep_len_mean,ep_len_std,n_episodes,seeds"
    assert len(rows) == 1 + 9 * 2
    assert {p.name for p in report.figures} == {"u_training_curves.png", "u_success_curves.png", "u_trajectories.png"}


def test_finished_run_is_not_retrained(trained_runs) -> None:
    cfg = tiny_config(trained_runs["route_choice"], "route_choice", "bc", True)
    before = (Path(cfg.run_dir) / "eval" / "deploy.json").stat().st_mtime_ns
    results = run(cfg)
    assert results["deploy"].n_episodes == 8
    assert (Path(cfg.run_dir) / "eval" / "deploy.json").stat().st_mtime_ns == before


def test_a_run_made_before_an_option_existed_is_still_its_run(trained_runs) -> None:
    cfg = tiny_config(trained_runs["route_choice"], "route_choice", "bc", True)
    config_file = Path(cfg.run_dir) / "config.yaml"
    stored = config_file.read_text()
    before_drop = OmegaConf.load(config_file)
    assert before_drop.window.pop("drop") == []
    try:
        OmegaConf.save(before_drop, config_file)  # as written before window.drop existed
        assert run(cfg)["deploy"].n_episodes == 8
        assert OmegaConf.load(config_file).window.drop == []  # the claim recorded the new key
        with pytest.raises(ConfigMismatchError, match=r"window\.drop: \[\] -> \['X'\]"):
            RunDirectory(cfg.run_dir).claim(tiny_config(trained_runs["route_choice"], "route_choice", "bc", True, "window.drop=[X]"))
    finally:
        config_file.write_text(stored)


def test_a_run_made_before_a_key_moved_is_still_its_run(trained_runs) -> None:
    """Before ``env.window_k`` moved to ``env.paper.window_k``, Route Choice stored k = 0 in
    the first and its family's 10 in the second: the migration must give back the run's 0."""
    cfg = tiny_config(trained_runs["route_choice"], "route_choice", "bc", True)
    config_file = Path(cfg.run_dir) / "config.yaml"
    stored = config_file.read_text()
    old_layout = OmegaConf.load(config_file)
    assert old_layout.env.paper.window_k == old_layout.window.k == 0
    old_layout.env.window_k, old_layout.env.paper.window_k = 0, 10
    try:
        OmegaConf.save(old_layout, config_file)
        assert RunDirectory(cfg.run_dir).read_config().env.paper.window_k == 0
        assert run(cfg)["deploy"].n_episodes == 8
        rewritten = OmegaConf.load(config_file)  # the claim wrote the current layout
        assert "window_k" not in rewritten.env and rewritten.env.paper.window_k == 0
    finally:
        config_file.write_text(stored)


# (window.mode=exact is refused earlier now, as a non-imitable diagram, before the run's config is read.)
@pytest.mark.parametrize(
    "change", ["env.make.maze=medium", "algo.optimizer.lr=0.01", "algo.actor.hidden=32", "algo.patience=3", "eval.final_episodes=9"]
)
def test_a_changed_config_is_refused_naming_the_key(trained_runs, change: str) -> None:
    cfg = tiny_config(trained_runs["rovermaze_u"], "rovermaze_u", "bc", True, change)
    config_file = Path(cfg.run_dir) / "config.yaml"
    stored = config_file.read_text()  # the finished run's: the change does not alter the run's name
    with pytest.raises(ConfigMismatchError, match=change.split("=")[0].replace(".", r"\.")):
        run(cfg)
    assert config_file.read_text() == stored


def test_a_changed_setting_in_the_run_name_gets_its_own_directory(trained_runs) -> None:
    cfg = tiny_config(trained_runs["rovermaze_u"], "rovermaze_u", "bc", True, "env.confounding_strength=0.5")
    assert not Path(cfg.run_dir).exists() and "cs0.5" in cfg.run_dir


def test_an_unfinished_run_refuses_a_changed_width_before_writing(tmp_path: Path) -> None:
    cfg = tiny_config(tmp_path, "rovermaze_u", "sqil", True, "algo.total_steps=400")
    with _interrupt_at(get_class(cfg.algo.trainer), 2), pytest.raises(RunInterrupted):
        run(cfg)
    config_file = Path(cfg.run_dir) / "config.yaml"
    stored, checkpoint = config_file.read_text(), (Path(cfg.run_dir) / "checkpoints" / "last.pt").read_bytes()
    with pytest.raises(ConfigMismatchError, match=r"algo\.critic\.hidden: 16 -> 32"):
        run(tiny_config(tmp_path, "rovermaze_u", "sqil", True, "algo.total_steps=400", "algo.critic.hidden=32"))
    assert config_file.read_text() == stored
    assert (Path(cfg.run_dir) / "checkpoints" / "last.pt").read_bytes() == checkpoint


def test_resume_false_discards_the_previous_run_and_nothing_else(trained_runs, tmp_path: Path) -> None:
    cfg = tiny_config(tmp_path, "route_choice", "bc", True)
    run(cfg)
    stale = Path(cfg.run_dir) / "eval" / "deploy-n5-seed1-envs5.json"  # a record of the previous run's
    stale.write_text((Path(cfg.run_dir) / "eval" / "deploy.json").read_text())
    run(tiny_config(tmp_path, "route_choice", "bc", True, "algo.optimizer.lr=0.01", "resume=false"))
    assert not stale.exists()
    assert OmegaConf.load(Path(cfg.run_dir) / "config.yaml").algo.optimizer.lr == 0.01
    # A file no run wrote: resume=false removes nothing, resume=true writes nothing beside it.
    mine = Path(cfg.run_dir) / "notes.txt"
    mine.write_text("my notes")
    before = {path: path.read_bytes() for path in Path(cfg.run_dir).rglob("*") if path.is_file() and path.name != ".lock"}
    for resume in ("false", "true"):
        with pytest.raises(ForeignFilesError, match="notes.txt") as error:
            run(tiny_config(tmp_path, "route_choice", "bc", True, "algo.optimizer.lr=0.02", f"resume={resume}"))
        assert "\n" not in str(error.value)
    assert {path: path.read_bytes() for path in Path(cfg.run_dir).rglob("*") if path.is_file() and path.name != ".lock"} == before


def test_a_run_held_by_another_process_is_refused_and_a_killed_holder_leaves_no_lock(tmp_path: Path) -> None:
    cfg = tiny_config(tmp_path, "route_choice", "bc", True)
    run_dir = Path(cfg.run_dir)
    holder = subprocess.Popen(
        [
            sys.executable,
            "-c",
            "import sys, time\n"
            "from torchrl_causal.experiment import RunDirectory\n"
            "with RunDirectory(sys.argv[1]).lock():\n"
            "    print('held', flush=True)\n"
            "    time.sleep(600)\n",
            str(run_dir),
        ],
        stdout=subprocess.PIPE,
        text=True,
    )
    try:
        assert holder.stdout.readline().strip() == "held"
        with pytest.raises(RunInUseError, match=rf"pid {holder.pid} on "):
            run(cfg)
        assert sorted(p.name for p in run_dir.iterdir()) == [".lock"]  # refused before claiming the directory
    finally:
        holder.kill()  # SIGKILL: no cleanup code runs in the holder
        holder.wait()
    run(cfg)
    assert json.loads((run_dir / "status.json").read_text())["status"] == "complete"


def test_a_killed_run_reads_as_killed_not_running(tmp_path: Path) -> None:
    run_dir = RunDirectory(tmp_path / "run")
    holder = subprocess.Popen(
        [
            sys.executable,
            "-c",
            "import sys, time\n"
            "from torchrl_causal.experiment import RunDirectory\n"
            "run = RunDirectory(sys.argv[1])\n"
            "with run.lock():\n"
            "    run.write_status('running', progress=7)\n"
            "    print('held', flush=True)\n"
            "    time.sleep(600)\n",
            str(run_dir.path),
        ],
        stdout=subprocess.PIPE,
        text=True,
    )
    try:
        assert holder.stdout.readline().strip() == "held"
        assert run_dir.is_held() and run_dir.read_status() == {"status": "running", "progress": 7}
    finally:
        holder.kill()  # SIGKILL: the holder cannot record its stop
        holder.wait()
    assert json.loads(run_dir.status_file.read_text())["status"] == "running"
    assert not run_dir.is_held() and run_dir.read_status() == {"status": "killed", "progress": 7}


def test_raising_the_budget_continues_a_finished_run(tmp_path: Path) -> None:
    run(tiny_config(tmp_path, "route_choice", "gail", True))
    longer = tiny_config(tmp_path, "route_choice", "gail", True, "algo.rounds=4")
    run(longer)
    status = json.loads((Path(longer.run_dir) / "status.json").read_text())
    assert (status["status"], status["progress"], status["total"]) == ("complete", 4, 4)
    assert [step for step, _ in read_scalar_csv(Path(longer.run_dir) / "logs/scalars/eval/train_return.csv")] == [1, 2, 3, 4]


def test_out_of_range_values_fail_before_a_run_directory_exists(tmp_path: Path, monkeypatch) -> None:
    for change in ("eval.final_episodes=0", "demos.episodes=0", "algo.num_envs=0", "env.confounding_strength=1.5"):
        with pytest.raises(ConfigValueError, match=change.split("=")[0].replace(".", r"\.")):
            run(tiny_config(tmp_path, "rovermaze_u", "sqil", True, change))
    assert not (tmp_path / "rovermaze_u").exists()
    # A failure after the directory was claimed but before any checkpoint leaves nothing either.
    import torchrl_causal.lifecycle as lifecycle

    def broken_window(cfg):
        raise RuntimeError("no window")

    monkeypatch.setattr(lifecycle, "make_window", broken_window)
    with pytest.raises(RuntimeError, match="no window"):
        run(tiny_config(tmp_path, "rovermaze_u", "sqil", True))
    assert not (tmp_path / "rovermaze_u").exists()


@contextmanager
def _interrupt_at(trainer_class, step: int, number: int = signal.SIGINT):
    """Sends SIGINT (or ``number``) to this process at the end of the ``step``-th training
    iteration, as Ctrl-C would (the trainer's handler must let the iteration finish)."""
    original, calls = trainer_class.train_step, []

    def train_step(trainer):
        scalars = original(trainer)
        calls.append(1)
        if len(calls) == step:
            signal.raise_signal(number)
        return scalars

    trainer_class.train_step = train_step
    try:
        yield
    finally:
        trainer_class.train_step = original


def _assert_same_state(a, b, where: str = "") -> None:
    if isinstance(a, dict):
        assert a.keys() == b.keys(), where
        for key in a:
            _assert_same_state(a[key], b[key], f"{where}/{key}")
    elif isinstance(a, torch.Tensor):
        assert torch.equal(a, b), where
    elif isinstance(a, (list, tuple)):
        for i, (x, y) in enumerate(zip(a, b, strict=True)):
            _assert_same_state(x, y, f"{where}[{i}]")
    else:
        assert a == b, where


def _last_checkpoints(*configs) -> list[dict]:
    """Each run's last checkpoint without the collector's state: trajectory ids are
    renumbered on load, and nothing reads them."""
    states = [load_checkpoint(Path(cfg.run_dir) / "checkpoints" / "last.pt") for cfg in configs]
    for state in states:
        state["training"].pop("collector", None)
    return states


EXACT = {
    "sqil": ("algo.total_steps=320", "algo.eval_every=160"),
    "gail": ("algo.rounds=3", "algo.eval_every=2"),
    "bc": ("algo.epochs=4", "algo.patience=10"),
}


@pytest.mark.parametrize("algo", sorted(EXACT))
def test_interrupt_at_a_random_step_then_resume_equals_an_uninterrupted_run(tmp_path: Path, algo: str) -> None:
    extra = (*EXACT[algo], "checkpoint_every_s=3600")  # no timed checkpoint: only the interrupt's
    straight = tiny_config(tmp_path / "a", "rovermaze_u", algo, True, *extra)
    results_a = run(straight)
    interrupted = tiny_config(tmp_path / "b", "rovermaze_u", algo, True, *extra)
    trainer_class = get_class(interrupted.algo.trainer)
    iterations = trainer_class.budget(interrupted) // {"sqil": 40, "gail": 1, "bc": 1}[algo]
    step = random.Random(f"{algo}-resume").randint(1, iterations - 1)
    with _interrupt_at(trainer_class, step), pytest.raises(RunInterrupted, match="interrupted by SIGINT") as stop:
        run(interrupted)
    interrupted_at = RunDirectory(interrupted.run_dir).read_status()["progress"]
    assert stop.value.exit_code == 130
    run_dir = RunDirectory(interrupted.run_dir)
    assert run_dir.read_status()["status"] == "interrupted"
    assert not run_dir.eval_path("deploy").exists()
    results_b = run(tiny_config(tmp_path / "b", "rovermaze_u", algo, True, *extra))
    _assert_same_state(*_last_checkpoints(straight, interrupted))
    _assert_same_state(*(load_checkpoint(Path(cfg.run_dir) / "checkpoints" / "best.pt") for cfg in (straight, interrupted)))
    assert results_a["deploy"].returns == results_b["deploy"].returns
    curves = [read_scalar_csv(Path(cfg.run_dir) / "logs/scalars/eval/train_return.csv") for cfg in (straight, interrupted)]
    assert curves[0] == curves[1]
    # Every logged scalar too: losses averaged on the device across the interrupt included;
    # the speed measurements at the same steps (their values are the machine's).
    logs = [
        {path.relative_to(Path(cfg.run_dir)): read_scalar_csv(path) for path in (Path(cfg.run_dir) / "logs/scalars").rglob("*.csv")}
        for cfg in (straight, interrupted)
    ]
    speed = {path for path in logs[0] if path.parts[2] == SPEED_PREFIX.strip("/")}
    assert speed and logs[0].keys() == logs[1].keys()
    assert {path: [step for step, _ in logs[0][path]] for path in speed} == {path: [step for step, _ in logs[1][path]] for path in speed}
    assert {path: series for path, series in logs[0].items() if path not in speed} == {
        path: series for path, series in logs[1].items() if path not in speed
    }
    assert len(logs[0]) - len(speed) > 2
    # the wall time goes on from the interrupted attempt's: it counts both attempts
    wall = [dict(logs[1][path]) for path in speed if path.name == "wall_time_s.csv"][0]
    assert list(wall.values()) == sorted(wall.values())
    # One attempt per start: the straight run's, and the interrupted run's two.
    attempts = [RunDirectory(cfg.run_dir).read_attempts() for cfg in (straight, interrupted)]
    assert [a["progress"] for a in attempts[0]] == [0]
    assert [a["progress"] for a in attempts[1]] == [0, interrupted_at]
    identities = [
        {k: v for k, v in attempt.items() if k not in COST_FIELDS} for attempt in (attempts[1][0], attempts[1][1], attempts[0][0])
    ]
    assert identities[0] == {**identities[1], "progress": 0} == identities[2]


@pytest.mark.parametrize("algo", sorted(EXACT))
def test_a_run_that_collects_its_demonstrations_equals_one_that_loads_them(tmp_path: Path, algo: str) -> None:
    # Found on AntMaze-Medium: the same C-SQIL seed deployed at 41.0% when its run collected
    # the demonstrations and 28.6% when it loaded the identical set.
    collects = tiny_config(tmp_path / "a", "rovermaze_u", algo, True, *EXACT[algo])
    results_a = run(collects)
    loads = tiny_config(tmp_path / "b", "rovermaze_u", algo, True, *EXACT[algo], f"demos.path={collects.demos.path}")
    results_b = run(loads)
    assert not (tmp_path / "b" / "_demos").exists()
    _assert_same_state(*_last_checkpoints(collects, loads))
    assert results_a["deploy"].returns == results_b["deploy"].returns


def test_a_resume_under_other_code_is_logged_and_recorded(tmp_path: Path, monkeypatch, caplog) -> None:
    from torchrl_causal.trainers import base

    cfg = tiny_config(tmp_path, "rovermaze_u", "bc", True, "algo.epochs=4", "algo.patience=10")
    with _interrupt_at(get_class(cfg.algo.trainer), 2), pytest.raises(RunInterrupted):
        run(cfg)
    identity = base.attempt_identity

    def edited(demonstrations, compile: bool, device, **kwargs) -> dict:
        return {**identity(demonstrations, compile, device, **kwargs), "source": "0123456789ab"}

    monkeypatch.setattr(base, "attempt_identity", edited)
    with caplog.at_level("WARNING"):
        run(cfg)
    attempts = RunDirectory(cfg.run_dir).read_attempts()
    assert [a["source"] for a in attempts] == [identity(None, False, "cpu")["source"], "0123456789ab"]
    assert attempts[0]["demonstrations"] == read_metadata(cfg.demos.path)["checksum"][:12]
    assert [a["progress"] for a in attempts] == [0, 2]
    warned = [r.getMessage() for r in caplog.records if "other code" in r.getMessage()]
    assert len(warned) == 1 and f"source: '{attempts[0]['source']}' -> '0123456789ab'" in warned[0]
    assert RunDirectory(cfg.run_dir).code_file in RunDirectory(cfg.run_dir).record_files()


def test_each_attempt_records_its_wall_and_cpu_time_and_status_shows_them(tmp_path: Path) -> None:
    cfg = tiny_config(tmp_path, "rovermaze_u", "bc", True, "algo.epochs=4", "algo.patience=10")

    def attempt(interrupted: bool) -> tuple[float, float]:
        """This process's own clocks around one attempt: the attempt's cost lies within them."""
        wall, cpu = time.monotonic(), process_cpu_seconds()
        if interrupted:
            with _interrupt_at(get_class(cfg.algo.trainer), 2), pytest.raises(RunInterrupted):
                run(cfg)
        else:
            run(cfg)
        return time.monotonic() - wall, process_cpu_seconds() - cpu

    spent = [attempt(interrupted=True), attempt(interrupted=False)]
    attempts = RunDirectory(cfg.run_dir).read_attempts()
    assert [a["progress"] for a in attempts] == [0, 2]
    for attempt, (wall, cpu) in zip(attempts, spent):
        assert 0.9 * wall - 0.05 <= attempt["wall_s"] <= wall + 1e-3
        assert 0.9 * cpu - 0.05 <= attempt["cpu_s"] <= cpu + 1e-3
    (row,) = run_statuses(tmp_path)
    assert row["cost (wall / CPU)"].count(" / ") == 2 and "—" not in row["cost (wall / CPU)"]
    run(cfg)  # complete: the stored evaluations are returned, no attempt is made
    assert RunDirectory(cfg.run_dir).read_attempts() == attempts


def test_replay_buffer_lives_in_the_run_directory_not_in_the_checkpoint(tmp_path: Path) -> None:
    cfg = tiny_config(tmp_path, "rovermaze_u", "sqil", True, "algo.total_steps=400", "algo.buffer_size=400", "checkpoint_every_s=0")
    with _interrupt_at(get_class(cfg.algo.trainer), 6), pytest.raises(RunInterrupted):
        run(cfg)
    run_dir = RunDirectory(cfg.run_dir)
    checkpoint = load_checkpoint(run_dir.last_checkpoint)
    assert checkpoint["progress"] == 240 and checkpoint["training"]["policy_buffer_len"] == 240
    stored = TensorDict.load_memmap(run_dir.replay_dir / "storage")  # what resume maps back
    assert stored.shape == (400,) and isinstance(stored["observation"], MemoryMappedTensor)
    assert stored["observation"][:240].abs().sum(-1).gt(0).all() and not stored["observation"][240:].any()
    assert all(not isinstance(v, torch.Tensor) or v.shape[:1] != (400,) for v in _leaves(checkpoint["training"]))


def _leaves(state):
    if isinstance(state, dict):
        for value in state.values():
            yield from _leaves(value)
    else:
        yield state


def test_checkpoints_follow_the_clock(tmp_path: Path) -> None:
    counts = {}
    for every in (0, 3600):
        cfg = tiny_config(
            tmp_path / str(every),
            "rovermaze_u",
            "bc",
            True,
            "algo.epochs=4",
            "algo.patience=10",
            "algo.eval_every=4",
            f"checkpoint_every_s={every}",
        )
        trainer_class = get_class(cfg.algo.trainer)
        original, saves = trainer_class.save_checkpoint, []
        trainer_class.save_checkpoint = lambda self: (saves.append(self.progress), original(self))
        try:
            run(cfg)
        finally:
            trainer_class.save_checkpoint = original
        counts[every] = saves
    assert counts[0] == [1, 2, 3, 4] and counts[3600] == [4]  # every epoch, or only at the evaluation


def test_corrupted_checkpoint_is_refused_by_name(tmp_path: Path) -> None:
    cfg = tiny_config(tmp_path, "route_choice", "bc", True)
    run(cfg)
    last = Path(cfg.run_dir) / "checkpoints" / "last.pt"
    last.write_bytes(b"not a checkpoint")
    with pytest.raises(CheckpointError, match="last.pt"):
        run(tiny_config(tmp_path, "route_choice", "bc", True, "algo.epochs=5"))


@pytest.mark.parametrize("by_success, selected_epoch", [(False, 4), (True, 3)])
def test_the_best_checkpoint_is_selected_by_return_or_by_success(tmp_path: Path, by_success: bool, selected_epoch: int) -> None:
    """Scripted train-regime scores (success, return) at epochs 1-4: the return alone picks
    epoch 4; success first picks epoch 3, whose return breaks its tie with epoch 2."""
    from types import SimpleNamespace

    scores = iter([(0.5, -10.0), (0.9, -50.0), (0.9, -40.0), (0.8, -5.0)])

    def scripted(policy):
        success_rate, return_mean = next(scores)
        return SimpleNamespace(success_rate=success_rate, return_mean=return_mean)

    cfg = tiny_config(tmp_path, "rovermaze_u", "bc", True, "algo.epochs=4", "algo.eval_every=1", f"eval.select_by_success={by_success}")
    window = make_window(cfg)
    trainer = get_class(cfg.algo.trainer)(cfg, RunDirectory(cfg.run_dir), window, scripted)
    trainer.fit()
    assert trainer.best_progress == selected_epoch
    best = load_checkpoint(Path(cfg.run_dir) / "checkpoints" / "best.pt")
    expected = {4: (0.8, -5.0), 3: (0.9, -40.0)}[selected_epoch]
    assert best["progress"] == selected_epoch and (best["train_success"], best["train_return"]) == expected


def test_route_choice_bc_reproduces_the_appendix_values(tmp_path: Path) -> None:
    """Through the whole trainer: causal BC takes the sheltered route (3/4 in both
    regimes), non-causal BC follows the compass (11/16 at training, 19/48 deployed)."""
    extra = (
        "demos.episodes=2000",
        "algo.epochs=60",
        "algo.batch_size=256",
        "algo.patience=60",
        "algo.eval_every=60",
        "eval.final_episodes=4000",
        "eval.num_envs=1000",
    )
    expected = {True: (3 / 4, 3 / 4), False: (11 / 16, 19 / 48)}
    for causal, (train_value, deploy_value) in expected.items():
        results = run(tiny_config(tmp_path, "route_choice", "bc", causal, *extra))
        for regime, value in (("train", train_value), ("deploy", deploy_value)):
            result = results[regime]
            assert abs(result.return_mean - value) < 4 * result.success_se + 1e-9, (causal, regime, result.return_mean)


def test_evaluate_cli_writes_its_own_record(trained_runs, torch_threads) -> None:
    from torchrl_causal.cli.evaluate import main as evaluate_main

    root = trained_runs["rovermaze_u"]
    for label in ("c_sqil", "expert"):
        (record,) = [r for r in load_runs(root) if r.label == label]
        final = (record.path / "eval" / "deploy.json").read_bytes()
        result = evaluate_main([f"run_dir={record.path}", "regime=deploy", "episodes=6", "num_envs=3", "confounding_strength=0.5"])
        assert result.n_episodes == 6 and result.regime == "deploy"
        assert (record.path / "eval" / "deploy-n6-seed30000-envs3-cs0.5.json").is_file()
        torch.set_num_threads(2)
        evaluate_main([f"run_dir={record.path}", "regime=deploy", "episodes=5", "num_envs=5"])
        assert torch.get_num_threads() == 1  # the CLI's default, not torch's thread per core
        assert (record.path / "eval" / "deploy-n5-seed30000-envs5.json").is_file()
        assert (record.path / "eval" / "deploy.json").read_bytes() == final  # training's record untouched
    assert len(load_runs(root)) == 9
    c_sqil = next(r for r in load_runs(root) if r.label == "c_sqil")
    assert c_sqil.evaluations["deploy"].n_episodes == 8 and len(c_sqil.evaluations["deploy"].trajectories) == 2
    with pytest.raises(SystemExit, match="unknown argument"):
        evaluate_main([f"run_dir={root}", "episodez=3"])


def test_successful_only_trains_on_the_successful_episodes_of_the_same_set(tmp_path: Path, caplog) -> None:
    from torchrl_causal.experiment.builders import load_or_collect_demonstrations

    # A 198-step horizon truncates some of the rover expert's 188-201-step episodes.
    every = tiny_config(tmp_path, "rovermaze_u", "sqil", True, "env.horizon=198", "demos.episodes=12")
    successful = tiny_config(tmp_path, "rovermaze_u", "sqil", True, "env.horizon=198", "demos.episodes=12", "demos.successful_only=true")
    assert successful.demos.path == every.demos.path  # one set on disk, selected at load
    all_episodes = load_or_collect_demonstrations(every)
    with caplog.at_level("INFO"):
        kept = load_or_collect_demonstrations(successful)
    ends = all_episodes["next", "done"].reshape(-1)
    succeeded = all_episodes["episode"][ends & all_episodes["next", "success"].reshape(-1)]
    assert 0 < succeeded.numel() < 12
    assert kept["episode"].unique().tolist() == succeeded.tolist()
    assert f"{succeeded.numel()} of 12 demonstration episodes reached the goal" in caplog.text
    assert trainer_sees(successful) == kept.shape[0] < trainer_sees(every) == all_episodes.shape[0]


def test_the_demonstration_set_is_a_function_of_demos_seed_alone(tmp_path: Path) -> None:
    """Runs that collect the same ``demos.seed`` after different draws of torch's global
    generator (another training seed, another order of work) write the same set; another
    ``demos.seed`` writes another. The rover expert's DART noise (std 0.2) seeds itself
    from the global generator, so without seeding it from ``demos.seed`` the first pair differs."""
    from torchrl_causal.experiment.builders import load_or_collect_demonstrations

    def collected(root: str, demos_seed: int, global_seed: int):
        cfg = tiny_config(tmp_path / root, "rovermaze_u", "bc", True, "demos.episodes=4", f"demos.seed={demos_seed}")
        torch.manual_seed(global_seed)
        untouched = torch.rand(3)
        torch.manual_seed(global_seed)
        demonstrations = load_or_collect_demonstrations(cfg)
        assert torch.equal(torch.rand(3), untouched)  # the run's own draws are as if nothing was collected
        return demonstrations

    first, second = collected("a", 0, 1), collected("b", 0, 2)
    other = collected("c", 1, 1)
    assert first.shape == second.shape and torch.equal(first["action"], second["action"]) and torch.equal(first["P"], second["P"])
    shortest = min(first.shape[0], other.shape[0])
    assert not torch.equal(first["action"][:shortest], other["action"][:shortest])


def test_a_set_collected_by_another_expert_is_refused_not_reused(tmp_path: Path) -> None:
    """The set's path names the env, horizon, strength, size and seed, not the expert: a run
    whose expert acts otherwise (here its noise; a retrained skill's weights alike) must not
    train on the old expert's demonstrations. It is refused in one line naming the field."""
    from torchrl_causal.data.demonstrations import DatasetError
    from torchrl_causal.experiment.builders import check_demonstrations, load_or_collect_demonstrations

    collected = tiny_config(tmp_path, "rovermaze_u", "bc", True, "demos.episodes=2")
    load_or_collect_demonstrations(collected)
    check_demonstrations(collected)  # the same expert: accepted
    other = tiny_config(tmp_path, "rovermaze_u", "bc", True, "demos.episodes=2", "+env.expert.noise_std=0.1")
    assert other.demos.path == collected.demos.path
    for load in (check_demonstrations, load_or_collect_demonstrations):
        with pytest.raises(
            DatasetError,
            match=(
                r"'policy_settings.noise_std' is 0.2, expected 0.1\. Nothing was changed\. "
                r".* is a set collected by .*RoverExpert: delete that folder and rerun"
            ),
        ) as error:
            load(other)
        assert "\n" not in str(error.value)


@pytest.mark.parametrize("maze_expert", ["ant", "humanoid"])
def test_the_policy_record_tells_skill_weights_apart(maze_expert: str) -> None:
    """Two maze experts of one class and settings differ in the record iff their skill's weights
    do, for every shipped skill body (the humanoid's holds a 0-d buffer, ``command_frame``)."""
    from torchrl_causal.data import policy_record
    from torchrl_causal.envs import AntMazeEnv, HumanoidMazeEnv
    from torchrl_causal.experts import AntMazeExpert, HumanoidMazeExpert

    env_class, expert_class = {"ant": (AntMazeEnv, AntMazeExpert), "humanoid": (HumanoidMazeEnv, HumanoidMazeExpert)}[maze_expert]
    env = env_class("medium", batch_size=1, seed=0)
    shipped, copy, retrained = expert_class(env), expert_class(env), expert_class(env)
    if maze_expert == "humanoid":
        assert any(value.dim() == 0 for value in shipped.state_dict().values())  # what the record must hash
    with torch.no_grad():
        next(retrained.locomotion.parameters()).add_(1e-6)
    assert policy_record(shipped) == policy_record(copy)
    assert policy_record(retrained)["policy_settings"] == policy_record(shipped)["policy_settings"]
    assert policy_record(retrained)["policy_weights"] != policy_record(shipped)["policy_weights"]


def trainer_sees(cfg) -> int:
    """How many expert transitions the off-policy trainer of ``cfg`` loads into its expert buffer."""
    trainer = build_trainer(cfg)
    trainer.setup()
    return len(trainer.expert_buffer)


def test_a_run_carried_without_its_replay_buffer_refills_it_and_finishes(tmp_path: Path, caplog) -> None:
    # The SQIL tiny run collects 40 env steps per iteration; interrupted after 6 iterations, it
    # is carried (python -m torchrl_causal.archive carry=true) to another "machine" and resumed there.
    extra = ("algo.total_steps=400", "algo.buffer_size=400", "checkpoint_every_s=3600")
    cfg = tiny_config(tmp_path / "here", "rovermaze_u", "sqil", True, *extra)
    with _interrupt_at(get_class(cfg.algo.trainer), 6), pytest.raises(RunInterrupted):
        run(cfg)
    carried = archive_main(["runs=" + str(tmp_path / "here"), "out=" + str(tmp_path / "carried"), "carry=true"])
    assert len(carried) == 1 and (carried[0] / "checkpoints" / "last.pt").is_file()
    assert not (carried[0] / "replay").exists() and not RunDirectory(carried[0]).lock_file.exists()
    assert RunDirectory(cfg.run_dir).replay_dir.is_dir()  # left behind, not moved
    there = tiny_config(tmp_path / "carried", "rovermaze_u", "sqil", True, *extra, f"demos.path={cfg.demos.path}")
    assert Path(there.run_dir) == carried[0]
    with caplog.at_level("WARNING"):
        results = run(there)
    assert any("has no replay buffer" in record.getMessage() for record in caplog.records)
    state = load_checkpoint(Path(there.run_dir) / "checkpoints" / "last.pt")
    refill = min(240, max(there.algo.random_steps, there.algo.batch_size))
    refilled = -(-refill // 40) * 40  # whole collector batches
    assert state["progress"] == 400 and state["training"]["refilled_steps"] == refilled
    # The buffer held the refill, then every step from 240 on: nothing was counted twice.
    assert state["training"]["policy_buffer_len"] == refilled + 400 - 240
    assert len(results["deploy"].returns) == there.eval.final_episodes and RunDirectory(there.run_dir).read_status()["status"] == "complete"


def test_carry_refuses_what_it_cannot_do_in_one_line(tmp_path: Path) -> None:
    (tmp_path / "runs").mkdir()
    with pytest.raises(SystemExit, match="^error: carry=true copies every checkpoint already; leave out policies=true$"):
        archive_main(["runs=" + str(tmp_path / "runs"), "out=" + str(tmp_path / "out"), "carry=true", "policies=true"])
    with pytest.raises(ValueError, match="must not contain one another"):
        carry_runs(tmp_path / "runs", tmp_path / "runs" / "inside")
