"""Fault injection: bad values, missing and corrupted files and a signal, given to every
command line as a user would give them.

For each case: exit status != 0, a short message on standard error (Hydra's own few lines
for an override it refuses), no traceback, and the run root exactly as it was before the
command (nothing written, nothing removed).

Speed: each case is its own process, forked from this one after the package has been
imported once (``python -m`` pays ~6 s of imports per process on 2 cores; a fork pays
none), running the command's module as ``__main__`` with its arguments, as the
interpreter does; the cases run a few at a time. ``test_a_fresh_interpreter_agrees``
runs two cases as real ``python -m`` subprocesses, so the forked runner is checked
against the real thing.
"""

from __future__ import annotations

import hashlib
import json
import logging
import os
import runpy
import shutil
import signal
import subprocess
import sys
import tempfile
import time
import traceback
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import pytest
from tiny_runs import merged, tiny

# Imported once here, before the forks. The commands' own modules (torchrl_causal.train...)
# are not: each case runs its module as __main__, as ``python -m`` does.
import torchrl_causal.cli.archive  # noqa: F401
import torchrl_causal.cli.evaluate  # noqa: F401
import torchrl_causal.cli.filmstrip  # noqa: F401
import torchrl_causal.cli.report  # noqa: F401
import torchrl_causal.cli.status  # noqa: F401
import torchrl_causal.cli.strength_ablation  # noqa: F401
import torchrl_causal.cli.train  # noqa: F401

REPO = Path(__file__).resolve().parents[1]
TINY_BC = tiny("bc", "algo.epochs=2", "algo.eval_every=1")
RUN = "rovermaze_u/h40-cs1.0-k2/c_bc/seed0"  # where TINY_BC's run lands below its run root
MAX_STDERR_LINES = 3
HYDRA_MAX_STDERR_LINES = 7  # Hydra's own report of an override it refuses: what, where, HYDRA_FULL_ERROR


@dataclass
class Outcome:
    code: int
    stdout: str
    stderr: str


def _child(module: str, argv: list[str], cwd: Path, out: int, err: int, prepare: Callable[[], None] | None) -> int:
    os.chdir(cwd)
    os.dup2(out, 1)
    os.dup2(err, 2)
    sys.stdout = open(1, "w", buffering=1, closefd=False)
    sys.stderr = open(2, "w", buffering=1, closefd=False)
    logging.root.handlers = []  # pytest's capture handlers; a fresh interpreter has none
    signal.signal(signal.SIGINT, signal.default_int_handler)
    signal.signal(signal.SIGTERM, signal.SIG_DFL)
    sys.argv = [module, *argv]
    try:
        if prepare is not None:
            prepare()
        if module.endswith(".py"):  # a script of benchmarks/, as `python benchmarks/<name>.py` runs it
            runpy.run_path(str(REPO / module), run_name="__main__")
        else:
            runpy.run_module(module, run_name="__main__", alter_sys=True)
    except SystemExit as stop:  # what the interpreter does with it
        if stop.code is None or isinstance(stop.code, int):
            return stop.code or 0
        print(stop.code, file=sys.stderr)
        return 1
    except BaseException:  # noqa: BLE001 -- an uncaught exception: the interpreter prints its traceback
        traceback.print_exc()
        return 1
    return 0


@dataclass
class Case:
    """One bad input: the command, its arguments (``{root}`` is the case's run root), what
    the run root holds before (``setup``), what must be said on stderr (``says``)."""

    name: str
    module: str
    argv: list[str]
    says: str
    setup: Callable[[Path], None] | None = None
    prepare: Callable[[], None] | None = None
    interrupt_after_s: float | None = None  # SIGINT this long after the start; the run may then hold a checkpoint
    never_says: str = ""  # e.g. "delete": advice the message must not give (the path is not ours)
    root: Path = field(default=Path())


