"""Cost of building a window: the listed family (the construction before issue 58) against
the rule (``windowed_adjustment``'s default), on the shipped env templates.

For each template, mode and k it builds the window both ways in this process, checks that
they are equal, and prints the CPU time (``time.process_time``: the other jobs of a shared
machine do not inflate it as they do the wall clock; best of ``--repeats``, the garbage
collector off) and the peak of Python's allocations (``tracemalloc``, a separate run:
tracing slows the code down), with the ratio old / new. The listed construction is
quadratic in k, so it is run only up to ``--old-max-k``; the rule alone goes on to the
larger k, and the exponent of a power law fitted to its times is printed per row group.

Usage:
    python benchmarks/window_construction.py [--ks 10 50 100 200 400 999] [--old-max-k 400]
        [--templates rovermaze antmaze humanoidmaze] [--repeats 1] [--output results/window_construction.md]
"""

from __future__ import annotations

import gc
import math
import platform
import subprocess
import sys
import time
import tracemalloc
from collections.abc import Callable
from pathlib import Path

from torchrl_causal.cli.arguments import OneLineParser, count, non_negative
from torchrl_causal.envs.antmaze import AntMazeEnv
from torchrl_causal.envs.humanoidmaze import HumanoidMazeEnv
from torchrl_causal.envs.route_choice import RouteChoiceEnv
from torchrl_causal.envs.rover_maze import RoverMazeEnv
from torchrl_causal.graphs import AdjustmentWindow, GraphError, TimeSliceTemplate, windowed_adjustment

TEMPLATES: dict[str, Callable[[], TimeSliceTemplate]] = {
    "routechoice": RouteChoiceEnv.slice_template,
    "rovermaze": RoverMazeEnv.slice_template,
    "antmaze": AntMazeEnv.slice_template,
    "humanoidmaze": HumanoidMazeEnv.slice_template,
}


def cpu_model() -> str:
    try:
        for line in subprocess.run(["lscpu"], capture_output=True, text=True, check=True).stdout.splitlines():
            if line.startswith("Model name:"):
                return line.split(":", 1)[1].strip()
    except (OSError, subprocess.CalledProcessError):
        pass
    return platform.processor() or "unknown"


def build(template: TimeSliceTemplate, k: int, mode: str, verification: str) -> AdjustmentWindow | str:
    try:
        return windowed_adjustment(template, k, mode, verification=verification)  # type: ignore[arg-type]
    except GraphError as error:  # a refusal is a result too (exact mode on the mazes)
        return f"{type(error).__name__}: {error}"


def timed(template: TimeSliceTemplate, k: int, mode: str, verification: str, repeats: int) -> tuple[float, AdjustmentWindow | str]:
    best, result = math.inf, None
    for _ in range(repeats):
        gc.collect()
        gc.disable()
        try:
            start = time.process_time()
            result = build(template, k, mode, verification)
            best = min(best, time.process_time() - start)
        finally:
            gc.enable()
    return best, result  # type: ignore[return-value]


def peak_mib(template: TimeSliceTemplate, k: int, mode: str, verification: str) -> float:
    gc.collect()
    tracemalloc.start()
    try:
        build(template, k, mode, verification)
        return tracemalloc.get_traced_memory()[1] / 2**20
    finally:
        tracemalloc.stop()


def exponent(points: list[tuple[int, float]]) -> float | None:
    """Least-squares slope of log(time) against log(k) over the points with k >= 50."""
    points = [(k, t) for k, t in points if k >= 50 and t > 0]
    if len(points) < 2:
        return None
    xs, ys = [math.log(k) for k, _ in points], [math.log(t) for _, t in points]
    mx, my = sum(xs) / len(xs), sum(ys) / len(ys)
    return sum((x - mx) * (y - my) for x, y in zip(xs, ys)) / sum((x - mx) ** 2 for x in xs)


def main(argv: list[str] | None = None) -> None:
    parser = OneLineParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--ks", type=non_negative, nargs="+", default=[10, 50, 100, 200, 400, 999])
    parser.add_argument("--old-max-k", type=non_negative, default=400, help="largest k the listed (quadratic) construction is run at")
    parser.add_argument("--templates", nargs="+", choices=sorted(TEMPLATES), default=["rovermaze", "antmaze", "humanoidmaze"])
    parser.add_argument("--modes", nargs="+", choices=["relaxed", "exact"], default=["relaxed", "exact"])
    parser.add_argument("--repeats", type=count, default=1)
    parser.add_argument("--output", type=Path, default=None, help="also write the table (markdown) here")
    args = parser.parse_args(argv)

    lines = [
        f"CPU: {cpu_model()}; Python {platform.python_version()}; one thread; CPU time of this process "
        f"(best of {args.repeats}); memory = peak of Python allocations (tracemalloc), separate run.",
        "",
        "| template | mode | k | old (listed) time | new (rule) time | time ratio "
        "| old peak MiB | new peak MiB | memory ratio | same window |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    print("\n".join(lines), flush=True)
    summary = []
    for name in args.templates:
        template = TEMPLATES[name]()
        for mode in args.modes:
            new_points = []
            for k in args.ks:
                new_time, new = timed(template, k, mode, "rule", args.repeats)
                new_peak = peak_mib(template, k, mode, "rule")
                new_points.append((k, new_time))
                if k <= args.old_max_k:
                    old_time, old = timed(template, k, mode, "listed", args.repeats)
                    old_peak = peak_mib(template, k, mode, "listed")
                    cells = [
                        f"{old_time:.3f} s",
                        f"{new_time:.3f} s",
                        f"{old_time / max(new_time, 1e-9):.1f}x",
                        f"{old_peak:.1f}",
                        f"{new_peak:.1f}",
                        f"{old_peak / max(new_peak, 1e-9):.1f}x",
                        "yes" if old == new else "NO",
                    ]
                    if old != new:
                        raise SystemExit(f"{name} {mode} k={k}: the two constructions differ")
                else:
                    cells = ["(not run)", f"{new_time:.3f} s", "", "", f"{new_peak:.1f}", "", ""]
                row = f"| {name} | {mode} | {k} | " + " | ".join(cells) + " |"
                lines.append(row)
                print(row, flush=True)
            fitted = exponent(new_points)
            summary.append(f"- {name} {mode}: new time ~ k^{fitted:.2f} (k >= 50)" if fitted is not None else f"- {name} {mode}: too few k")
    lines += ["", "Fitted exponent of the new construction's CPU time:", *summary]
    print("\n".join(["", "Fitted exponent of the new construction's CPU time:", *summary]), flush=True)
    if args.output is not None:
        args.output.write_text("\n".join(lines) + "\n")


if __name__ == "__main__":
    main(sys.argv[1:])
