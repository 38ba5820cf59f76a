"""The main job (``make demo``): Causal SQIL against SQIL, and Causal BC against BC, on
Confounded RoverMaze-U, end to end.

1. collects RoverMaze-U demonstrations with the scripted ``RoverExpert`` (it reads the
   rover's true heading, which the imitator never sees);
2. trains Causal SQIL and Causal BC (the windowed adjustment: positions, speeds and past
   actions over k = 10 steps, the compass W excluded) and SQIL and BC (the paper's
   V^O_t: the current observation, compass included);
3. evaluates every policy in the train regime (the demonstrations' conditions) and the
   deploy regime (the compass rotated by pi: the confounder's distribution has shifted);
4. prints Table 1's layout, the raw table and the paper's claims checked, and writes the
   report (Markdown, CSV, figures) to ``runs/demo/report``.

Budgets are the CPU scale's, shortened so that the job fits 10 minutes on 2 cores (see
:data:`DEMO_OVERRIDES`); ``results/rovermaze_medium.md`` has the full 8-algorithm table
on the larger maze. Re-running returns finished runs instead of training them again;
``DEMO_RUN_ROOT`` moves the output.
"""

from __future__ import annotations

import logging
import os
import sys
import time
from pathlib import Path

import torch

from torchrl_causal.evaluation import aggregate, effect_checks, load_runs, write_report
from torchrl_causal.evaluation.tables import effect_markdown, lengths_markdown, raw_markdown, table1_markdown
from torchrl_causal.train import run
from torchrl_causal.trainers import RunInterrupted, compose_config

__all__ = ["main", "DEMO_OVERRIDES", "DEMO_RUNS"]

# The CPU scale with shorter training and evaluation so the whole job fits 10 minutes.
DEMO_OVERRIDES: dict[str, list[str]] = {
    "common": ["env=rovermaze_u", "scale=cpu", "demos.episodes=100", "eval.final_episodes=300", "eval.episodes=20",
               "eval.num_envs=100", "threads=2"],
    "expert": [],
    "bc": ["algo.epochs=30", "algo.eval_every=10"],
    "sqil": ["algo.total_steps=30000", "algo.random_steps=4000", "algo.eval_every=10000"],
}
# (algorithm, causal): the paper's method and its baseline first.
DEMO_RUNS: tuple[tuple[str, bool], ...] = (("expert", False), ("sqil", True), ("sqil", False), ("bc", True),
                                           ("bc", False))


def main() -> None:
    start = time.monotonic()
    logging.basicConfig(level=logging.INFO, format="%(message)s", stream=sys.stdout)
    torch.set_num_threads(2)
    root = Path(os.environ.get("DEMO_RUN_ROOT", "runs/demo"))
    print(__doc__.split("\n\n")[0])
    for algo, causal in DEMO_RUNS:
        cfg = compose_config([*DEMO_OVERRIDES["common"], *DEMO_OVERRIDES[algo], f"algo={algo}",
                              f"causal={str(causal).lower()}", f"run_root={root}"])
        print(f"\n=== {algo}{' (causal)' if causal else ''}: {cfg.run_dir} ===", flush=True)
        try:
            run(cfg)
        except RunInterrupted as stop:
            print(f"{stop}. Resume with: make demo", file=sys.stderr)
            raise SystemExit(stop.exit_code) from None
    (table,) = aggregate(load_runs(root)).values()
    print("\nDeploy regime (Table 1 layout; normalised E[Y] shifts the worst algorithm to 0):\n")
    print(table1_markdown(table, "deploy"))
    print("\nTrain regime (the demonstrations' conditions):\n")
    print(table1_markdown(table, "train"))
    print("\nRaw E[Y] and success rate:\n")
    print(raw_markdown(table))
    print("\nMean length of successful episodes:\n")
    print(lengths_markdown(table))
    print("\nThe paper's claims on these runs:\n")
    print(effect_markdown(effect_checks(table)))
    report = write_report(root, root / "report", name="rovermaze_u_demo", command="make demo")
    print(f"\nReport: {report.markdown} (+ CSV and figures). Total {time.monotonic() - start:.0f} s.")


if __name__ == "__main__":
    main()