def _snapshot(root: Path) -> dict[str, str]:
    """Every path below ``root`` with its content's hash; a run's ``.lock`` aside (each
    attempt writes its pid there, holding it)."""
    return {
        str(path.relative_to(root)): hashlib.sha256(path.read_bytes()).hexdigest() if path.is_file() else "dir"
        for path in sorted(root.rglob("*"))
        if path.name != ".lock"
    }


def run_forked(cases: list[Case], parallel: int = 3, timeout_s: float = 120.0) -> dict[str, Outcome]:
    """Runs every case in its own forked process, ``parallel`` at a time, from the main thread."""
    outcomes: dict[str, Outcome] = {}
    pending = list(cases)
    running: dict[int, tuple[Case, object, object, float]] = {}
    while pending or running:
        while pending and len(running) < parallel:
            case = pending.pop(0)
            out, err = tempfile.TemporaryFile(), tempfile.TemporaryFile()
            sys.stdout.flush()
            sys.stderr.flush()
            pid = os.fork()
            if pid == 0:  # the child never returns into pytest
                code = 1
                try:
                    code = _child(
                        case.module, [a.format(root=case.root) for a in case.argv], case.root, out.fileno(), err.fileno(), case.prepare
                    )
                finally:
                    try:
                        sys.stdout.flush()
                        sys.stderr.flush()
                    finally:
                        os._exit(code)
            running[pid] = (case, out, err, time.monotonic())
            if case.interrupt_after_s is not None:
                time.sleep(case.interrupt_after_s)
                os.kill(pid, signal.SIGINT)
        pid, status = os.waitpid(-1, os.WNOHANG)
        if pid == 0:
            for child, (case, _, _, started) in list(running.items()):
                if time.monotonic() - started > timeout_s:
                    os.kill(child, signal.SIGKILL)
            time.sleep(0.02)
            continue
        case, out, err, _ = running.pop(pid)
        code = os.waitstatus_to_exitcode(status)
        texts = []
        for handle in (out, err):
            handle.seek(0)
            texts.append(handle.read().decode(errors="replace"))
            handle.close()
        outcomes[case.name] = Outcome(code, *texts)
    return outcomes


# ---------------------------------------------------------------------- what the cases start from


def _trained_run(cache: Path) -> Path:
    """A finished tiny C-BC run (its run root), trained once per session in a forked child."""
    root = cache / "trained"
    if not (root / RUN / "eval" / "deploy.json").is_file():
        outcome = run_forked(
            [Case("train", "torchrl_causal.train", [*TINY_BC, f"run_root={root}"], "", root=cache)], parallel=1, timeout_s=300
        )["train"]
        assert outcome.code == 0, outcome.stderr[-3000:]
    return root


def _copy_of(trained: Path) -> Callable[[Path], None]:
    def setup(root: Path) -> None:
        shutil.copytree(trained, root, dirs_exist_ok=True)
        config = root / RUN / "config.yaml"  # as if trained here: its run_root, run_dir and demos.path
        config.write_text(config.read_text().replace(str(trained), str(root)))

    return setup


def _then(first: Callable[[Path], None], change: Callable[[Path], None]) -> Callable[[Path], None]:
    def setup(root: Path) -> None:
        first(root)
        change(root)

    return setup


def _write(relative: str, data: bytes) -> Callable[[Path], None]:
    def change(root: Path) -> None:
        (root / relative).parent.mkdir(parents=True, exist_ok=True)
        (root / relative).write_bytes(data)

    return change


def _remove(relative: str) -> Callable[[Path], None]:
    def change(root: Path) -> None:
        (root / relative).unlink()

    return change


def _user_files(relative: str) -> Callable[[Path], None]:
    """A folder of the user's own: a document, a subfolder with a file, nothing a run wrote."""

    def change(root: Path) -> None:
        folder = root / relative
        (folder / "photos").mkdir(parents=True)
        (folder / "thesis.tex").write_text("\\chapter{Results}\n")
        (folder / "photos" / "cat.jpg").write_bytes(bytes(range(256)))

    return change


