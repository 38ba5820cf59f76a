"""Runtime of the sequential pi-backdoor computations on the maze templates (paper, App. D.3).

Three tables, each time the best of at least ``--repeats`` runs, more for fast cases (CPU
time of this process, which the other jobs on a shared machine do not inflate as they do
the wall clock; the garbage collector off during a run, as ``timeit`` does):

* Full horizon, imitable. The paper's mazes are not exactly imitable (the hidden
  orientation / centre-of-mass velocity persists), so the complete computation is timed
  on their exactly imitable variants (the hidden variable not persistent, the reward at
  the last slice) for H in ``--horizons``: unrolling, FindOX, the Markov boundary and the
  boundary actions (``exact_adjustment``), then every per-action set, as its prefix of the
  sorted conditioning order ("prefix form", what the computation needs) and, separately,
  built one by one as a frozenset and dropped ("materialised": together they are
  quadratic in H). The sets of the shortest horizon above 1 are checked against
  Definition 2. The paper reports 7.1 s at H = 1 and 14,854 s at H = 2000 on its own
  hardware; the ratios use the materialised time.
* Full horizon, refusal. The same call on the paper's templates, which ends in
  ``NotImitableError`` with a certificate path.
* Windows. ``windowed_adjustment`` for k in ``--windows``, exact and relaxed mode, on a
  first call (the cached Assumption-1 bound dropped before each run).

Pure Python, single-threaded.

Usage:
    python benchmarks/adjustment_runtime.py [--repeats 3] [--horizons 1 100 500 1000 2000]
        [--windows 2 10] [--output results/adjustment_runtime.md]
"""

from __future__ import annotations

import gc
import os
import platform
import shlex
import sys
import time
from collections.abc import Callable
from typing import Any

import networkx as nx
from tqdm import tqdm

from torchrl_causal.cli.arguments import OneLineParser, count, non_negative
from torchrl_causal.envs.templates import ANTMAZE_TEMPLATE, HUMANOIDMAZE_TEMPLATE
from torchrl_causal.graphs import (
    REWARD,
    NotImitableError,
    TimeSliceTemplate,
    check_bounded_influence,
    exact_adjustment,
    sequential_pi_backdoor,
    windowed_adjustment,
)

PAPER_SECONDS = {1: 7.1, 2000: 14854.0}
PAPER_TEMPLATES = {"antmaze": (ANTMAZE_TEMPLATE, "O"), "humanoidmaze": (HUMANOIDMAZE_TEMPLATE, "C")}
WINDOW_TARGET_SECONDS = 5e-3  # issue 12: windowed adjustment at k = 10 within 5 ms
MIN_TOTAL_SECONDS = 0.5
MAX_RUNS = 100


def imitable_variant(template: TimeSliceTemplate, hidden: str) -> TimeSliceTemplate:
    return template.replace(directed=[e for e in template.directed if e != (hidden, hidden, 1)], reward_slices="last")


def best_time(fn: Callable[[], Any], repeats: int, before: Callable[[], None] = lambda: None) -> float:
    """The shortest of at least ``repeats`` runs, repeated until they add up to
    ``MIN_TOTAL_SECONDS`` (at most ``MAX_RUNS``), so that fast cases get many tries."""
    times: list[float] = []
    while len(times) < repeats or (sum(times) < MIN_TOTAL_SECONDS and len(times) < MAX_RUNS):
        before()
        gc.collect()
        gc.disable()
        try:
            start = time.process_time()
            fn()
            times.append(time.process_time() - start)
        finally:
            gc.enable()
    return min(times)


def fmt(seconds: float | None) -> str:
    if seconds is None:
        return "—"
    return f"{seconds * 1e3:.2f} ms" if seconds < 1 else f"{seconds:.2f} s"


def ratio_text(slow: float, fast: float) -> str:
    ratio = slow / fast
    return f"{ratio:,.0f}x" if ratio >= 10 else f"{ratio:.1f}x"


def every_set_size(template: TimeSliceTemplate, horizon: int) -> int:
    result = exact_adjustment(template, horizon)
    return sum(result.set_size(x) for x in result.actions)


