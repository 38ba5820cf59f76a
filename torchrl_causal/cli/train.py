"""Hydra entry point: ``python -m torchrl_causal.train env=<name> algo=<bc|gail|sqil|iq_learn|expert>
causal=<bool> window.k=<int> seed=<int> [env.horizon=...] [env.confounding_strength=...]``.

The config tree is ``torchrl_causal/conf/`` (package data; see ``conf/config.yaml``), typed
by :mod:`torchrl_causal.experiment.schema`: a bad value stops the command before a run
directory exists. ``scale=paper`` selects Appendix E's networks and budgets,
``scale=cpu`` (default) a 2-core budget. Sweeps:
``python -m torchrl_causal.train -m experiment=paper_table``.

Each job is :func:`torchrl_causal.lifecycle.run`: rerunning the same command resumes an
unfinished run from its last checkpoint and returns a finished run's stored evaluations.
Ctrl-C (SIGINT), SIGTERM or SIGUSR2 (SLURM's time-limit warning) checkpoints, marks the
run interrupted and prints the command that resumes it.
"""

from __future__ import annotations

import sys

import hydra
from hydra.core.hydra_config import HydraConfig
from omegaconf import DictConfig

from torchrl_causal.cli.arguments import one_line_errors, refuse_repeated_keys
from torchrl_causal.errors import RenderingUnavailable
from torchrl_causal.experiment.config import CONFIG_NAME, CONFIG_PATH
from torchrl_causal.experiment.interrupts import RunInterrupted
from torchrl_causal.experiment.run_directory import CheckpointError, RunInUseError
from torchrl_causal.lifecycle import run

__all__ = ["entry_point", "main"]


@hydra.main(config_path=CONFIG_PATH, config_name=CONFIG_NAME, version_base="1.3")
def main(cfg: DictConfig) -> float:
    """Runs one job; returns its deploy-regime success rate (what a sweeper would optimise)."""
    try:
        # (a Ctrl-C before the run's own handlers, while checking or building the window, is entry_point's)
        with one_line_errors(CheckpointError, RunInUseError, RenderingUnavailable):
            results = run(cfg)
    except RunInterrupted as stop:
        command = " ".join(["python -m torchrl_causal.train", *HydraConfig.get().overrides.task])
        print(f"{stop}. Resume with: {command}", file=sys.stderr)
        raise SystemExit(stop.exit_code) from None
    return results["deploy"].success_rate


def entry_point() -> None:
    """``main`` as the command line runs it: a Ctrl-C while Hydra composes the config (before
    :func:`main` handles signals) stops with one line too, and so does a key given twice
    (Hydra would keep the last value silently)."""
    refuse_repeated_keys(sys.argv[1:])
    try:
        main()
    except KeyboardInterrupt:
        command = " ".join(["python -m torchrl_causal.train", *sys.argv[1:]])
        print(f"interrupted by SIGINT before the run started, nothing was written. Resume with: {command}", file=sys.stderr)
        raise SystemExit(130) from None


if __name__ == "__main__":
    entry_point()