def _edit(relative: str, old: str, new: str) -> Callable[[Path], None]:
    def change(root: Path) -> None:
        path = root / relative
        text = path.read_text()
        assert old in text, (old, path)
        path.write_text(text.replace(old, new))

    return change


def _nudge_weights(root: Path) -> None:
    """The selected policy's weights changed by a little, still loadable: an edited best.pt."""
    import torch

    path = root / RUN / "checkpoints" / "best.pt"
    state = torch.load(path, weights_only=True)
    name = sorted(state["policy"])[0]
    state["policy"][name] = state["policy"][name] + 1e-3
    torch.save(state, path)


def _demos_dir(root: Path) -> Path:
    return next((root / "_demos").iterdir())


def _corrupt_demos(root: Path) -> None:
    data = next(path for path in sorted((_demos_dir(root) / "data").rglob("*.memmap")))
    data.write_bytes(data.read_bytes()[:-8])  # truncated


def _without_tensorboard() -> None:
    sys.modules["tensorboard"] = None  # type: ignore[assignment]  # what a venv without the extra gives
    sys.modules["torch.utils.tensorboard"] = None  # type: ignore[assignment]


def _cases(trained: Path) -> list[Case]:
    run = _copy_of(trained)
    fresh = ["run_root={root}/runs", *TINY_BC]
    rerun = ["run_root={root}", *TINY_BC]

    # A key of TINY_BC named again takes the case's value (the command line refuses a key given twice).
    def fresh_with(*extra: str) -> list[str]:
        return merged([*fresh, *extra])

    def rerun_with(*extra: str) -> list[str]:
        return merged([*rerun, *extra])

    T, E, R, S = "torchrl_causal.train", "torchrl_causal.evaluate", "torchrl_causal.report", "torchrl_causal.status"
    A, F, X = "torchrl_causal.strength_ablation", "torchrl_causal.filmstrip", "torchrl_causal.archive"
    B = "benchmarks/transform_overhead.py"
    in_run = f"{{root}}/{RUN}"
    return [
        # ---- train: sizes, keys, budgets, files
        Case("train window longer than horizon", T, fresh_with("window.k=100000"), "window.k=100000 must be < env.horizon"),
        Case("train +typo key", T, [*fresh, "+windw.k=2"], "config key windw.k is unknown"),
        Case("train typo key", T, [*fresh, "windw.k=2"], "windw"),
        Case("train seed not a number", T, [*fresh, "seed=abc"], "seed=abc"),
        Case(
            "train budget inside warm-up",
            T,
            ["run_root={root}/runs", "env=rovermaze_u", "algo=sqil", "algo.total_steps=100", "algo.random_steps=512"],
            "algo.total_steps=100 must be > algo.random_steps=512",
        ),
        Case("train drop unknown variable", T, [*fresh, "window.drop=[Q]"], "window.drop"),
        Case("train zero eval envs", T, [*fresh, "eval.num_envs=0"], "eval.num_envs=0"),
        Case("train memory over limit", T, [*fresh, "max_memory_gb=0.1"], "of memory"),
        Case("train run_root is a file", T, ["run_root={root}/afile", *TINY_BC], "afile", setup=_write("afile", b"not a folder")),
        Case("train tensorboard missing", T, [*fresh, "logger=tensorboard"], "tensorboard", prepare=_without_tensorboard),
        Case("train demonstrations corrupted", T, [*rerun, "seed=1"], "delete", setup=_then(run, _corrupt_demos)),
        Case(
            "train checkpoint corrupted",
            T,
            rerun,
            "last.pt",
            setup=_then(
                _then(run, _write(f"{RUN}/checkpoints/last.pt", b"garbage")),
                _write(f"{RUN}/status.json", b'{"status": "interrupted", "progress": 1, "total": 2}'),
            ),
        ),
        Case("train status corrupted", T, rerun, "status.json", setup=_then(run, _write(f"{RUN}/status.json", b"{"))),
        Case("train config changed", T, rerun_with("algo.batch_size=7"), "holds a run of another config", setup=run),
        # ---- train: a folder that is not a run's is neither cleared nor written into
        Case(
            "train resume=false over the user's files",
            T,
            [*TINY_BC, "run_dir={root}/mine", "resume=false"],
            "which no run wrote",
            setup=_user_files("mine"),
        ),
        Case(
            "train resume=true over the user's files",
            T,
            [*TINY_BC, "run_dir={root}/mine", "resume=true"],
            "which no run wrote",
            setup=_user_files("mine"),
        ),
        Case(
            "train over another program's config.yaml",
            T,
            [*TINY_BC, "run_dir={root}/mine", "resume=false"],
            "config.yaml",
            setup=_write("mine/config.yaml", b"model: resnet50\n"),
        ),
        Case("train key given twice", T, [*fresh, "seed=1", "seed=2"], "seed is given twice"),
        Case(
            "train demos.path is a file",
            T,
            [*fresh, "demos.path={root}/afile"],
            "not a demonstration set",
            setup=_write("afile", b"x"),
            never_says="delete",
        ),
        # ---- evaluate
        Case("evaluate unknown regime", E, [f"run_dir={in_run}", "regime=foo"], "regime='foo' must be one of", setup=run),
        Case("evaluate zero episodes", E, [f"run_dir={in_run}", "episodes=0"], "episodes=0", setup=run),
        Case("evaluate seed not a number", E, [f"run_dir={in_run}", "seed=abc"], "seed='abc' must be an integer", setup=run),
        Case("evaluate zero envs", E, [f"run_dir={in_run}", "num_envs=0"], "num_envs=0", setup=run),
        Case("evaluate strength above one", E, [f"run_dir={in_run}", "confounding_strength=2"], "confounding_strength=2", setup=run),
        Case("evaluate missing run", E, ["run_dir={root}/nowhere"], "nowhere"),
        Case("evaluate folder without a run", E, ["run_dir={root}"], "config.yaml", setup=_write("x.txt", b"x")),
        Case(
            "evaluate best checkpoint corrupted",
            E,
            [f"run_dir={in_run}"],
            "best.pt",
            setup=_then(run, _write(f"{RUN}/checkpoints/best.pt", b"garbage")),
        ),
        Case(
            "evaluate best checkpoint missing", E, [f"run_dir={in_run}"], "best.pt", setup=_then(run, _remove(f"{RUN}/checkpoints/best.pt"))
        ),
        Case(
            "evaluate config corrupted",
            E,
            [f"run_dir={in_run}"],
            "config.yaml",
            setup=_then(run, _write(f"{RUN}/config.yaml", b"env: [unclosed")),
        ),
        Case(
            "evaluate window corrupted", E, [f"run_dir={in_run}"], "window.json", setup=_then(run, _write(f"{RUN}/window.json", b'{"k": '))
        ),
        Case("evaluate unknown argument", E, [f"run_dir={in_run}", "episodez=3"], "episodez", setup=run),
        Case("evaluate zero threads", E, [f"run_dir={in_run}", "threads=0"], "threads=0", setup=run),
        Case("evaluate missing device", E, [f"run_dir={in_run}", "device=cuda:9"], "cuda:9", setup=run),
        Case("evaluate key given twice", E, [f"run_dir={in_run}", "episodes=4", "episodes=8"], "episodes is given twice", setup=run),
        # ---- evaluate: a run's config, window and weights are checked against each other
        Case(
            "evaluate config edited (digests recorded)",
            E,
            [f"run_dir={in_run}", "episodes=2"],
            "config.yaml changed since its policy was selected",
            setup=_then(run, _edit(f"{RUN}/config.yaml", "\nseed: 0\n", "\nseed: 5\n")),
        ),
        Case(
            "evaluate weights edited",
            E,
            [f"run_dir={in_run}", "episodes=2"],
            "best.pt changed since its policy was selected",
            setup=_then(run, _nudge_weights),
        ),
        Case(
            "evaluate another maze (no digests)",
            E,
            [f"run_dir={in_run}", "episodes=2"],
            "another maze",
            setup=_then(_then(run, _remove(f"{RUN}/checkpoints/best.json")), _edit(f"{RUN}/config.yaml", "maze: u", "maze: medium")),
        ),
        Case(
            "evaluate window edited (no digests)",
            E,
            [f"run_dir={in_run}", "episodes=2"],
            "window.json is not the window",
            setup=_then(_then(run, _remove(f"{RUN}/checkpoints/best.json")), _edit(f"{RUN}/window.json", '"k": 2', '"k": 3')),
        ),
        # ---- report
        Case("report missing runs", R, ["runs={root}/nowhere"], "nowhere"),
        Case("report no runs", R, ["runs={root}"], "no evaluated runs", setup=_write("x.txt", b"x")),
        Case("report impossible fraction", R, ["runs={root}", "causal_fraction=2"], "causal_fraction", setup=run),
        Case(
            "report evaluation corrupted",
            R,
            ["runs={root}", "out={root}/out"],
            "deploy.json",
            setup=_then(run, _write(f"{RUN}/eval/deploy.json", b'{"regime"')),
        ),
        Case(
            "report notes would be lost",
            R,
            ["runs={root}", "out={root}/out", "name=r"],
            "notes markers",
            setup=_then(run, _write("out/r.md", b"# R\nA reading written by hand.\n")),
        ),
        Case("report out is a file", R, ["runs={root}", "out={root}/afile"], "afile", setup=_then(run, _write("afile", b"x"))),
        Case("report missing argument", R, ["out={root}/out"], "runs=", setup=run),
        # ---- status
        Case("status missing runs", S, ["runs={root}/nowhere"], "nowhere"),
        Case("status runs is a file", S, ["runs={root}/afile"], "afile", setup=_write("afile", b"x")),
        Case("status corrupted status", S, ["runs={root}"], "status.json", setup=_then(run, _write(f"{RUN}/status.json", b"{not json"))),
        Case("status unknown argument", S, ["runs={root}", "verbose=true"], "verbose", setup=run),
        # ---- strength ablation
        Case("strength above one", A, ["runs={root}", "strengths=[2]", "out={root}/out"], "strengths=2", setup=run),
        Case("strength not a number", A, ["runs={root}", "strengths=[abc]"], "strengths='abc'", setup=run),
        Case("strength zero episodes", A, ["runs={root}", "episodes=0"], "episodes=0", setup=run),
        Case("strength missing runs", A, ["runs={root}/nowhere"], "nowhere"),
        Case(
            "strength notes would be lost",
            A,
            ["runs={root}", "strengths=[1.0]", "episodes=4", "out={root}/out", "name=s"],
            "notes markers",
            setup=_then(run, _write("out/s.md", b"# S\nA reading written by hand.\n")),
        ),
        # ---- filmstrip
        # (the tiny run is a RoverMaze, which renders since its top-down renderer: test_filmstrip.py
        # refuses an env that cannot render with Route Choice)
        Case("filmstrip labels mismatch", F, [f"runs=[{in_run}]", "labels=[a,b]", "out={root}/strip.png"], "labels", setup=run),
        Case("filmstrip missing run", F, ["runs=[{root}/nowhere]", "out={root}/strip.png"], "nowhere"),
        Case("filmstrip zero frames", F, [f"runs=[{in_run}]", "frames=0", "out={root}/strip.png"], "it must be >= 2", setup=run),
        # ---- archive
        Case("archive missing runs", X, ["runs={root}/nowhere", "out={root}/archive"], "nowhere"),
        Case("archive out inside runs", X, ["runs={root}", "out={root}/inside"], "must not contain", setup=run),
        Case("archive out is a file", X, ["runs={root}/rovermaze_u", "out={root}/afile"], "afile", setup=_then(run, _write("afile", b"x"))),
        Case("archive missing out", X, ["runs={root}"], "out=", setup=run),
        Case(
            "archive over the user's files",
            X,
            ["runs={root}/rovermaze_u", "out={root}/archive"],
            "notes.txt",
            setup=_then(run, _write(f"archive/{RUN.removeprefix('rovermaze_u/')}/notes.txt", b"mine")),
        ),
        # ---- benchmarks
        Case("benchmark negative count", B, ["--steps", "-5"], "--steps: -5 must be an integer >= 1"),
    ]