def every_set_materialised(template: TimeSliceTemplate, horizon: int) -> int:
    result = exact_adjustment(template, horizon)
    return sum(len(result.adjustment_set(x)) for x in result.actions)


def refuse(template: TimeSliceTemplate, horizon: int) -> tuple:
    try:
        exact_adjustment(template, horizon)
    except NotImitableError as err:
        return err.witness
    raise AssertionError("the paper's mazes are not exactly imitable")


def window(template: TimeSliceTemplate, k: int, mode: str) -> str:
    try:
        found = windowed_adjustment(template, k, mode=mode)  # type: ignore[arg-type]
    except NotImitableError as err:
        return type(err).__name__
    return f"window, {len(found.witnesses)} witnesses" if mode == "relaxed" else "exact window"


def check_sets(template: TimeSliceTemplate, horizon: int) -> None:
    result = exact_adjustment(template, horizon)
    report = sequential_pi_backdoor(template.unroll(horizon), result.actions, REWARD, result.family)
    if not report.holds:
        raise AssertionError(f"the sets at H={horizon} fail Definition 2: {report.witnesses}")


def main() -> None:
    parser = OneLineParser(description=__doc__.split("\n")[0])
    parser.add_argument("--repeats", type=count, default=3, help="timed runs per case (best is kept)")
    parser.add_argument("--horizons", type=count, nargs="+", default=[1, 100, 500, 1000, 2000])
    parser.add_argument("--windows", type=non_negative, nargs="+", default=[2, 10])
    parser.add_argument("--output", default="results/adjustment_runtime.md")
    args = parser.parse_args()
    load_before = os.getloadavg()

    full_rows, refusal_rows, window_rows = [], [], []
    checked = min((h for h in args.horizons if h > 1), default=args.horizons[0])
    for name, (template, hidden) in PAPER_TEMPLATES.items():
        check_sets(imitable_variant(template, hidden), checked)
    cases = [(name, h) for name in PAPER_TEMPLATES for h in args.horizons]
    for name, horizon in tqdm(cases, desc="full horizon"):
        template, hidden = PAPER_TEMPLATES[name]
        imitable = imitable_variant(template, hidden)
        nodes = len(imitable.unroll(horizon))
        unroll = best_time(lambda: imitable.unroll(horizon), args.repeats)
        sets = best_time(lambda: exact_adjustment(imitable, horizon), args.repeats)
        prefix = best_time(lambda: every_set_size(imitable, horizon), args.repeats)
        materialised = best_time(lambda: every_set_materialised(imitable, horizon), args.repeats)
        total_size = every_set_size(imitable, horizon)
        full_rows.append((f"{name}-imitable", horizon, nodes, total_size, unroll, sets, prefix, materialised, PAPER_SECONDS.get(horizon)))
        witness = refuse(template, horizon)
        refusal = best_time(lambda: refuse(template, horizon), args.repeats)
        refusal_rows.append((name, horizon, len(template.unroll(horizon)), refusal, witness))
    window_cases = [
        (name, variant, k, mode)
        for name in PAPER_TEMPLATES
        for variant in (False, True)
        for k in args.windows
        for mode in ("exact", "relaxed")
    ]
    for name, variant, k, mode in tqdm(window_cases, desc="windows"):
        template, hidden = PAPER_TEMPLATES[name]
        if variant:
            template = imitable_variant(template, hidden)
        result = window(template, k, mode)
        cold = best_time(lambda: window(template, k, mode), args.repeats, before=check_bounded_influence.cache_clear)
        window_rows.append((name + ("-imitable" if variant else ""), k, mode, result, cold))
    load_after = os.getloadavg()

    command = shlex.join(["python", "benchmarks/adjustment_runtime.py", *sys.argv[1:]])
    lines = [
        "# Adjustment runtime: full horizon vs windowed",
        "",
        f"Command: `{command}` (from the repository root).",
        "",
        f"Machine: {platform.processor() or platform.machine()}, {os.cpu_count()} CPUs shared with other jobs "
        f"(load average {load_before[0]:.1f} before, {load_after[0]:.1f} after), Python {platform.python_version()}, "
        f"networkx {nx.__version__}; pure Python, one thread; CPU time of the process (the wall clock would "
        f"count the other jobs), best of at least {args.repeats} runs (up to {MAX_RUNS} while they add up to less "
        f"than {MIN_TOTAL_SECONDS:g} s), garbage collector off during a run. The paper's "
        "times are from its own hardware and its own diagrams.",
        "",
        "## Full horizon, exactly imitable variants",
        "",
        "The complete computation on the variants of the maze templates whose hidden variable does not "
        "persist (reward at the last slice). `exact_adjustment` = unrolling + FindOX + Markov boundary + "
        "boundary actions; `+ every set (prefix form)` adds each action's set as its prefix of the sorted "
        "conditioning order; `+ every set (materialised)` instead builds each set as a frozenset (dropped "
        "after use; their total size, `Σ|Z_t|`, is quadratic in H). The paper's ratio uses the "
        f"materialised time. The sets at H = {checked} were checked against Definition 2 "
        "(`sequential_pi_backdoor`) before timing.",
        "",
        "| template | H | nodes | Σ\\|Z_t\\| | unroll | exact_adjustment | + every set (prefix form) "
        "| + every set (materialised) | paper | paper / ours |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for name, horizon, nodes, total_size, unroll, sets, prefix, materialised, paper in full_rows:
        lines.append(
            f"| {name} | {horizon} | {nodes:,} | {total_size:,} | {fmt(unroll)} | {fmt(sets)} | {fmt(prefix)} "
            f"| {fmt(materialised)} | {fmt(paper)} | {ratio_text(paper, materialised) if paper else '—'} |"
        )
    lines += [
        "",
        "## Full horizon, refusal on the paper's templates",
        "",
        "`exact_adjustment` on the paper's templates: FindOX leaves the actions out, and the "
        "`NotImitableError` carries a certificate path for the latest one (shown for the shortest horizon "
        "above 1). This is a refusal, not the computation of sets: it is not comparable with the paper's "
        "full-horizon times.",
        "",
        "| template | H | nodes | refusal (FindOX + certificate) | certificate |",
        "|---|---|---|---|---|",
    ]
    for name, horizon, nodes, refusal, witness in refusal_rows:
        shown = " ~ ".join(map(str, witness)) if horizon == checked else ""
        lines.append(f"| {name} | {horizon} | {nodes:,} | {fmt(refusal)} | {shown} |")
    lines += [
        "",
        "## Windows (Algorithm 1), first call",
        "",
        "`windowed_adjustment(template, k, mode)`, with the cached Assumption-1 bound dropped before each "
        "run. Exact mode: FindOX on the horizon-(k+1) proxy (the paper's mazes end there in "
        "`NotImitableError`), the Assumption-1 check, the window checked against Definition 2 at "
        "H = k+1, 2k+3 and 5k+7 (and, if it fails, the other windows tried). Relaxed mode: the observed "
        "reward ancestors, with the open paths at those horizons listed as witnesses. The paper reports "
        "Algorithm 1 at a few seconds (7.1 s at H = 1); the target of issue 12 is "
        f"{fmt(WINDOW_TARGET_SECONDS)} at k = 10.",
        "",
        "| template | k | mode | result | first call | within 5 ms | paper (7.1 s) / ours |",
        "|---|---|---|---|---|---|---|",
    ]
    for name, k, mode, result, cold in window_rows:
        within = "yes" if cold <= WINDOW_TARGET_SECONDS else "no"
        lines.append(f"| {name} | {k} | {mode} | {result} | {fmt(cold)} | {within} | {ratio_text(7.1, cold)} |")
    report = "\n".join(lines) + "\n"
    os.makedirs(os.path.dirname(args.output) or ".", exist_ok=True)
    tmp = args.output + ".tmp"
    with open(tmp, "w") as f:
        f.write(report)
    os.replace(tmp, args.output)
    print(report)


if __name__ == "__main__":
    main()
