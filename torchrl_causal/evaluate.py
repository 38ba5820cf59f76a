"""Evaluate a finished run: ``python -m torchrl_causal.evaluate run_dir=<dir> regime=deploy episodes=1000``.

Rebuilds the run's policy from its saved config and adjustment window, loads
``checkpoints/best.pt`` and runs ``episodes`` episodes in batches of ``num_envs``
(default: the run's ``eval.num_envs``). Prints the success rate ± SE, raw E[Y] ± std and
the length of successful episodes, and writes ``<run_dir>/eval/<regime>.json`` (the
record the report reads) unless ``save=false``. ``confounding_strength=<s>`` evaluates
under another deployment shift; such records go to ``eval/<regime>-cs<s>.json`` and the
report ignores them. ``device=<cpu|cuda|...>`` picks where the policy runs; by default the
run's own device when this machine has it, else the CPU (a run trained on a GPU evaluates
anywhere).
"""

from __future__ import annotations

import json
import sys
from collections.abc import Sequence
from pathlib import Path

from omegaconf import OmegaConf

from torchrl_causal.evaluation.metrics import EvaluationResult
from torchrl_causal.evaluation.runs import CONFIG_FILE, EVAL_DIR, WINDOW_FILE
from torchrl_causal.graphs.window import AdjustmentWindow
from torchrl_causal.trainers import make_trainer
from torchrl_causal.trainers.builders import make_env, maze_geometry
from torchrl_causal.trainers.device import resolve_device

__all__ = ["evaluate_run", "main"]

_ARGS = {"run_dir", "regime", "episodes", "num_envs", "seed", "confounding_strength", "save", "trajectories", "device"}


def evaluate_run(run_dir: str | Path, regime: str = "deploy", episodes: int = 1000, *, num_envs: int | None = None,
                 seed: int = 30_000, confounding_strength: float | None = None, trajectories: int = 0,
                 save: bool = True, device: str | None = None) -> EvaluationResult:
    """Evaluates the best checkpoint of ``run_dir`` (see the module docstring)."""
    run_dir = Path(run_dir)
    config_file = run_dir / CONFIG_FILE
    if not config_file.is_file():
        raise FileNotFoundError(f"{run_dir} is not a run directory: {CONFIG_FILE} is missing")
    cfg = OmegaConf.load(config_file)
    if num_envs is not None:
        cfg.eval.num_envs = int(num_envs)
    if confounding_strength is not None:
        cfg.env.confounding_strength = float(confounding_strength)
    if device is not None:
        cfg.device = str(device)
    else:
        try:
            resolve_device(str(OmegaConf.select(cfg, "device", default="cpu")))
        except ValueError:
            cfg.device = "cpu"
    trainer = make_trainer(cfg)
    policy = None  # the expert is rebuilt for every env it evaluates in
    if trainer.uses_window:
        trainer.window = AdjustmentWindow.from_dict(json.loads((run_dir / WINDOW_FILE).read_text()))
        policy = trainer.load_best_policy()
    result = trainer.evaluate(regime, int(episodes), int(seed), trajectories=int(trajectories), progress=True,
                              policy=policy)
    if save:
        name = regime if confounding_strength is None else f"{regime}-cs{float(confounding_strength):g}"
        record = result.to_dict()
        record["maze"] = maze_geometry(make_env(cfg, regime, 1, 0))
        (run_dir / EVAL_DIR).mkdir(exist_ok=True)
        (run_dir / EVAL_DIR / f"{name}.json").write_text(json.dumps(record))
    return result


def main(argv: Sequence[str] | None = None) -> EvaluationResult:
    args = OmegaConf.from_cli(list(sys.argv[1:] if argv is None else argv))
    unknown = set(args) - _ARGS
    if unknown or "run_dir" not in args:
        raise SystemExit(f"usage: python -m torchrl_causal.evaluate run_dir=<dir> [regime=deploy] [episodes=1000] "
                         f"[num_envs=...] [seed=...] [confounding_strength=...] [save=true] [device=...]"
                         + (f"; unknown argument(s) {sorted(unknown)}" if unknown else ""))
    result = evaluate_run(**{k: args[k] for k in args})
    s = result.summary()
    print(f"{args.run_dir} [{s['regime']}] episodes {s['n_episodes']}: success {100 * s['success_rate']:.1f}% "
          f"± {100 * s['success_se']:.1f}, E[Y] {s['return_mean']:.1f} ± {s['return_std']:.1f}, "
          f"successful episode length {s['ep_len_mean']:.0f} ± {s['ep_len_std']:.0f}")
    return result


if __name__ == "__main__":
    main()