@pytest.fixture(scope="module")
def trained(tmp_path_factory) -> Path:
    return _trained_run(tmp_path_factory.mktemp("faults"))


def test_every_bad_input_fails_with_one_line_and_leaves_the_run_root_as_it_was(trained: Path, tmp_path: Path) -> None:
    cases = _cases(trained)
    assert len(cases) >= 40 and {c.module.removesuffix(".py").split(".")[-1].split("/")[0] for c in cases} == {
        "benchmarks",
        "train",
        "evaluate",
        "report",
        "status",
        "strength_ablation",
        "filmstrip",
        "archive",
    }
    before = {}
    for index, case in enumerate(cases):
        case.root = tmp_path / f"case{index:02d}"
        case.root.mkdir()
        if case.setup is not None:
            case.setup(case.root)
        before[case.name] = _snapshot(case.root)
    outcomes = run_forked(cases)
    failures = []
    for case in cases:
        outcome = outcomes[case.name]
        lines = [line for line in outcome.stderr.splitlines() if line.strip()]
        problems = []
        if outcome.code == 0:
            problems.append("exit status 0")
        if "Traceback" in outcome.stderr:
            problems.append("a traceback")
        hydra = "HYDRA_FULL_ERROR" in outcome.stderr
        if not lines or len(lines) > (HYDRA_MAX_STDERR_LINES if hydra else MAX_STDERR_LINES):
            problems.append(f"{len(lines)} lines on stderr")
        if case.says.lower() not in outcome.stderr.lower():
            problems.append(f"no {case.says!r}")
        if case.never_says and case.never_says.lower() in outcome.stderr.lower():
            problems.append(f"says {case.never_says!r}")
        after = _snapshot(case.root)
        resumable = case.interrupt_after_s is not None and all(
            json.loads(path.read_text())["status"] == "interrupted" for path in case.root.rglob("status.json")
        )
        if after != before[case.name] and not resumable:
            changed = sorted(set(after.items()) ^ set(before[case.name].items()))
            problems.append(f"the run root changed: {changed[:4]}")
        if problems:
            failures.append(f"{case.name}: {', '.join(problems)}\n    stderr: {outcome.stderr.strip()[-600:]}")
    assert not failures, f"{len(failures)} of {len(cases)} cases:\n" + "\n".join(failures)


