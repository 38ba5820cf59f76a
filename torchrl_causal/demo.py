"""The main job (``make demo``): Causal SQIL against SQIL and Causal BC against BC, each in
the train regime and the deploy regime, in minutes on 2 CPU cores.

1. **Causal SQIL vs SQIL on Route Choice**, the paper's single-stage example
   (Appendix A): the expert reads its orientation O, the imitator a wind-driven compass W.
   Causal SQIL's adjustment set excludes W and learns the sheltered route (success 3/4 in
   both regimes); SQIL conditions on W, which predicts the expert's action in training
   and misleads it once the wind's distribution shifts (deploy regime).
2. **Causal BC vs BC on Confounded RoverMaze-U**: a scripted expert that reads the
   rover's true heading; Causal BC conditions on positions, speeds and actions over the
   last k = 2 steps (the heading shows in the displacement), BC on the current
   observation, compass W included; the deploy regime rotates the compass by pi.
3. Every policy is evaluated in both regimes; the job prints Table 1's layout and the
   raw table for each task and writes the report (Markdown, CSV, figures) to
   ``runs/demo/report``.

Budgets are shortened from the CPU scale so that the job fits 10 minutes on 2 cores
(:data:`DEMO_SETTINGS`, :data:`DEMO_ALGOS`). Off-policy learning on the maze takes longer
than that on 2 cores (Causal SQIL reaches the expert on RoverMaze-medium after 45k-150k
env steps: ``results/rovermaze_medium.md``). Re-running returns finished runs instead of
training them again; ``DEMO_RUN_ROOT`` moves the output.
"""

from __future__ import annotations

import logging
import os
import sys
import time
from pathlib import Path

from torchrl_causal.evaluation import aggregate, effect_checks, load_runs, write_report
from torchrl_causal.evaluation.tables import effect_markdown, lengths_markdown, raw_markdown, table1_markdown
from torchrl_causal.train import run
from torchrl_causal.trainers import RunInterrupted, compose_config

__all__ = ["main", "DEMO_SETTINGS", "DEMO_ALGOS", "DEMO_RUNS"]

# Each task at a budget that fits the job's 10 minutes.
DEMO_SETTINGS: dict[str, list[str]] = {
    "route_choice": ["env=route_choice", "demos.episodes=2000", "eval.episodes=1000", "eval.final_episodes=4000",
                     "eval.num_envs=1000"],
    "rovermaze_u": ["env=rovermaze_u", "env.horizon=400", "window.k=2", "demos.episodes=200", "eval.episodes=20",
                    "eval.final_episodes=200", "eval.num_envs=200"],
}
DEMO_ALGOS: dict[str, list[str]] = {
    "expert": [],
    "sqil": ["algo.total_steps=3000", "algo.random_steps=640", "algo.utd_ratio=1.0", "algo.num_envs=64",
             "algo.frames_per_batch=640", "algo.eval_every=1000"],
    "bc": ["algo.epochs=30", "algo.eval_every=10"],
}
# (task, algorithm, causal), the paper's method first.
DEMO_RUNS: tuple[tuple[str, str, bool], ...] = (
    ("route_choice", "expert", False), ("route_choice", "sqil", True), ("route_choice", "sqil", False),
    ("rovermaze_u", "expert", False), ("rovermaze_u", "bc", True), ("rovermaze_u", "bc", False),
)
# Appendix A's values for Route Choice, what the causal and the compass-reading policies get.
ROUTE_CHOICE_VALUES = "the causal policy 3/4 in both regimes; the expert's, read through W, 11/16 (train) and 19/48 (deploy)"


def main() -> None:
    start = time.monotonic()
    logging.basicConfig(level=logging.INFO, format="%(message)s", stream=sys.stdout)
    root = Path(os.environ.get("DEMO_RUN_ROOT", "runs/demo"))
    print(__doc__.split("\n\n")[0])
    for task, algo, causal in DEMO_RUNS:
        cfg = compose_config(["scale=cpu", "threads=1", *DEMO_SETTINGS[task], f"algo={algo}", *DEMO_ALGOS[algo],
                              f"causal={str(causal).lower()}", f"run_root={root}"])
        print(f"\n=== {task}: {algo}{' (causal)' if causal else ''}: {cfg.run_dir} ===", flush=True)
        try:
            run(cfg)
        except RunInterrupted as stop:
            print(f"{stop}. Resume with: make demo", file=sys.stderr)
            raise SystemExit(stop.exit_code) from None
    for setting, table in sorted(aggregate(load_runs(root)).items()):
        print(f"\n## {setting.describe()}\n")
        print("Deploy regime (Table 1 layout; normalised E[Y] shifts the worst algorithm to 0):\n")
        print(table1_markdown(table, "deploy"))
        print("\nTrain regime (the demonstrations' conditions):\n")
        print(table1_markdown(table, "train"))
        print("\nRaw E[Y] and success rate:\n")
        print(raw_markdown(table))
        if setting.env == "route_choice":
            print(f"\nAppendix A: {ROUTE_CHOICE_VALUES}.")
        else:
            print("\nMean length of successful episodes:\n")
            print(lengths_markdown(table))
            print("\nThe paper's claims on these runs:\n")
            print(effect_markdown(effect_checks(table)))
    report = write_report(root, root / "report", name="demo", command="make demo")
    print(f"\nReport: {report.markdown} (+ CSV and figures). Total {time.monotonic() - start:.0f} s.")


if __name__ == "__main__":
    main()
