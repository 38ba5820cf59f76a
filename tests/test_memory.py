"""The run footprint estimate: each item equals the bytes of the tensors it stands for,
long windows are extrapolated exactly, a run builds its window once, a run that would not
fit is refused by name before anything is allocated (small limits; nothing big is allocated),
and the whole estimate bounds the measured peak resident size of a real (small) run."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from torchrl_causal.experiment import ConfigValueError, compose_config, validate_config
from torchrl_causal.experiment.builders import expert_transitions, load_or_collect_demonstrations, make_window
from torchrl_causal.experiment.memory import (
    EXACT_K,
    GB,
    Footprint,
    check_footprint,
    check_run_fits,
    encoded_transition_bytes,
    measured_transition_bytes,
    run_footprint,
)

TINY = ["env=rovermaze_u", "env.horizon=40", "window.k=2", "demos.episodes=4", "progress_bar=false"]


def test_a_transition_costs_what_the_replay_tensors_hold(tmp_path: Path) -> None:
    cfg = compose_config([*TINY, "algo=sqil", f"run_root={tmp_path}"])
    transitions = expert_transitions(make_window(cfg), load_or_collect_demonstrations(cfg))
    held = sum(t.numel() * t.element_size() for t in transitions.values(True, True))  # + the float32 reward
    assert encoded_transition_bytes(cfg) * transitions.shape[0] == held + 4 * transitions.shape[0]
    footprint = run_footprint(cfg)  # the set exists now: its actual transitions count, not the bound
    encoded = next(v for k, v in footprint.ram.items() if k.startswith("encoded demonstrations"))
    assert encoded == 2 * transitions.shape[0] * encoded_transition_bytes(cfg)


@pytest.mark.parametrize(
    "overrides", [["window.k=40"], ["window.k=33", "causal=false", "window.window_matched=true"], ["window.k=25", "window.drop=[X]"]]
)
def test_long_windows_are_extrapolated_exactly(overrides: list[str]) -> None:
    cfg = compose_config(["env=rovermaze_u", "algo=bc", *overrides])
    assert cfg.window.k > EXACT_K
    assert encoded_transition_bytes(cfg) == measured_transition_bytes(cfg, cfg.window.k)


def test_a_run_that_does_not_fit_is_refused_naming_what_fills_it(tmp_path: Path) -> None:
    # the k=999 (< horizon 1000, so not refused by the bound) on 200 x 1000 demonstration steps
    cfg = compose_config(["env=rovermaze_u", "algo=bc", "window.k=999", "max_memory_gb=8", f"run_root={tmp_path}"])
    validate_config(cfg)
    with pytest.raises(
        ConfigValueError,
        match=r"needs an estimated 1\d\.\d GB of memory \(encoded demonstrations "
        r"\(demos\.episodes x env\.horizon x window\.k\) 1\d\.\d GB",
    ) as error:
        check_run_fits(cfg)
    assert "8.0 GB are available" in str(error.value) and "\n" not in str(error.value)
    assert not any(tmp_path.iterdir())
    check_run_fits(compose_config(["env=rovermaze_u", "algo=bc", "max_memory_gb=8", f"run_root={tmp_path}"]))


def test_a_replay_buffer_larger_than_the_disk_is_refused() -> None:
    footprint = Footprint(ram={"libraries": GB // 2}, disk={"policy replay buffer (algo.buffer_size x window.k)": 3 * GB})
    check_footprint(footprint, available_ram=GB, free_disk=4 * GB)
    with pytest.raises(ConfigValueError, match=r"3\.0 GB of disk \(policy replay buffer .*2\.0 GB free"):
        check_footprint(footprint, available_ram=GB, free_disk=2 * GB)


def test_every_algorithm_has_an_estimate() -> None:
    for algo in ("expert", "bc", "gail", "sqil", "iq_learn"):
        footprint = run_footprint(compose_config(["env=rovermaze_u", f"algo={algo}", "run_root=/nonexistent/runs"]))
        assert 0.5 * GB <= footprint.ram_bytes < 2 * GB, (algo, footprint)


MEASURE = r"""
import json, resource, sys
from torchrl_causal import lifecycle
from torchrl_causal.experiment import compose_config
from torchrl_causal.experiment.memory import run_footprint