def test_a_fresh_interpreter_agrees(trained: Path, tmp_path: Path) -> None:
    """Two cases as real ``python -m`` subprocesses: the same status and the same stderr."""
    chosen = [case for case in _cases(trained) if case.name in ("evaluate seed not a number", "train +typo key")]
    for index, case in enumerate(chosen):
        case.root = tmp_path / f"fresh{index}"
        case.root.mkdir()
        if case.setup is not None:
            case.setup(case.root)
    forked = run_forked(chosen)
    for case in chosen:
        argv = [a.format(root=case.root) for a in case.argv]
        real = subprocess.run(
            [sys.executable, "-m", case.module, *argv],
            cwd=case.root,
            capture_output=True,
            text=True,
            env={**os.environ, "OMP_NUM_THREADS": "1"},
            timeout=300,
        )
        assert (real.returncode, real.stderr.strip()) == (forked[case.name].code, forked[case.name].stderr.strip())


def test_archive_replaces_only_the_files_it_writes(trained: Path, tmp_path: Path) -> None:
    """Archiving again over an archive replaces its records and removes an earlier run's stale
    evaluation record, and leaves every other file found in the run's folders as it was."""
    from torchrl_causal.evaluation.runs import archive_runs

    root, out = tmp_path / "runs", tmp_path / "out"
    _copy_of(trained)(root)
    archive_runs(root, out)
    target = out / RUN
    stale = target / "eval" / "deploy-n3-seed9-envs3.json"  # an earlier run's record at a setting this one lacks
    stale.write_text((target / "eval" / "deploy.json").read_text())
    mine = {
        target / "eval" / "notes.txt": b"my reading of these numbers",
        target / "eval" / "plot_settings.json": b'{"dpi": 300}',
        target / "logs" / "README.md": b"# mine",
    }
    for path, data in mine.items():
        path.write_bytes(data)
    archive_runs(root, out)
    assert not stale.exists()
    assert {path: path.read_bytes() for path in mine} == mine
    assert (target / "eval" / "deploy.json").read_bytes() == (root / RUN / "eval" / "deploy.json").read_bytes()


