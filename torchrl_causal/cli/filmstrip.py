"""Frame strips of one evaluation episode per run, rendered offscreen, one row per run:
``python -m torchrl_causal.filmstrip runs=[<dir>,<dir>] labels=[C-SQIL,SQIL] out=strip.png``.

Each run's selected policy (``checkpoints/best.pt``; the expert row rebuilds its expert)
acts in one ``regime`` episode (default ``deploy``) seeded with ``seed``, in the
imitator's view of its own run; ``frames`` evenly spaced frames are kept, looked at from
above the whole maze (``camera=<name>`` picks an MJCF camera, e.g. ``track``). Every run
gets the same seed, so every row starts from the same state and sees the same gusts.
Needs a MuJoCo maze env and an offscreen GL context (EGL on a headless machine).
"""

from __future__ import annotations

import sys
from collections.abc import Sequence
from pathlib import Path

from omegaconf import OmegaConf

from torchrl_causal.lifecycle import open_run
from torchrl_causal.evaluation.rendering import Filmstrip, record_filmstrip, save_filmstrips

__all__ = ["filmstrip_of_run", "main"]

_ARGS = {"runs", "labels", "out", "regime", "seed", "frames", "every", "size", "camera"}


def filmstrip_of_run(run_dir: str | Path, *, regime: str = "deploy", seed: int = 0, frames: int = 6,
                     every: int = 10, size: int = 240, camera: str | None = None) -> Filmstrip:
    """One ``regime`` episode of the selected policy of ``run_dir`` (see the module docstring)."""
    _, evaluator, policy = open_run(run_dir, device="cpu")
    env = evaluator.make_env(regime, 1, seed)
    try:
        if policy is not None:
            policy.eval()  # no dropout
        acting = evaluator.acting_policy(policy, env)
        return record_filmstrip(env, acting, max_steps=evaluator.cfg.env.horizon, frames=frames, every=every,
                                width=size, height=size, camera=camera)
    finally:
        env.close()


def main(argv: Sequence[str] | None = None) -> Path:
    args = OmegaConf.from_cli(list(sys.argv[1:] if argv is None else argv))
    unknown = set(args) - _ARGS
    if unknown or "runs" not in args or "out" not in args:
        raise SystemExit("usage: python -m torchrl_causal.filmstrip runs=[<dir>,...] out=<png> [labels=[...]] "
                         "[regime=deploy] [seed=0] [frames=6] [every=10] [size=240] [camera=<name>]"
                         + (f"; unknown argument(s) {sorted(unknown)}" if unknown else ""))
    runs = [str(run) for run in args.runs]
    labels = [str(label) for label in args.get("labels", runs)]
    if len(labels) != len(runs):
        raise SystemExit(f"labels names {len(labels)} rows for {len(runs)} runs")
    options = {key: args[key] for key in ("regime", "seed", "frames", "every", "size", "camera") if key in args}
    strips = {}
    for label, run in zip(labels, runs):
        strip = filmstrip_of_run(run, **options)
        outcome = f"goal at step {strip.length}" if strip.success else f"no goal in {strip.length} steps"
        print(f"{label}: {run} [{options.get('regime', 'deploy')}] {outcome}")
        strips[label] = strip
    path = save_filmstrips(strips, args.out)
    print(f"wrote {path}")
    return path


if __name__ == "__main__":
    main()