def resident():
    with open("/proc/self/statm") as statm:
        return int(statm.read().split()[1]) * resource.getpagesize()

cfg = compose_config(sys.argv[2:])
base = resident()  # the libraries imported, nothing of the run allocated yet
footprint = run_footprint(cfg)
lifecycle.run(cfg)
# VmHWM, this process's own high-water mark: not ru_maxrss, which Linux carries over an exec
# from the forked parent (here the pytest worker, ~0.9 GB late in a suite run).
with open("/proc/self/status") as status:
    peak = next(int(line.split()[1]) * 1024 for line in status if line.startswith("VmHWM:"))
json.dump({"base": base, "peak": peak, "estimate": footprint.ram_bytes, "items": footprint.ram}, open(sys.argv[1], "w"))
"""


@pytest.mark.slow
def test_the_estimate_bounds_the_measured_peak_of_a_run(tmp_path: Path) -> None:
    # A BC run whose encoded demonstrations (8,000 transitions at k = 50, ~31 MB) are the
    # largest item that scales, trained for one epoch: its own process, so that the peak
    # resident size (VmHWM) is this run's alone.
    overrides = [
        *["env=rovermaze_u", "algo=bc", "causal=true", "env.horizon=200", "window.k=50", "demos.episodes=40"],
        *["eval.episodes=4", "eval.num_envs=4", "eval.final_episodes=4", "algo.actor.hidden=16", "algo.actor.num_blocks=1"],
        *["algo.epochs=1", "algo.batch_size=256", "algo.eval_every=1", "threads=1", "progress_bar=false", f"run_root={tmp_path}"],
    ]
    out = tmp_path / "measured.json"
    env = {**os.environ, "OMP_NUM_THREADS": "1"}
    done = subprocess.run([sys.executable, "-c", MEASURE, str(out), *overrides], env=env, capture_output=True, text=True)
    assert done.returncode == 0, done.stderr[-3000:]
    measured = json.loads(out.read_text())
    estimate, peak, base = measured["estimate"], measured["peak"], measured["base"]
    encoded = next(v for k, v in measured["items"].items() if k.startswith("encoded demonstrations"))
    # The estimate bounds the real peak, and not loosely: within a factor 2 of it.
    assert peak <= estimate <= 2 * peak, measured
    # What it allows the run beyond the imported libraries covers the run's measured growth
    # (the libraries' allowance, 0.5 GB, carries the run's fixed costs: networks, envs,
    # workspaces) within a factor 4 of it, and the largest scaled item fits inside that growth.
    growth = peak - base
    assert growth <= estimate - base <= 4 * growth, measured
    assert encoded <= growth, measured


def _count_windows(monkeypatch: pytest.MonkeyPatch) -> list[int]:
    """The ``k`` of every window the package constructs from a config from now on."""
    from torchrl_causal.experiment import builders

    built: list[int] = []
    construct = builders.imitator_window

    def counted(template, k, **options):  # type: ignore[no-untyped-def]
        built.append(k)
        return construct(template, k, **options)

    monkeypatch.setattr(builders, "imitator_window", counted)
    return built


def test_a_run_builds_its_window_once_for_the_memory_check_the_trainer_and_the_evaluator(tmp_path: Path, monkeypatch) -> None:
    from tiny_runs import tiny

    from torchrl_causal.lifecycle import run

    built = _count_windows(monkeypatch)
    cfg = compose_config([*tiny("bc", "algo.epochs=1"), f"run_root={tmp_path}"])
    run(cfg)
    assert built == [cfg.window.k]  # one construction, shared by every reader of the run
    assert Path(cfg.run_dir, "window.json").is_file()  # the trained run's window is the one built


def test_a_long_window_is_not_built_by_the_memory_check(monkeypatch) -> None:
    # window.k > EXACT_K: two fixed-size probes give the width; the run's own window is not
    # asked for, so a window too large to fit is refused before it is built.
    built = _count_windows(monkeypatch)
    asked: list[int] = []
    cfg = compose_config(["env=rovermaze_u", "algo=bc", "window.k=40", "run_root=/nonexistent/runs"])
    step = encoded_transition_bytes(cfg, lambda: asked.append(1) or make_window(cfg))
    assert not asked and built == [EXACT_K // 2, EXACT_K]
    assert step == measured_transition_bytes(cfg, cfg.window.k)  # the extrapolation is exact