def test_a_shipped_policy_is_evaluated_without_writing_into_the_package(
    trained: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    """A run directory in the package's results tree is only read: the record goes below the
    user's run root, and the command says where."""
    import torchrl_causal.lifecycle as lifecycle
    from torchrl_causal.cli.evaluate import main as evaluate_main

    assert lifecycle.PACKAGE_RESULTS == REPO / "results"
    results = (tmp_path / "results").resolve()
    _copy_of(trained)(results / "policies")
    monkeypatch.setattr(lifecycle, "PACKAGE_RESULTS", results)
    before = _snapshot(results)
    shipped = results / "policies" / RUN
    argv = [f"run_dir={shipped}", "episodes=2", f"run_root={tmp_path / 'mine'}"]
    first = evaluate_main(argv)
    record = tmp_path / "mine" / "evaluated" / "policies" / RUN / "eval" / "deploy-n2-seed30000-envs2.json"
    assert record.is_file() and f"record: {record}" in capsys.readouterr().out
    assert _snapshot(results) == before
    assert evaluate_main([*argv, "reuse=true"]).successes == first.successes  # read back from there
    assert _snapshot(results) == before


def test_every_benchmark_checks_its_numbers() -> None:
    """Every benchmark and every ``--flags`` command of the package (the skill trainers) parses
    its flags with the shared one-line parser, its numbers typed with bounds (a negative count
    is refused, not timed)."""
    scripts = sorted((REPO / "benchmarks").glob("*.py")) + sorted((REPO / "torchrl_causal").rglob("*.py"))
    with_flags = [path for path in scripts if "add_argument(" in path.read_text()]
    assert len(with_flags) >= 12 and {"locomotion.py", "locomotion_ppo.py"} <= {path.name for path in with_flags}
    for path in with_flags:
        text = path.read_text()
        assert ("OneLineParser(" in text or "skill_parser(" in text) and "argparse.ArgumentParser(" not in text, path.name
        assert "type=int" not in text and "type=float" not in text, path.name


def test_every_shipped_policy_agrees_with_its_run_files() -> None:
    """Each policy in ``results/policies`` records the digests of its weights, config and window
    (``checkpoints/best.json``), and its config, window, weights and final records pass the
    checks ``evaluate`` makes before it evaluates (an edited file is refused, see the cases)."""
    from torchrl_causal.experiment import RunDirectory
    from torchrl_causal.lifecycle import open_run

    shipped = sorted(path.parent.parent for path in (REPO / "results" / "policies").rglob("checkpoints/best.pt"))
    assert len(shipped) >= 10
    for run_dir in shipped:
        assert RunDirectory(run_dir).policy_identity_file.is_file(), run_dir
        _, _, policy = open_run(run_dir, device="cpu")
        assert policy is not None
